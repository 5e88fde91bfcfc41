"""Planar geometry shared by every method: SE(2) algebra, the odometry chain, the one
predicted-bearing kernel (:func:`pair_bearings`; :func:`bearing_offsets` where the bearing is
linearised) and the one least-squares ray-intersection kernel with its parallax measures.

A pose is ``[x_m, y_m, psi_rad]``; an odometry increment ``[dx_m, dy_m, dpsi_rad]`` is the
motion from pose ``t-1`` to pose ``t`` expressed in the frame of pose ``t-1`` (STREAM_FORMAT.md):
``xy_t = xy_{t-1} + R(psi_{t-1}) [dx, dy]``, ``psi_t = psi_{t-1} + dpsi``. This is GTSAM's
``Pose2.compose``; the paper's move-then-turn model is the increment ``[l, 0, phi]``.

Rays: each bearing taken from pose ``p`` is a ray from ``p[:2]`` in world direction
``p[2] + bearing``. A point's least-squares intersection minimises the summed squared
perpendicular distances to its rays, ``sum_k (I - d_k d_k^T)(x - o_k) = 0``. The normal matrix
``A = sum_k (I - d_k d_k^T)`` has smallest eigenvalue ``1 - |cos(alpha)|`` for two rays at
angle ``alpha``: that eigenvalue, the angle the ray origins span seen from the point, and the
:func:`effective_parallax` of many rays are the parallax measures every method gates on.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from .angles import angle_residual, wrap_angle
from .errors import ConfigError


def rotation(psi_rad: ArrayLike) -> np.ndarray:
    """Rotation matrices ``R(psi)`` of shape ``(..., 2, 2)``."""
    c, s = np.cos(psi_rad), np.sin(psi_rad)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def compose(pose: ArrayLike, odom: ArrayLike) -> np.ndarray:
    """``pose ⊕ odom`` for arrays of shape ``(..., 3)`` (broadcasting); heading wrapped."""
    p = np.asarray(pose, dtype=float)
    u = np.asarray(odom, dtype=float)
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    x = p[..., 0] + c * u[..., 0] - s * u[..., 1]
    y = p[..., 1] + s * u[..., 0] + c * u[..., 1]
    return np.stack([x, y, wrap_angle(p[..., 2] + u[..., 2])], -1)


def arc_root(odom: ArrayLike, k: int) -> np.ndarray:
    """The increment ``v`` with ``v ⊕ v ⊕ ... ⊕ v`` (``k`` times) ``= odom``: one ``k``-th of
    the constant-curvature arc from the origin to ``odom`` (the SE(2) exponential of a
    ``k``-th of its logarithm), shape ``(3,)``; the turn is taken in ``(-pi, pi]``."""
    dx, dy, th = (float(v) for v in np.asarray(odom, dtype=float).reshape(3))
    th = float(wrap_angle(th))

    def v_matrix(a: float) -> np.ndarray:      # translation = V(a) [vx, vy] for a turn a
        if abs(a) < 1e-9:
            return np.eye(2)
        sa, ca = math.sin(a), math.cos(a)
        return np.array([[sa / a, -(1.0 - ca) / a], [(1.0 - ca) / a, sa / a]])

    velocity = np.linalg.solve(v_matrix(th), [dx, dy]) / k
    t = v_matrix(th / k) @ velocity
    return np.array([t[0], t[1], th / k])


def between(pose_a: ArrayLike, pose_b: ArrayLike) -> np.ndarray:
    """The increment ``u`` with ``pose_a ⊕ u = pose_b``, shape ``(..., 3)``."""
    a = np.asarray(pose_a, dtype=float)
    b = np.asarray(pose_b, dtype=float)
    dx, dy = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack([c * dx + s * dy, -s * dx + c * dy,
                     angle_residual(b[..., 2], a[..., 2])], -1)


def chain_odometry(odoms: ArrayLike, start_pose: ArrayLike | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Chain odometry increments: the one odometry chain of bomgraph (no Python loop).

    Parameters
    ----------
    odoms : array of shape (T, 3)
        Increments ``[dx_m, dy_m, dpsi_rad]`` for steps 1..T.
    start_pose : array of shape (3,), optional
        The pose the chain starts from; ``None`` chains in the frame of the first pose (the
        same numbers as a zero start pose, without adding zeros).

    Returns
    -------
    xy_m : ndarray of shape (T + 1, 2)
        Positions of poses 0..T.
    psi_rad : ndarray of shape (T + 1,)
        Headings of poses 0..T, cumulative (not wrapped).
    """
    u = np.asarray(odoms, dtype=float).reshape(-1, 3)
    psi = np.concatenate([[0.0], np.cumsum(u[:, 2])])
    if start_pose is not None:
        p0 = np.asarray(start_pose, dtype=float)
        psi = p0[2] + psi
    c, s = np.cos(psi[:-1]), np.sin(psi[:-1])
    dxy = np.stack([c * u[:, 0] - s * u[:, 1], s * u[:, 0] + c * u[:, 1]], -1)
    xy = np.concatenate([np.zeros((1, 2)), np.cumsum(dxy, axis=0)])
    if start_pose is not None:
        xy = p0[:2] + xy
    return xy, psi


def dead_reckon(odoms: ArrayLike, start_pose: ArrayLike = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Poses ``(T + 1, 3)`` chained from ``start_pose`` by :func:`chain_odometry`, headings
    wrapped.

    Parameters
    ----------
    odoms : array of shape (T, 3)
        Increments ``[dx_m, dy_m, dpsi_rad]`` for steps 1..T.
    start_pose : array of shape (3,)
    """
    xy, psi = chain_odometry(odoms, start_pose)
    return np.column_stack([xy, wrap_angle(psi)])


def inverse(pose: ArrayLike) -> np.ndarray:
    """``pose^-1`` for arrays of shape ``(..., 3)``: ``compose(pose, inverse(pose)) = 0``."""
    p = np.asarray(pose, dtype=float)
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    return np.stack([-c * p[..., 0] - s * p[..., 1], s * p[..., 0] - c * p[..., 1],
                     wrap_angle(-p[..., 2])], -1)


def to_world(pose: ArrayLike, points_local_xy: ArrayLike) -> np.ndarray:
    """Points ``(n, 2)`` in the frame of ``pose`` mapped to the world frame."""
    p = np.asarray(pose, dtype=float)
    q = np.asarray(points_local_xy, dtype=float)
    return q @ rotation(p[2]).T + p[:2]


def to_local(pose: ArrayLike, points_world_xy: ArrayLike) -> np.ndarray:
    """Points ``(n, 2)`` in the world frame expressed in the frame of ``pose``."""
    p = np.asarray(pose, dtype=float)
    q = np.asarray(points_world_xy, dtype=float)
    return (q - p[:2]) @ rotation(p[2])


def bearings_to(pose: ArrayLike, points_world_xy: ArrayLike) -> np.ndarray:
    """Bearings ``(n,)`` from ``pose`` to world points, relative to its heading, wrapped."""
    return pair_bearings(pose, np.asarray(points_world_xy, dtype=float).reshape(-1, 2))


def pair_bearings(poses: ArrayLike, points_world_xy: ArrayLike, *,
                  wrapped: bool = True) -> np.ndarray:
    """The bearing of each point from its own pose: the one predicted-bearing kernel.

    Parameters
    ----------
    poses : array of shape (..., 3)
        ``[x_m, y_m, psi_rad]``; row ``i`` is the pose that sees point ``i``.
    points_world_xy : array of shape (..., 2)
        World points; broadcast against ``poses`` (rows ``(m, 3)`` with ``(m, 2)``, or every
        pose with every point as ``(W, 1, 3)`` with ``(1, m, 2)``).
    wrapped : bool
        True (the default): ``atan2(dy, dx) - psi`` wrapped to (-pi, pi] (as
        :func:`~bomgraph.angles.angle_residual`). False: not wrapped, for a residual that
        wraps once, ``angle_residual(measured, pair_bearings(..., wrapped=False))``: wrapping
        the prediction first rounds differently.

    Returns
    -------
    bearing_rad : ndarray of the broadcast shape without the last axis
        Counter-clockwise from the pose's heading to the point, in radians.
    """
    p = np.asarray(poses, dtype=float)
    d = np.asarray(points_world_xy, dtype=float) - p[..., :2]
    ang = np.arctan2(d[..., 1], d[..., 0])
    return angle_residual(ang, p[..., 2]) if wrapped else ang - p[..., 2]


def bearing_offsets(poses: ArrayLike, points_world_xy: ArrayLike
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`pair_bearings` not wrapped, with the offset and squared range its Jacobian is
    built from: the one kernel for a bearing that is linearised.

    With ``[dx, dy]`` the offset and ``r2 = dx^2 + dy^2``, the bearing's derivatives are
    ``[-dy, dx] / r2`` (rad/m) with respect to the point ``[lx, ly]`` and
    ``[dy / r2, -dx / r2, -1]`` with respect to the pose ``[x, y, psi]``.

    Parameters
    ----------
    poses : array of shape (..., 3)
        ``[x_m, y_m, psi_rad]``; row ``i`` is the pose that sees point ``i``.
    points_world_xy : array of shape (..., 2)
        World points, broadcast against ``poses`` as in :func:`pair_bearings`.

    Returns
    -------
    bearing_rad : ndarray of the broadcast shape without the last axis
        ``atan2(dy, dx) - psi``, not wrapped (the bits of ``pair_bearings(..., wrapped=False)``;
        wrap it, or the residual it enters, once).
    offset_xy_m : ndarray of the broadcast shape
        ``[dx, dy]``: the point less the pose's position.
    range2_m2 : ndarray of the broadcast shape without the last axis
        ``dx * dx + dy * dy`` (zero where a point is at its pose: divide with care).
    """
    p = np.asarray(poses, dtype=float)
    d = np.subtract(points_world_xy, p[..., :2])
    dx, dy = d[..., 0], d[..., 1]
    return np.arctan2(dy, dx) - p[..., 2], d, dx * dx + dy * dy


# --------------------------------------------------------------------------------------------
# Rays
# --------------------------------------------------------------------------------------------

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
    x, ok = intersect_ray_groups(o, d, np.zeros(len(o), np.int64), 1,
                                 min_parallax_rad=min_parallax_rad,
                                 min_front_fraction=min_front_fraction)
    return x[0], bool(ok[0])


def intersect_ray_groups(origins_xy: np.ndarray, directions_rad: np.ndarray, owner: np.ndarray,
                         m: int, *, min_parallax_rad: float = math.radians(2.0),
                         min_front_fraction: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """:func:`intersect_rays` for ``m`` points at once, each from its own rays.

    Parameters
    ----------
    origins_xy : array of shape (R, 2)
        Every ray's origin (world frame, metres).
    directions_rad : array of shape (R,)
        Every ray's world direction.
    owner : int array of shape (R,)
        The point (``0 .. m-1``) of each ray; a point with fewer than two rays is refused.
    m : int
        Number of points.
    min_parallax_rad, min_front_fraction : float
        The gates of :func:`intersect_rays`.

    Returns
    -------
    points_xy : ndarray of shape (m, 2)
        NaN where refused.
    ok : bool ndarray of shape (m,)

    Each point's normal equations are summed ray by ray in the rays' order (``np.add.at``),
    the same sums as :func:`intersect_rays` makes for one point.
    """
    n = ray_normals(directions_rad)
    if m == 1:  # the same sums, without the scatter's overhead
        a, b = n.sum(0)[None], np.einsum("kij,kj->i", n, origins_xy)[None]
    else:
        a, b = np.zeros((m, 2, 2)), np.zeros((m, 2))
        np.add.at(a, owner, n)
        np.add.at(b, owner, np.einsum("kij,kj->ki", n, origins_xy))
    x, ok = solve_ray_normal_equations(a, b, origins_xy, directions_rad, min_parallax_rad,
                                       min_front_fraction, owner)
    few = np.bincount(owner, minlength=m) < 2
    x[few] = np.nan
    return x, ok & ~few


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


def solve_ray_normal_equations(a: np.ndarray, b: np.ndarray, origins: np.ndarray, dirs: np.ndarray,
           min_parallax_rad: float, min_front_fraction: float,
           owner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Solve the ray normal equations ``a[m] x = b[m]`` of m points, then gate them.

    Parameters
    ----------
    a : array of shape (m, 2, 2)
        Summed :func:`ray_normals` of each point's rays.
    b : array of shape (m, 2)
        Summed ``(I - d d^T) o`` of each point's rays.
    origins : array of shape (R, 2)
        Every ray's origin (world frame, metres).
    dirs : array of shape (R,)
        Every ray's world direction, radians.
    min_parallax_rad, min_front_fraction : float
        The gates of :func:`intersect_rays`.
    owner : int array of shape (R,)
        The point (``0 .. m-1``) of each ray.

    Returns
    -------
    points_xy : ndarray of shape (m, 2)
        NaN where a gate refused the point.
    ok : bool ndarray of shape (m,)
    """
    # A necessary condition first (the normal matrix must be invertible: with the gate at 0,
    # one ray or parallel rays give an eigenvalue of 0 to rounding, which must not reach the
    # solve, whose LinAlgError would lose every point of the group) ...
    lam = parallax_eigenvalue(a)
    ok = (lam >= 1.0 - math.cos(min_parallax_rad)) & (lam > 1e-12 * (a[..., 0, 0] + a[..., 1, 1]))
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


def effective_parallax(direction_rad: np.ndarray, owner: np.ndarray, n: int) -> np.ndarray:
    """Parallax of several rays per point: ``arccos |mean exp(2 i alpha)|`` in ``[0, pi/2]``.

    For two rays at angle ``gamma`` it is ``min(gamma, pi - gamma)`` (the two-ray gate of the
    paper); for many rays it measures how well they fix the point in every direction (the
    smallest eigenvalue of ``mean(I - u u^T)`` is ``(1 - |mean exp(2 i alpha)|) / 2``), so rays
    from all around a landmark give ``pi / 2``, not a span past ``pi``.

    Parameters
    ----------
    direction_rad : array of shape (R,)
        World direction of each ray.
    owner : int array of shape (R,)
        Point of each ray, in ``0 .. n-1``.
    n : int
        Number of points.
    """
    e2 = np.exp(2j * np.asarray(direction_rad, dtype=float))
    count = np.bincount(owner, minlength=n)
    mean = (np.bincount(owner, e2.real, n) + 1j * np.bincount(owner, e2.imag, n)) \
        / np.maximum(count, 1)
    return np.arccos(np.clip(np.abs(mean), 0.0, 1.0))


def direction_span(direction_rad: np.ndarray, owner: np.ndarray, n: int) -> np.ndarray:
    """Per point, the angle its rays' world directions span (radians, 0 for one ray).

    Unlike :func:`effective_parallax`, which weighs every ray, it does not change when the
    same motion is sampled by more rays (two rays at the ends of a baseline and thirty along
    it span the same angle, to the last ray), so it measures the geometry of a path, not how
    often it was keyframed. Directions are taken about each point's circular mean.

    Parameters
    ----------
    direction_rad : array of shape (R,)
        World direction of each ray.
    owner : int array of shape (R,)
        Point of each ray, in ``0 .. n-1``.
    n : int
        Number of points.
    """
    d = np.asarray(direction_rad, dtype=float)
    mean = np.arctan2(np.bincount(owner, np.sin(d), n), np.bincount(owner, np.cos(d), n))
    res = angle_residual(d, mean[owner])
    hi = np.full(n, -np.inf)
    lo = np.full(n, np.inf)
    np.maximum.at(hi, owner, res)
    np.minimum.at(lo, owner, res)
    return np.where(hi >= lo, hi - lo, 0.0)

