"""The naive baseline ``triangulate``: dead reckoning plus least-squares ray intersection.

Each landmark is the least-squares intersection of its rays
(:func:`bomgraph.geometry.intersect_rays`), gated by parallax and ray depth.

``TriangulateMapper`` dead-reckons the poses from odometry and keeps the two 2x2 / 2-vector
sums per landmark, so each step costs O(bearings) and the estimate O(landmarks).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Mapping

import numpy as np

from bomgraph.config import Presets, requirement, resolve
from bomgraph.geometry import ray_normals, solve_ray_normal_equations
from bomgraph.mapper import MapEstimate
from bomgraph.method_limits import Reach
from bomgraph.stream import Step, StreamHeader


@dataclass(frozen=True)
class TriangulateConfig(Presets):
    """Options of the naive baseline. Presets: ``paper`` (the defaults) and ``real``, the
    recording setting every method has (issue 15 item 4), which for this baseline is the same:
    it has nothing a recording would tune.

    min_parallax_rad : a landmark is mapped once its rays span at least this angle.
    min_front_fraction : the point must lie in front of this fraction of its rays (dead
        reckoning drifts over a long run, so not all of them).
    """

    PRESETS: ClassVar[Mapping[str, Mapping[str, Any]]] = {"paper": {}, "real": {}}

    min_parallax_rad: float = math.radians(2.0)
    min_front_fraction: float = 0.5

    def __post_init__(self) -> None:
        need = requirement("TriangulateConfig")
        need(0 < self.min_parallax_rad < math.pi / 2, "min_parallax_rad must be in (0, pi/2)")
        need(0 <= self.min_front_fraction <= 1, "min_front_fraction must be in [0, 1]")


class TriangulateMapper:
    """Dead-reckoned poses + least-squares ray intersection per landmark.

    Parameters
    ----------
    header : StreamHeader
    start_pose : (x_m, y_m, psi_rad)
        The frame of the map; the first pose by default is the origin.
    """

    def __init__(self, header: StreamHeader, *, start_pose: tuple[float, float, float] =
                 (0.0, 0.0, 0.0), config: TriangulateConfig | None = None,
                 preset: str | None = None, **options: float) -> None:
        self.config = resolve(TriangulateConfig, config, preset, options)
        self._header = header
        # refuses a bad start_pose; no sigma is checked: triangulate uses none (h158)
        self._reach = Reach(start_pose, "triangulate", max_sigma=None)
        self._pose = self._reach.start_pose
        self._poses: list[np.ndarray] = []
        self._slot: dict[int, int] = {}
        self._a = np.zeros((0, 2, 2))
        self._b = np.zeros((0, 2))
        self._ray_origin: list[np.ndarray] = []
        self._ray_dir: list[np.ndarray] = []
        self._ray_owner: list[np.ndarray] = []

    def _slots(self, ids: np.ndarray) -> np.ndarray:
        new = [int(i) for i in ids if int(i) not in self._slot]
        for i in new:
            self._slot[i] = len(self._slot)
        if new:
            self._a = np.concatenate([self._a, np.zeros((len(new), 2, 2))])
            self._b = np.concatenate([self._b, np.zeros((len(new), 2))])
        return np.array([self._slot[int(i)] for i in ids], dtype=np.int64)

    def step(self, step: Step) -> None:
        self._pose = self._reach.advance(step)  # dead reckoning, refused beyond 1e9 m
        self._poses.append(self._pose)
        if step.landmark_ids.size == 0:
            return
        slots = self._slots(step.landmark_ids)
        dirs = self._pose[2] + step.bearings_rad
        n = ray_normals(dirs)
        np.add.at(self._a, slots, n)
        np.add.at(self._b, slots, n @ self._pose[:2])
        self._ray_origin.append(np.broadcast_to(self._pose[:2], (len(slots), 2)))
        self._ray_dir.append(dirs)
        self._ray_owner.append(slots)

    def estimate(self) -> MapEstimate:
        ids = np.array(sorted(self._slot, key=self._slot.get), dtype=np.int64)
        poses = np.array(self._poses).reshape(-1, 3)
        pose_t = np.arange(len(poses))
        if ids.size == 0:
            return MapEstimate(ids, np.zeros((0, 2)), pose_t=pose_t, poses=poses,
                               info={"left_out": []})
        x, ok = solve_ray_normal_equations(self._a, self._b, np.concatenate(self._ray_origin),
                       np.concatenate(self._ray_dir), self.config.min_parallax_rad,
                       self.config.min_front_fraction, np.concatenate(self._ray_owner))
        order = np.argsort(ids[ok])
        return MapEstimate(ids[ok][order], x[ok][order], pose_t=pose_t, poses=poses,
                           info={"left_out": sorted(int(i) for i in ids[~ok])})
