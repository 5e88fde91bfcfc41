"""When a window of steps closes and how many steps the next one drops (issue 8's keyframe
windows and issue 15's windows measured in the geometry of the motion):
:class:`WindowSchedule`, used by the mapper's windowed triangulation (:mod:`.window`,
:mod:`.bundle`)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from ..errors import ConfigError
from ..geometry import direction_span


#: Path thresholds are met to this relative rounding (sums of increments drift in the last bits).
_ROUND = 1.0 - 1e-9


class WindowSchedule:
    """When the current window of steps closes, and how many steps the next one drops.

    Two ways to measure a window:

    * in keyframes (``poses``, ``stride``; the issue-8 windows): ``W`` poses, the next window
      ``stride`` steps later;
    * in the geometry of the motion (issue 15): a window closes once its landmarks are
      triangulated from well apart -- the ``quantile`` of the parallax of the landmarks it
      saw from two poses or more (at least ``min_landmarks`` of them) reaches
      ``parallax_rad`` -- or once the path driven across it reaches ``length_m``, whichever
      comes first; the next window starts at the first step ``1 / overlap`` of the window's
      path further on, and ends no sooner than that much path after its end (so windows are
      spaced by the path, not by how many keyframes in a row pass the test;
      ``ceil(overlap)`` windows hold each reading). A landmark seen once has parallax 0.

    The parallax of a landmark is the angle spanned by the world directions of its rays
    (dead-reckoned heading plus bearing, :func:`~bomgraph.geometry.direction_span`): it grows
    with the baseline over the depth and not with the number of rays, so the same recording
    keyframed every 0.1 m or every 0.3 m closes its windows at the same places (to a
    keyframe), and a recording with distant landmarks gets longer windows in metres than a
    small arena. It is a pure angle, not a multiple of the stream's bearing sigma, so a
    smaller or larger calibrated sigma does not change the windows. (The eigenvalue measure
    :func:`~bomgraph.geometry.effective_parallax` is not used here: it weighs every ray, so two
    rays at the ends of a baseline score up to sqrt(3) times more than many along it.)
    ``max_poses`` caps a window's size (the bundle's cost) whatever the motion.

    :meth:`push` a step, then :meth:`full` says whether the buffered steps make a window;
    :meth:`advance` drops the steps the next window does not share and says how many.
    """

    def __init__(self, *, poses: int | None = None, stride: int | None = None,
                 parallax_rad: float | None = None, length_m: float | None = None,
                 overlap: float = 1.0, min_landmarks: int = 3, quantile: float = 0.5,
                 max_poses: int | None = None, prefixes: int = 20) -> None:
        geometric = parallax_rad is not None or length_m is not None
        if (poses is None) == (not geometric):
            raise ConfigError("WindowSchedule: give poses (keyframes), or parallax_rad and / "
                              "or length_m (geometry)")
        self.poses = poses
        self.stride = stride if stride is not None else (poses - 1 if poses else None)
        self.parallax_rad = parallax_rad
        self.length_m = math.inf if length_m is None else float(length_m)
        self.overlap = float(overlap)
        self.min_landmarks = int(min_landmarks)
        self.quantile = float(quantile)
        self.max_poses = max_poses
        self._path: list[float] = []          # cumulative path of each step (m)
        self._psi = 0.0                       # dead-reckoned heading (rad)
        self._ids: list[np.ndarray] = []      # per step: landmark ids, world ray directions
        self._dirs: list[np.ndarray] = []
        self._by_geometry = False
        self._next_end_m = -math.inf          # the next window ends no earlier (path, m)
        self.prefixes = int(prefixes)
        self._parallax_at = (-1, 0.0, 0)      # (steps buffered, parallax, landmarks): cached
        self._start_spacing()

    @property
    def inflation(self) -> float:
        """About how many windows a reading enters; each fused estimate's variance is
        multiplied by it, so overlapping windows do not count one reading several times."""
        if self.poses is not None:
            return float(max(1, math.ceil((self.poses - 1) / self.stride)))
        return float(max(1, math.ceil(self.overlap)))

    def __len__(self) -> int:
        return len(self._path)

    def clear(self) -> None:
        """Forget the buffered steps (a gap in the odometry)."""
        self._path.clear()
        self._ids.clear()
        self._dirs.clear()
        self._psi = 0.0
        self._next_end_m = -math.inf
        self._start_spacing()

    def _start_spacing(self) -> None:
        """Prefix ends of a first window (no window closed before it): at ``1 / prefixes``
        of ``length_m``, or, measuring parallax, where it first reaches each
        ``j / prefixes`` of ``parallax_rad``."""
        self._bounds: list[int] = []
        self._mark = 1
        self._spacing_m = (self.length_m / self.prefixes
                           if self.parallax_rad is None and math.isfinite(self.length_m)
                           else None)

    def push(self, odom: ArrayLike | None, landmark_ids: np.ndarray,
             bearings_rad: np.ndarray) -> None:
        """Buffer one step: its increment from the step before (None: the first step) and
        its bearings."""
        step_m = 0.0
        if odom is not None and self._path:
            dx, dy, dpsi = (float(v) for v in odom)
            step_m = math.hypot(dx, dy)
            self._psi += dpsi
        self._path.append((self._path[-1] if self._path else 0.0) + step_m)
        if self.poses is None and self.parallax_rad is not None:
            self._ids.append(np.asarray(landmark_ids))
            self._dirs.append(self._psi + np.asarray(bearings_rad, dtype=float))
        if self.poses is None:
            self._mark_prefix()

    def _mark_prefix(self) -> None:
        """Record the newest step as a prefix end if it crosses the next mark."""
        n = len(self._path)
        if n < 2:
            return
        if self._spacing_m is not None:
            progress = (self._path[-1] - self._path[0]) / self._spacing_m
        else:
            par, n_lm = self._cached_parallax()
            progress = (par / self.parallax_rad * self.prefixes
                        if n_lm >= self.min_landmarks else 0.0)
        if progress >= self._mark * _ROUND:
            self._bounds.append(n)
            self._mark = int(math.floor(progress / _ROUND)) + 1

    def _cached_parallax(self) -> tuple[float, int]:
        n = len(self._path)
        if self._parallax_at[0] != n:
            self._parallax_at = (n, *self.parallax())
        return self._parallax_at[1], self._parallax_at[2]

    def parallax(self) -> tuple[float, int]:
        """The ``quantile`` of the parallax (rad) of the buffered landmarks
        (:func:`~bomgraph.geometry.direction_span` of their dead-reckoned ray directions, 0
        for a landmark seen once), and how many there are."""
        if not self._ids:
            return 0.0, 0
        ids = np.concatenate(self._ids)
        if ids.size < 2:
            return 0.0, 0
        uniq, owner = np.unique(ids, return_inverse=True)
        span = direction_span(np.concatenate(self._dirs), owner, uniq.size)
        return float(np.quantile(span, self.quantile)), int(uniq.size)

    def full(self) -> bool:
        """Whether the buffered steps make a window."""
        n = len(self._path)
        if self.poses is not None:
            return n >= self.poses
        self._by_geometry = False
        if n < 2:
            return False
        if self._path[-1] < self._next_end_m * _ROUND:
            pass                              # too soon after the last window's end
        elif self._path[-1] - self._path[0] >= self.length_m * _ROUND:
            self._by_geometry = True
        elif self.parallax_rad is not None:
            par, n_lm = self._cached_parallax()
            self._by_geometry = n_lm >= self.min_landmarks and par >= self.parallax_rad
        return self._by_geometry or (self.max_poses is not None and n >= self.max_poses)

    def prefix_ends(self) -> list[int]:
        """Ends (pose counts) of the prefixes of the buffered window on which a bundle is
        solved in turn (issue 8's ``grow`` measured in path instead of poses); the last is
        the whole window. They are fixed as the steps arrive, never moved by later ones, so
        the open window's prefixes are those of the window it becomes (an estimate can go on
        from the last one, :class:`.bundle.PrefixState`): every ``1 / prefixes`` of the last
        closed window's path from the window's start (windows close at about the same path,
        :meth:`advance`); in a first window, ``length_m / prefixes``, or where the parallax
        first reaches each ``j / prefixes`` of ``parallax_rad``."""
        n = len(self._path)
        return [e for e in self._bounds if 2 <= e < n] + [n]

    def advance(self) -> int:
        """Drop the steps the next window does not share (at least one) and return how many."""
        n = len(self._path)
        if self.poses is not None:
            k = self.stride
        elif self._by_geometry:
            path = np.asarray(self._path) - self._path[0]
            k = int(np.searchsorted(path, path[-1] / self.overlap * _ROUND, side="left"))
            if path[-1] > 0:
                self._spacing_m = path[-1] / self.prefixes
            # the next window ends a stride later too: windows are spaced by the path, not
            # by how many keyframes satisfy the closing test in a row
            self._next_end_m = self._path[-1] + path[-1] / self.overlap
        else:                                 # closed by max_poses
            k = int(math.ceil(n / self.overlap))
            if self._path[-1] > self._path[0]:
                self._spacing_m = (self._path[-1] - self._path[0]) / self.prefixes
        k = max(1, min(k, n))
        del self._path[:k]
        del self._ids[:k]
        del self._dirs[:k]
        if self.poses is None:            # the next window's prefix ends, from its start
            self._bounds, self._mark = [], 1
            self._parallax_at = (-1, 0.0, 0)
            kept, self._path = self._path, []
            for i, v in enumerate(kept):
                self._path.append(v)
                if self._spacing_m is not None or i == len(kept) - 1:
                    self._mark_prefix()
        return k


__all__ = ["WindowSchedule"]
