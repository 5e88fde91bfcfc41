"""The naive baseline ``triangulate`` and the ray intersection other methods reuse.

Each bearing taken from pose ``p`` is a ray from ``p[:2]`` in world direction
``p[2] + bearing``. A landmark's position is the least-squares intersection of its rays: the
point minimising the summed squared perpendicular distances to the rays,
``sum_k (I - d_k d_k^T)(x - o_k) = 0``. Its normal matrix ``A = sum_k (I - d_k d_k^T)`` has
smallest eigenvalue ``1 - |cos(alpha)|`` for two rays at angle ``alpha``: that eigenvalue is the
parallax test (``min_parallax_rad``). A point behind any ray (negative depth) is refused.

``TriangulateMapper`` dead-reckons the poses from odometry and keeps the two 2x2 / 2-vector
sums per landmark, so each step costs O(bearings) and the estimate O(landmarks).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .angles import angle_residual
from .errors import ConfigError
from .geometry import compose
from .mapper import MapEstimate
from .stream import Step, StreamHeader


def ray_normals(directions_rad: np.ndarray) -> np.ndarray:
    """``I - d d^T`` for world ray directions, shape ``(k, 2, 2)``."""
    c, s = np.cos(directions_rad), np.sin(directions_rad)
    return np.stack([np.stack([s * s, -s * c], -1), np.stack([-s * c, c * c], -1)], -2)


def parallax_eigenvalue(a: np.ndarray) -> np.ndarray:
    """Smallest eigenvalue of symmetric 2x2 matrices ``(..., 2, 2)`` (closed form)."""
    tr = a[..., 0, 0] + a[..., 1, 1]
    det = a[..., 0, 0] * a[..., 1, 1] - a[..., 0, 1] * a[..., 1, 0]
    return tr / 2 - np.sqrt(np.maximum(tr * tr / 4 - det, 0.0))


def intersect_rays(origins_xy: np.ndarray, directions_rad: np.ndarray, *,
                   min_parallax_rad: float = math.radians(2.0),
                   min_front_fraction: float = 1.0) -> tuple[np.ndarray, bool]:
    """Least-squares intersection of rays.

    Parameters
    ----------
    origins_xy : array of shape (k, 2)
        Ray origins (robot positions), world frame.
    directions_rad : array of shape (k,)
        World directions (robot heading + bearing).
    min_parallax_rad : float
        Two rays at this angle are the least that counts as determined.
    min_front_fraction : float
        The fraction of rays the point must lie in front of (1.0: all of them).

    Returns
    -------
    point_xy : ndarray of shape (2,)
        NaN when not determined.
    ok : bool
        False with fewer than 2 rays, too little parallax, or the point behind too many rays.
    """
    o = np.asarray(origins_xy, dtype=float).reshape(-1, 2)
    d = np.asarray(directions_rad, dtype=float).reshape(-1)
    if len(o) != len(d):
        raise ConfigError(f"intersect_rays: {len(o)} origins but {len(d)} directions")
    if len(o) < 2:
        return np.full(2, np.nan), False
    n = ray_normals(d)
    a = n.sum(0)
    b = np.einsum("kij,kj->i", n, o)
    x, ok = _solve(a[None], b[None], o, d, min_parallax_rad, min_front_fraction,
                   np.zeros(len(o), np.int64))
    return x[0], bool(ok[0])


def origin_spread(points_xy: np.ndarray, origins: np.ndarray, owner: np.ndarray,
                  n: int) -> np.ndarray:
    """Per point, the angle spanned by its rays' origins seen from it, shape ``(n,)``."""
    v = origins - points_xy[owner]
    ang = np.arctan2(v[:, 1], v[:, 0])
    mean = np.arctan2(np.bincount(owner, np.sin(ang), n), np.bincount(owner, np.cos(ang), n))
    res = angle_residual(ang, mean[owner])
    hi = np.full(n, -np.inf)
    lo = np.full(n, np.inf)
    np.maximum.at(hi, owner, np.nan_to_num(res, nan=-np.inf))
    np.minimum.at(lo, owner, np.nan_to_num(res, nan=np.inf))
    return np.where(hi >= lo, hi - lo, 0.0)


def _solve(a: np.ndarray, b: np.ndarray, origins: np.ndarray, dirs: np.ndarray,
           min_parallax_rad: float, min_front_fraction: float,
           owner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Solve ``a[m] x = b[m]`` for m landmarks; check parallax and the depth of the rays.

    ``origins``/``dirs`` are all rays, ``owner`` the landmark slot of each ray.
    """
    # A necessary condition first (the normal matrix must be invertible) ...
    lam = parallax_eigenvalue(a)
    ok = lam >= 1.0 - math.cos(min_parallax_rad)
    x = np.full((len(a), 2), np.nan)
    if np.any(ok):
        x[ok] = np.linalg.solve(a[ok], b[ok][..., None])[..., 0]
    if origins.size:
        depth = np.einsum("kj,kj->k", x[owner] - origins,
                          np.column_stack([np.cos(dirs), np.sin(dirs)]))
        front = np.bincount(owner, weights=(depth > 0), minlength=len(a))
        total = np.bincount(owner, minlength=len(a))
        ok &= front >= min_front_fraction * total
        # ... then the geometric parallax: the angle the ray origins span as seen from the
        # solved point (many rays from one place, or noisy rays, do not make parallax).
        ok &= origin_spread(x, origins, owner, len(a)) >= min_parallax_rad
    x[~ok] = np.nan
    return x, ok


@dataclass(frozen=True)
class TriangulateConfig:
    """Options of the naive baseline.

    min_parallax_rad : a landmark is mapped once its rays span at least this angle.
    min_front_fraction : the point must lie in front of this fraction of its rays (dead
        reckoning drifts over a long run, so not all of them).
    """

    min_parallax_rad: float = math.radians(2.0)
    min_front_fraction: float = 0.5

    def __post_init__(self) -> None:
        if not 0 < self.min_parallax_rad < math.pi / 2:
            raise ConfigError("min_parallax_rad must be in (0, pi/2)")
        if not 0 <= self.min_front_fraction <= 1:
            raise ConfigError("min_front_fraction must be in [0, 1]")


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
                 **options: float) -> None:
        if config is not None and options:
            raise ConfigError("TriangulateMapper: pass either config or options, not both")
        self.config = config or TriangulateConfig(**options)
        self._header = header
        self._start = np.asarray(start_pose, dtype=float)
        self._pose = self._start.copy()
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
        if step.odom is not None:
            self._pose = compose(self._pose, step.odom)
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
        x, ok = _solve(self._a, self._b, np.concatenate(self._ray_origin),
                       np.concatenate(self._ray_dir), self.config.min_parallax_rad,
                       self.config.min_front_fraction, np.concatenate(self._ray_owner))
        order = np.argsort(ids[ok])
        return MapEstimate(ids[ok][order], x[ok][order], pose_t=pose_t, poses=poses,
                           info={"left_out": sorted(int(i) for i in ids[~ok])})
