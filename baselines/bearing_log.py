"""Every bearing of an LM mapper's run as flat arrays, and where its factor sits in the graphs.

:class:`BearingLog` keeps the bearings (owner step, landmark id, bearing) for the vectorised
plausibility checks of a solution; :class:`BearingFactors` the index of each bearing factor in
the state's graph and robust graph, so that a solve can leave chosen bearings out
(:mod:`baselines.near_range`) without a loop over the factors.
"""

from __future__ import annotations

import numpy as np

from bomgraph.stream import Step

__all__ = ["BearingLog", "BearingFactors"]


class BearingLog:
    """Every bearing of a run kept as three flat arrays (owner step, landmark id, bearing in
    rad, each ``(J,)``): appended per step, concatenated into one piece when read after new
    bearings came in (shared by the LM mappers' state and iSAM2's long-mode window)."""

    def __init__(self) -> None:
        self._parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def add(self, step: Step) -> None:
        """Keep ``step``'s bearings."""
        ids = np.asarray(step.landmark_ids, dtype=np.int64)
        if ids.size:
            self._parts.append((np.full(ids.size, step.t, np.int64), ids,
                                np.asarray(step.bearings_rad, dtype=float)))

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Owner steps, landmark ids and bearings (rad) of every bearing kept, each ``(J,)``."""
        if not self._parts:
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
        if len(self._parts) > 1:
            self._parts = [tuple(np.concatenate(c) for c in zip(*self._parts))]  # type: ignore
        return self._parts[0]


class BearingFactors:
    """Where each bearing factor of the LM mappers' state sits: its step and landmark id, and
    its index in the state's graph and in its robust graph (-1 without one).

    Filled from :attr:`baselines.bearing_graph.NewFactors.bearing_rows` as each batch is
    pushed (:meth:`add`); :meth:`find` returns the indices of given (step, landmark) pairs by
    one vectorised match (a pair is encoded on the landmarks' positions in a sorted id array,
    so that ids up to 2^63 - 1 need no wide integers).
    """

    def __init__(self) -> None:
        self._parts: list[np.ndarray] = []
        self._rows = np.zeros((0, 4), np.int64)

    def add(self, rows: np.ndarray, core_offset: int, landmark_offset: int,
            robust_offset: int) -> None:
        """Record a batch: ``rows`` (k, 5) of ``(t, landmark id, in core (1) or landmark (0)
        graph, index there, index in the robust graph or -1)``, the first two graphs pushed at
        ``core_offset`` / ``landmark_offset`` of the state's graph, the robust at
        ``robust_offset``."""
        if not len(rows):
            return
        g = rows[:, 3] + np.where(rows[:, 2] == 1, core_offset, landmark_offset)
        r = np.where(rows[:, 4] >= 0, rows[:, 4] + robust_offset, -1)
        self._parts.append(np.column_stack([rows[:, 0], rows[:, 1], g, r]))

    def _all(self) -> np.ndarray:
        if self._parts:
            self._rows = np.concatenate([self._rows, *self._parts])
            self._parts = []
        return self._rows

    def find(self, t: np.ndarray, lid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Graph and robust-graph indices of the factors of the bearings ``(t[k], lid[k])``
        (each (m,), every factor of a pair if a step saw a landmark twice; robust -1 where
        there is no robust graph)."""
        rows = self._all()
        if not t.size or not rows.size:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        ids = np.unique(np.concatenate([rows[:, 1], lid]))
        width = np.int64(ids.size)
        key = rows[:, 0] * width + np.searchsorted(ids, rows[:, 1])
        want = np.asarray(t, np.int64) * width + np.searchsorted(ids, lid)
        hit = np.isin(key, want)
        return rows[hit, 2], rows[hit, 3]
