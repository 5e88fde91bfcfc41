"""Scoring an estimate against the truth (paper section IV-A).

The estimated map lives in the method's own frame, so it is first aligned to the truth by the
transform that minimises the summed squared landmark errors: rotation, translation and
reflection, without scale (the paper's choice; a similarity transform is an option). The mean
position error (MPE) is the mean Euclidean landmark error after it. Robot positions are scored
under the same landmark-derived transform. Nothing here mutates its inputs.

All scoring lives here: :func:`score_estimate` (one map), :func:`score_checkpoints` (every
checkpoint of a run, as typed :class:`CheckpointScore` rows; the runner stores them),
:func:`error_table` (the same as columns), and the consistency measures
:func:`landmark_nees` and :func:`pose_nees` (NEES in the aligned frame).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .angles import angle_residual
from .errors import EvaluationError, TooFewLandmarksError
from .mapper import Checkpoint, MapEstimate, RunResult
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


@dataclass(frozen=True)
class CheckpointScore:
    """The scores of one checkpoint of a run (metres; NEES dimensionless).

    The errors are NaN when the map shares fewer than 3 landmarks with the truth (the counts
    are still given); ``robot_*`` are NaN without poses; ``nees_landmark`` (the mean over the
    common landmarks) and ``nees_pose`` (the latest pose) are NaN without covariances.
    """

    t: int
    n_mapped: int
    estimate_s: float
    mpe_m: float
    rmse_m: float
    median_m: float
    max_m: float
    n_common: int
    robot_last_m: float
    robot_mean_m: float
    nees_landmark: float
    nees_pose: float


def score_checkpoints(result: RunResult | Sequence[Checkpoint], truth: Truth, *,
                      nees: bool = True) -> list[CheckpointScore]:
    """Score every checkpoint of a run (or a sequence of checkpoints) against ``truth``.

    A checkpoint whose map shares fewer than 3 landmarks with the truth gets NaN errors (and
    its counts); any other evaluation error is raised. ``nees=False`` leaves the NEES NaN.
    """
    checkpoints = result.checkpoints if isinstance(result, RunResult) else tuple(result)
    return [_score_checkpoint(c, truth, nees) for c in checkpoints]


def _score_checkpoint(c: Checkpoint, truth: Truth, nees: bool) -> CheckpointScore:
    nan = math.nan
    try:
        s = score_estimate(c.estimate, truth)
    except TooFewLandmarksError:
        common = np.intersect1d(c.estimate.landmark_ids, truth.landmark_ids).size
        return CheckpointScore(c.t, len(c.estimate), c.estimate_s, nan, nan, nan, nan,
                               int(common), nan, nan, nan, nan)
    nl = np_ = nan
    if nees:
        nl, np_ = _mean_landmark_nees(c.estimate, truth, s.alignment), pose_nees(
            c.estimate, truth, s.alignment)
    return CheckpointScore(c.t, len(c.estimate), c.estimate_s, s.mpe_m, s.rmse_m, s.median_m,
                           s.max_m, s.n_common, s.robot_last_m, s.robot_mean_m, nl, np_)


ERROR_COLUMNS = ("t", "mpe_m", "rmse_m", "median_m", "max_m", "n_mapped", "n_common",
                 "robot_last_m", "robot_mean_m")


def error_table(result: RunResult | Sequence[Checkpoint], truth: Truth) -> dict[str, np.ndarray]:
    """Errors at every checkpoint of a run, as columns (see ``ERROR_COLUMNS``): the rows of
    :func:`score_checkpoints` without the NEES, integer columns as int64."""
    rows = score_checkpoints(result, truth, nees=False)
    arr = np.array([[getattr(r, name) for name in ERROR_COLUMNS] for r in rows],
                   dtype=float).reshape(-1, len(ERROR_COLUMNS))
    return {name: (arr[:, k].astype(np.int64) if name in ("t", "n_mapped", "n_common")
                   else arr[:, k]) for k, name in enumerate(ERROR_COLUMNS)}


def landmark_nees(estimate: MapEstimate, truth: Truth, alignment: Alignment) -> np.ndarray:
    """Per-landmark NEES ``e^T P^-1 e`` (in the aligned frame), for estimates with covariances.

    The covariance is rotated with the alignment; values are only meaningful when the method's
    frame is anchored like the truth's (a rigid alignment of a consistent estimate).
    Returns shape ``(n_common,)``.
    """
    if estimate.landmark_cov is None:
        raise EvaluationError("the estimate has no landmark covariances")
    common, ie, it = np.intersect1d(estimate.landmark_ids, truth.landmark_ids,
                                    return_indices=True)
    e = alignment.apply(estimate.landmarks_xy[ie]) - truth.landmarks_xy[it]
    r = alignment.rotation
    cov = r @ estimate.landmark_cov[ie] @ r.T
    return np.einsum("ni,nij,nj->n", e, np.linalg.inv(cov), e)


def _mean_landmark_nees(estimate: MapEstimate, truth: Truth, alignment: Alignment) -> float:
    """The mean of :func:`landmark_nees`, NaN without covariances or with a singular one."""
    if estimate.landmark_cov is None:
        return math.nan
    try:
        return float(np.mean(landmark_nees(estimate, truth, alignment)))
    except np.linalg.LinAlgError:
        return math.nan


def pose_nees(estimate: MapEstimate, truth: Truth, alignment: Alignment) -> float:
    """NEES ``e^T P^-1 e`` of the latest estimated pose (x, y, psi) in the aligned frame.

    The error is ``(dx [m], dy [m], dpsi [rad])``; the 3x3 pose covariance is transformed by
    ``diag(R, det R)`` of the alignment (a reflection negates the heading). NaN when the
    estimate has no poses or no pose covariances, the truth has no poses, or the covariance is
    singular.
    """
    if (estimate.pose_cov is None or estimate.poses is None or truth.poses is None
            or not len(estimate.poses)):
        return math.nan
    k = int(np.argmax(estimate.pose_t))
    p = alignment.apply_poses(estimate.poses[k:k + 1])[0]
    true = truth.poses[estimate.pose_t[k]]
    e = np.array([p[0] - true[0], p[1] - true[1], float(angle_residual(p[2], true[2]))])
    t = np.eye(3)
    t[:2, :2] = alignment.rotation
    t[2, 2] = np.linalg.det(alignment.rotation)
    cov = t @ estimate.pose_cov[k] @ t.T
    try:
        return float(e @ np.linalg.solve(cov, e))
    except np.linalg.LinAlgError:
        return math.nan


__all__ = ["Alignment", "align", "MapScore", "score_estimate", "CheckpointScore",
           "score_checkpoints", "ERROR_COLUMNS", "error_table", "landmark_nees", "pose_nees"]
