"""Planar pose algebra shared by every method: composition, dead reckoning, frames.

A pose is ``[x_m, y_m, psi_rad]``; an odometry increment ``[dx_m, dy_m, dpsi_rad]`` is the
motion from pose ``t-1`` to pose ``t`` expressed in the frame of pose ``t-1`` (STREAM_FORMAT.md):
``xy_t = xy_{t-1} + R(psi_{t-1}) [dx, dy]``, ``psi_t = psi_{t-1} + dpsi``. This is GTSAM's
``Pose2.compose``; the paper's move-then-turn model is the increment ``[l, 0, phi]``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .angles import angle_residual, wrap_angle


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


def between(pose_a: ArrayLike, pose_b: ArrayLike) -> np.ndarray:
    """The increment ``u`` with ``pose_a ⊕ u = pose_b``, shape ``(..., 3)``."""
    a = np.asarray(pose_a, dtype=float)
    b = np.asarray(pose_b, dtype=float)
    dx, dy = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack([c * dx + s * dy, -s * dx + c * dy,
                     angle_residual(b[..., 2], a[..., 2])], -1)


def dead_reckon(odoms: ArrayLike, start_pose: ArrayLike = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Chain odometry increments from ``start_pose``.

    Parameters
    ----------
    odoms : array of shape (T, 3)
        Increments ``[dx_m, dy_m, dpsi_rad]`` for steps 1..T.
    start_pose : array of shape (3,)

    Returns
    -------
    ndarray of shape (T + 1, 3)
        Poses 0..T (headings wrapped), computed without a Python loop.
    """
    u = np.asarray(odoms, dtype=float).reshape(-1, 3)
    p0 = np.asarray(start_pose, dtype=float)
    psi = p0[2] + np.concatenate([[0.0], np.cumsum(u[:, 2])])
    c, s = np.cos(psi[:-1]), np.sin(psi[:-1])
    dxy = np.stack([c * u[:, 0] - s * u[:, 1], s * u[:, 0] + c * u[:, 1]], -1)
    xy = p0[:2] + np.concatenate([np.zeros((1, 2)), np.cumsum(dxy, axis=0)])
    return np.column_stack([xy, wrap_angle(psi)])


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
    p = np.asarray(pose, dtype=float)
    q = np.asarray(points_world_xy, dtype=float).reshape(-1, 2)
    return angle_residual(np.arctan2(q[:, 1] - p[1], q[:, 0] - p[0]), p[2])
