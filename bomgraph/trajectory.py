"""Pose errors of an aligned trajectory, as evo reports them, and a truth-free consistency
figure.

- :func:`absolute_pose_errors`: per pose, the translation error [m] and the heading error
  [rad] of the aligned estimate against the reference (evo's APE, translation and rotation
  parts).
- :func:`relative_pose_errors`: per pair of poses ``delta`` steps apart, the error of the
  relative motion ``E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)`` (evo's RPE with ``--delta``):
  ``|E.xy|`` [m] and ``|E.psi|`` [rad].
- :func:`bearing_residuals`: measured minus predicted bearing of every measurement the
  estimate's own map and trajectory cover (no truth needed).

Nothing here aligns; :mod:`bomgraph.evaluate` does, then calls these on the aligned poses.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .angles import angle_residual
from .geometry import between
from .stream import Step


def _rms(v: np.ndarray) -> float:
    """RMS without overflow (scaled by the largest magnitude); NaN when empty."""
    if not v.size:
        return float("nan")
    m = float(np.max(np.abs(v)))
    return 0.0 if m == 0 else m * float(np.sqrt(np.mean((v / m) ** 2)))


@dataclass(frozen=True)
class PoseErrors:
    """Errors per pose (APE) or per pose pair (RPE): ``t`` (k,) the step (for RPE the first
    step of the pair), ``translation_m`` (k,), ``heading_rad`` (k,) absolute values."""

    t: np.ndarray
    translation_m: np.ndarray
    heading_rad: np.ndarray

    def __len__(self) -> int:
        return len(self.t)

    @property
    def translation_rmse_m(self) -> float:
        return _rms(self.translation_m)

    @property
    def heading_rmse_rad(self) -> float:
        return _rms(self.heading_rad)


def absolute_pose_errors(t: np.ndarray, est_poses: np.ndarray,
                         ref_poses: np.ndarray) -> PoseErrors:
    """APE of aligned ``(k, 3)`` poses ``est_poses`` against ``ref_poses`` at steps ``t``."""
    e, r = np.asarray(est_poses, float).reshape(-1, 3), np.asarray(ref_poses, float).reshape(-1, 3)
    trans = np.hypot(e[:, 0] - r[:, 0], e[:, 1] - r[:, 1])
    head = np.abs(angle_residual(e[:, 2], r[:, 2]))
    return PoseErrors(np.asarray(t, np.int64), trans, np.asarray(head, float))


def relative_pose_errors(t: np.ndarray, est_poses: np.ndarray, ref_poses: np.ndarray,
                         delta: int = 1) -> PoseErrors:
    """RPE over every pair of steps ``(t_i, t_i + delta)`` both present in ``t``.

    ``est_poses`` and ``ref_poses`` are ``(k, 3)`` at the steps ``t`` (aligned, so that a
    mirrored estimate is compared in the reference's handedness).
    """
    if delta < 1:
        raise ValueError(f"delta must be >= 1 step, got {delta}")
    t = np.asarray(t, np.int64)
    e, r = np.asarray(est_poses, float).reshape(-1, 3), np.asarray(ref_poses, float).reshape(-1, 3)
    order = np.argsort(t)
    t, e, r = t[order], e[order], r[order]
    if not len(t) or delta > int(t[-1]) - int(t[0]):  # no pair (and no int64 overflow)
        return PoseErrors(t[:0], np.zeros(0), np.zeros(0))
    j = np.searchsorted(t, t + delta)
    ok = j < len(t)
    ok[ok] = t[j[ok]] == t[ok] + delta
    i, j = np.nonzero(ok)[0], j[ok]
    err = between(between(r[i], r[j]), between(e[i], e[j]))
    return PoseErrors(t[i], np.hypot(err[:, 0], err[:, 1]), np.abs(err[:, 2]))


def bearing_residuals(landmark_ids: np.ndarray, landmarks_xy: np.ndarray, pose_t: np.ndarray,
                      poses: np.ndarray, steps: Sequence[Step], *,
                      mirrored: bool = False) -> np.ndarray:
    """Measured minus predicted bearing [rad] of every measurement of a mapped landmark from
    a pose the estimate holds, shape (m,): how well a map and trajectory explain the data.

    ``mirrored`` negates the predictions: an estimate in a mirrored frame explains the
    bearings that way (a reflection reverses every angle).
    """
    if not len(steps) or not len(landmark_ids) or not len(pose_t):
        return np.zeros(0)
    t = np.concatenate([np.full(len(st.landmark_ids), st.t) for st in steps]).astype(np.int64)
    ids = np.concatenate([st.landmark_ids for st in steps]).astype(np.int64)
    brg = np.concatenate([st.bearings_rad for st in steps]).astype(float)

    def rows(keys: np.ndarray, wanted: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        order = np.argsort(keys)
        pos = np.clip(np.searchsorted(keys, wanted, sorter=order), 0, len(keys) - 1)
        return order[pos], keys[order[pos]] == wanted

    pr, pok = rows(np.asarray(pose_t, np.int64), t)
    lr, lok = rows(np.asarray(landmark_ids, np.int64), ids)
    ok = pok & lok
    if not ok.any():
        return np.zeros(0)
    p, q = np.asarray(poses, float)[pr[ok]], np.asarray(landmarks_xy, float)[lr[ok]]
    pred = angle_residual(np.arctan2(q[:, 1] - p[:, 1], q[:, 0] - p[:, 0]), p[:, 2])
    return angle_residual(brg[ok], -pred if mirrored else pred)


__all__ = ["PoseErrors", "absolute_pose_errors", "relative_pose_errors", "bearing_residuals"]
