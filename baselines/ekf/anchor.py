"""The anchor bearing of an inverse-depth candidate, tested once later sightings constrain it
(option ``anchor_test`` of ``ekf``; docs/measurements.md, "Re-testing the anchor bearing").

A feature's first bearing ``z_1`` sets its ``theta = psi_1 + z_1`` (:meth:`~baselines.ekf.
slam.EkfSlam._add_inverse_depth`); nothing predicts it, so no gate can test it, and an outlier
there goes, through the feature's later bearings, into the robot's heading. With the option
on, each new feature also gets one state, the anchor bearing's error ``e = theta - psi_1 - z_1
(+ b)`` (``b`` the coloured error, when modelled), added at the first sighting as that exact
linear function of the state (zero, variance ``sigma^2``, uncorrelated with everything but
``theta``): the anchor bearing is then the measurement ``0 = e + v``, ``v ~ N(0, sigma^2)``,
of a state no other bearing measures, and the filter carries ``e``'s posterior under every
later update, with all correlations (the poses, the other features). The marginal of the
other states is unchanged (no row of any update touches ``e``).

The test is the anchor's leave-one-out residual: with ``e_hat``, ``P_e`` its posterior, the
residual ``-e_hat`` of that measurement has variance ``sigma^2 - P_e`` (the posterior of ``e``
without the anchor, against the anchor), so ``e_hat^2 / (sigma^2 - P_e)`` is chi-square with
1 dof when the anchor is as stated, tested at the filter's gate (``gate_probability``). It is
made only once the rest of the filter knows ``e`` at least as well as the anchor alone does
(``P_e <= sigma^2 / 2``: information from elsewhere ``>= 1 / sigma^2``), and, when the
feature's bearings at the step are in the state (``"sighting"``) or when it is about to join
the map (``"conversion"``, also in ``"sighting"``), before Bailey's test is made. A failing
anchor is taken out of the filter (:meth:`~baselines.ekf.filter.BearingEkf.retract`, the
inverse of its update: the robot's heading and every correlated state get back what it
pulled), the feature keeps its later bearings, and ``e`` is marginalised out; the feature's
depth and Bailey's test then rest on its later sightings. The robot's truth is never used.
Counted in ``info["anchors_dropped"]`` (the ids in ``info["anchors_dropped_ids"]``).
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from .config import ANCHOR_TESTS
from .filter import FilterNumericalError
from .slam import BLOCK_ANCHOR, BLOCK_IDP

#: The test is made once the rest of the filter holds at least this share of the anchor's own
#: information on its error (``P_e <= sigma^2 / (1 + share)``).
MIN_SHARE = 1.0


class AnchorTestMixin:
    """The ``anchor_test`` option, mixed into :class:`~baselines.ekf.mappers.EkfMapper` before
    :class:`~baselines.ekf.slam.EkfSlam`; with ``"none"`` every method is the next class's."""

    config: Any
    filter: Any
    _sizes: dict
    _offset: dict
    _gate: float
    _white_sigma: float

    def _anchor_mode(self) -> str:
        return getattr(self.config, "anchor_test", "none")

    def _anchor_state(self) -> dict[str, Any]:
        st = getattr(self, "_anchors", None)
        if st is None:
            st = self._anchors = {"sighted": np.zeros(0, np.int64), "dropped": []}
        return st

    def _add_inverse_depth(self, ids: np.ndarray, z: np.ndarray) -> None:
        on = self._anchor_mode() != "none" and ids.size
        if on:
            self._drop_orphans()           # a restarted feature's old error, before its new one
        super()._add_inverse_depth(ids, z)                 # type: ignore[misc]
        if not on:
            return
        m = ids.size
        off = self._offset
        theta = [off[(BLOCK_IDP, i)] + 2 for i in ids.tolist()]
        bias = [off[("bias", i)] for i in ids.tolist() if ("bias", i) in off]
        idx = np.array([2, *theta, *bias], np.int64)
        jac = np.zeros((m, idx.size))
        jac[:, 0] = -1.0                                    # e = theta - psi (- z: the value 0)
        jac[np.arange(m), 1 + np.arange(m)] = 1.0
        if bias:                                            # (+ b: theta = psi + z - b + e)
            jac[np.arange(m), 1 + m + np.arange(m)] = 1.0
        self._add_blocks([(BLOCK_ANCHOR, i) for i in ids.tolist()],  # type: ignore[attr-defined]
                         np.zeros(m), idx, jac, np.zeros(m))

    def _update_mapped(self, ids: np.ndarray, z: np.ndarray) -> np.ndarray:
        in_state = super()._update_mapped(ids, z)          # type: ignore[misc]
        if self._anchor_mode() == "sighting":
            self._anchor_state()["sighted"] = ids[in_state]
        return in_state

    def _convert(self, ready: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> None:
        mode = self._anchor_mode()
        if mode != "none":
            st = self._anchor_state()
            tested = set(self._ready_ids(ready))
            if mode == "sighting":
                tested.update(st["sighted"].tolist())
                st["sighted"] = np.zeros(0, np.int64)
            self._test_anchors(tested)
        super()._convert(ready)                            # type: ignore[misc]
        if mode != "none":
            self._drop_orphans()

    def _ready_ids(self, ready: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> list[int]:
        """The features ``ready`` would make Euclidean now (as :meth:`EkfSlam._convert`)."""
        keys, bi = self._idp_blocks()                      # type: ignore[attr-defined]
        if not keys:
            return []
        x, P = self.filter.x, self.filter.P
        f = x[bi]
        sel = np.asarray(ready(f, P[bi[:, :, None], bi[:, None, :]]), bool) & (f[:, 3] > 0)
        return [keys[n][1] for n in np.flatnonzero(sel)]

    def _test_anchors(self, ids: set[int]) -> None:
        """Test the anchors of the features ``ids``; retract the worst failing one and test
        the rest again, until none fails."""
        var = self._white_sigma ** 2
        todo = sorted(i for i in ids if (BLOCK_ANCHOR, i) in self._offset)
        while todo:
            o = np.array([self._offset[(BLOCK_ANCHOR, i)] for i in todo], np.int64)
            e, pe = self.filter.x[o], self.filter.P[o, o]
            rest = var - pe                          # the residual's variance
            ok = rest >= var * MIN_SHARE / (1.0 + MIN_SHARE)
            stat = np.where(ok, e * e / np.where(ok, rest, 1.0), 0.0)
            worst = int(np.argmax(stat))
            if not stat[worst] > self._gate:
                return
            try:
                self.filter.retract(int(o[worst]), var)
            except FilterNumericalError:             # (not reached: rest >= var / 2 > 0)
                return
            i = todo.pop(worst)
            self._remove_blocks([(BLOCK_ANCHOR, i)])       # type: ignore[attr-defined]
            self._anchor_state()["dropped"].append(i)

    def _drop_orphans(self) -> None:
        """Marginalise the anchor errors of features no longer in inverse depth (converted:
        the anchor is part of the landmark now; restarted)."""
        gone = [k for k in self._sizes if k[0] == BLOCK_ANCHOR and (BLOCK_IDP, k[1]) not in
                self._sizes]
        if gone:
            self._remove_blocks(gone)                      # type: ignore[attr-defined]

    def _anchor_info(self) -> dict[str, Any]:
        if self._anchor_mode() == "none":
            return {}
        dropped = self._anchor_state()["dropped"]
        return {"anchors_dropped": len(dropped), "anchors_dropped_ids": list(dropped)}


__all__ = ["ANCHOR_TESTS", "AnchorTestMixin", "MIN_SHARE"]
