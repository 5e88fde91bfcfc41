"""Scoring an estimate against the truth (paper section IV-A).

The estimated map lives in the method's own frame, so it is first aligned to the truth by the
transform that minimises the summed squared landmark errors: rotation, translation and
reflection, without scale (the paper's choice; a similarity transform is an option). The mean
position error (MPE) is the mean Euclidean landmark error after it. Robot positions are scored
under the same landmark-derived transform. Nothing here mutates its inputs.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .angles import angle_residual
from .errors import EvaluationError, TooFewLandmarksError
from .mapper import MapEstimate, RunResult
from .stream import Truth


@dataclass(frozen=True)
class Alignment:
    """``x -> scale * R x + translation``; ``R`` is orthogonal, det -1 when reflected."""

    rotation: np.ndarray
    translation: np.ndarray
    scale: float = 1.0

    @property
    def reflected(self) -> bool:
        return bool(np.linalg.det(self.rotation) < 0)

    def apply(self, points_xy: np.ndarray) -> np.ndarray:
        """Transform ``(n, 2)`` points (returns a new array)."""
        p = np.asarray(points_xy, dtype=float).reshape(-1, 2)
        return self.scale * p @ self.rotation.T + self.translation

    def apply_poses(self, poses: np.ndarray) -> np.ndarray:
        """Transform ``(m, 3)`` poses: positions as points, headings through ``R``."""
        p = np.asarray(poses, dtype=float).reshape(-1, 3)
        h = np.column_stack([np.cos(p[:, 2]), np.sin(p[:, 2])]) @ self.rotation.T
        return np.column_stack([self.apply(p[:, :2]), np.arctan2(h[:, 1], h[:, 0])])


def align(source_xy: np.ndarray, target_xy: np.ndarray, *, allow_reflection: bool = True,
          with_scale: bool = False) -> Alignment:
    """The least-squares transform taking ``source_xy`` onto ``target_xy`` (Umeyama, 1991).

    Parameters
    ----------
    source_xy, target_xy : arrays of shape (n, 2), corresponding rows, n >= 3
    allow_reflection : bool
        Allow det(R) = -1 (the paper's evaluation does: MDS maps come mirrored).
    with_scale : bool
        Also fit a scale (similarity transform).
    """
    src = np.asarray(source_xy, dtype=float).reshape(-1, 2)
    dst = np.asarray(target_xy, dtype=float).reshape(-1, 2)
    if not (np.all(np.isfinite(src)) and np.all(np.isfinite(dst))):
        raise EvaluationError("align(): points must be finite")
    if src.shape != dst.shape:
        raise EvaluationError(f"align(): {len(src)} source points but {len(dst)} targets")
    if len(src) < 3:
        raise TooFewLandmarksError(f"alignment needs at least 3 common landmarks, got {len(src)}")
    mu_s, mu_d = src.mean(0), dst.mean(0)
    a, b = src - mu_s, dst - mu_d
    u, sv, vt = np.linalg.svd(b.T @ a)
    d = np.ones(2)
    if not allow_reflection and np.linalg.det(u @ vt) < 0:
        d[-1] = -1.0
    r = (u * d) @ vt
    scale = 1.0
    if with_scale:
        var = float((a ** 2).sum())
        if var == 0:
            raise EvaluationError("align(): all source points coincide; scale is undefined")
        scale = float((sv * d).sum() / var)
    return Alignment(r, mu_d - scale * r @ mu_s, scale)


@dataclass(frozen=True)
class MapScore:
    """Errors of one estimate after alignment (metres).

    ``robot_*`` are NaN when the estimate or the truth has no poses. ``robot_last_m`` is the
    error of the latest estimated pose; ``robot_mean_m`` averages over all estimated poses.
    """

    mpe_m: float
    rmse_m: float
    median_m: float
    max_m: float
    n_mapped: int
    n_truth: int
    n_common: int
    robot_last_m: float
    robot_mean_m: float
    n_poses: int
    landmark_ids: np.ndarray
    errors_m: np.ndarray
    alignment: Alignment

    def as_dict(self) -> dict[str, float | int]:
        return {k: (float(v) if isinstance(v, (float, np.floating)) else int(v))
                for k, v in self.__dict__.items()
                if isinstance(v, (int, float, np.integer, np.floating))}


def score_estimate(estimate: MapEstimate, truth: Truth, *, allow_reflection: bool = True,
                   with_scale: bool = False) -> MapScore:
    """Align ``estimate`` to ``truth`` on the landmarks both have and measure the errors.

    Raises
    ------
    EvaluationError
        If fewer than 3 landmarks are common to the estimate and the truth.
    """
    common, ie, it = np.intersect1d(estimate.landmark_ids, truth.landmark_ids,
                                    return_indices=True)
    if common.size < 3:
        raise TooFewLandmarksError(f"the estimate shares {common.size} landmark(s) with the truth; "
                              f"alignment needs at least 3")
    est_xy = estimate.landmarks_xy[ie]
    true_xy = truth.landmarks_xy[it]
    al = align(est_xy, true_xy, allow_reflection=allow_reflection, with_scale=with_scale)
    err = np.linalg.norm(al.apply(est_xy) - true_xy, axis=1)
    robot_last = robot_mean = float("nan")
    n_poses = 0
    if estimate.poses is not None and truth.poses is not None and len(estimate.poses):
        ok = (estimate.pose_t >= 0) & (estimate.pose_t < len(truth.poses))
        if not np.all(ok):
            raise EvaluationError(f"estimate has poses at steps "
                                  f"{estimate.pose_t[~ok][:5].tolist()} outside the truth's "
                                  f"0..{len(truth.poses) - 1}")
        p_err = np.linalg.norm(al.apply(estimate.poses[:, :2])
                               - truth.poses[estimate.pose_t, :2], axis=1)
        robot_last = float(p_err[np.argmax(estimate.pose_t)])
        robot_mean = float(p_err.mean())
        n_poses = int(len(p_err))
    return MapScore(mpe_m=float(err.mean()), rmse_m=float(np.sqrt((err ** 2).mean())),
                    median_m=float(np.median(err)), max_m=float(err.max()),
                    n_mapped=int(len(estimate.landmark_ids)),
                    n_truth=int(len(truth.landmark_ids)), n_common=int(common.size),
                    robot_last_m=robot_last, robot_mean_m=robot_mean, n_poses=n_poses,
                    landmark_ids=common, errors_m=err, alignment=al)


def heading_errors(estimate: MapEstimate, truth: Truth, alignment: Alignment) -> np.ndarray:
    """Heading errors (rad) of the estimated poses under ``alignment``."""
    if estimate.poses is None or truth.poses is None:
        return np.zeros(0)
    p = alignment.apply_poses(estimate.poses)
    return np.asarray(angle_residual(p[:, 2], truth.poses[estimate.pose_t, 2]))


ERROR_COLUMNS = ("t", "mpe_m", "rmse_m", "median_m", "max_m", "n_mapped", "n_common",
                 "robot_last_m", "robot_mean_m")


def error_table(result: RunResult | Sequence, truth: Truth) -> dict[str, np.ndarray]:
    """Errors at every checkpoint of a run, as columns (see ``ERROR_COLUMNS``).

    A checkpoint whose map shares fewer than 3 landmarks with the truth gets NaN errors (and its
    counts); any other evaluation error is raised.
    """
    checkpoints = result.checkpoints if isinstance(result, RunResult) else tuple(result)
    rows = []
    for c in checkpoints:
        try:
            s = score_estimate(c.estimate, truth)
            rows.append((c.t, s.mpe_m, s.rmse_m, s.median_m, s.max_m, s.n_mapped, s.n_common,
                         s.robot_last_m, s.robot_mean_m))
        except TooFewLandmarksError:
            n = len(c.estimate)
            rows.append((c.t, np.nan, np.nan, np.nan, np.nan, n,
                          int(np.intersect1d(c.estimate.landmark_ids, truth.landmark_ids).size),
                          np.nan, np.nan))
    arr = np.array(rows, dtype=float).reshape(-1, len(ERROR_COLUMNS))
    return {name: (arr[:, k].astype(np.int64) if name in ("t", "n_mapped", "n_common")
                   else arr[:, k]) for k, name in enumerate(ERROR_COLUMNS)}


def landmark_nees(estimate: MapEstimate, truth: Truth, alignment: Alignment) -> np.ndarray:
    """Per-landmark NEES ``e^T P^-1 e`` (in the aligned frame), for estimates with covariances.

    The covariance is rotated with the alignment; values are only meaningful when the method's
    frame is anchored like the truth's (a rigid alignment of a consistent estimate).
    """
    if estimate.landmark_cov is None:
        raise EvaluationError("the estimate has no landmark covariances")
    common, ie, it = np.intersect1d(estimate.landmark_ids, truth.landmark_ids,
                                    return_indices=True)
    e = alignment.apply(estimate.landmarks_xy[ie]) - truth.landmarks_xy[it]
    r = alignment.rotation
    cov = r @ estimate.landmark_cov[ie] @ r.T
    return np.einsum("ni,nij,nj->n", e, np.linalg.inv(cov), e)
