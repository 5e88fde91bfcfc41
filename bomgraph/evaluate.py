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
from typing import Any, Callable, Sequence, Union

import numpy as np

from .angles import angle_residual
from .checks import is_integer, row_array
from .errors import (EvaluationError, OutOfRangeError, TooFewLandmarksError,
                     UndeterminedAlignmentError)
from .mapper import Checkpoint, MapEstimate, RunResult
from .stream import Truth
from .tables import counted
from .trajectory import PoseErrors, absolute_pose_errors, relative_pose_errors, rms


@dataclass(frozen=True)
class Alignment:
    """``x -> scale * R x + translation``; ``R`` is orthogonal, det -1 when reflected.

    ``rank`` is the rank of the fitted points' cross-covariance: 2 when the fit is determined;
    1 when a set is collinear (with reflection allowed, its mirror image across the line fits
    exactly as well); 0 when a set's points coincide (the rotation is undetermined).
    """

    rotation: np.ndarray
    translation: np.ndarray
    scale: float = 1.0
    rank: int = 2

    @property
    def reflected(self) -> bool:
        return bool(np.linalg.det(self.rotation) < 0)

    def apply(self, points_xy: np.ndarray) -> np.ndarray:
        """Transform ``(n, 2)`` points (returns a new array)."""
        p = row_array(points_xy, 2, "Alignment.apply(): points_xy", EvaluationError, copy=False)
        return self.scale * p @ self.rotation.T + self.translation

    def apply_poses(self, poses: np.ndarray) -> np.ndarray:
        """Transform ``(m, 3)`` poses: positions as points, headings through ``R``."""
        p = row_array(poses, 3, "Alignment.apply_poses(): poses", EvaluationError, copy=False)
        h = np.column_stack([np.cos(p[:, 2]), np.sin(p[:, 2])]) @ self.rotation.T
        return np.column_stack([self.apply(p[:, :2]), np.arctan2(h[:, 1], h[:, 0])])


#: A cross-covariance whose second singular value is below this fraction of the first is
#: rank 1 (collinear points): the mirror image fits as well to rounding.
RANK_TOL = 1e-9
#: Centred coordinates beyond 2**+-400 (about 1e+-120) are scaled by a power of two (exact)
#: before the products and the SVD, so that nothing overflows or underflows.
_SAFE_EXP = 400


def _exponent(x: np.ndarray) -> int:
    """The binary exponent of the largest magnitude in ``x`` (0 when all are 0 or none)."""
    m = float(np.max(np.abs(x))) if x.size else 0.0
    return 0 if m == 0 else math.frexp(m)[1]


def _mean(x: np.ndarray) -> np.ndarray:
    """Column means (of a 1-D array: the mean) without overflow or underflow (scaled by a
    power of two, exactly, when the values are huge or tiny)."""
    e = _exponent(x)
    if abs(e) < _SAFE_EXP:
        return x.mean(0)
    return np.ldexp(np.ldexp(x, -e).mean(0), e)


#: The largest coordinate magnitude (m) scored: beyond it an error (up to about 5x the
#: coordinates, after the centring, the rotation and the difference) may leave the
#: floating-point range (1.8e308). Below it every statistic is computed without overflow.
MAX_SCORED_M = 1e306


def _check_range(named: Sequence[tuple[str, np.ndarray]]) -> None:
    """Refuse (:class:`OutOfRangeError`) the first of the named coordinate arrays holding a
    magnitude above :data:`MAX_SCORED_M`."""
    for name, xy in named:
        top = float(np.max(np.abs(xy))) if xy.size else 0.0
        if top > MAX_SCORED_M:
            raise OutOfRangeError(f"the {name} reach {top:.3g} m, beyond the {MAX_SCORED_M:g} m "
                                  f"that can be scored (their errors would leave the "
                                  f"floating-point range): a diverged map, not scored")


def align_candidates(source_xy: np.ndarray, target_xy: np.ndarray, *,
                     allow_reflection: bool = True, with_scale: bool = False
                     ) -> tuple[Alignment, ...]:
    """Every least-squares transform taking ``source_xy`` onto ``target_xy`` (Umeyama, 1991).

    One alignment when the fit is determined. When a set is collinear (``rank`` 1) and
    reflection is allowed, the two mirror images across the line, which fit equally well; the
    first is what :func:`align` returns. Points are centred, and scaled by a power of two when
    their magnitude would overflow the products (1e154 and beyond), before the SVD.
    """
    src = row_array(source_xy, 2, "align(): source_xy", EvaluationError, copy=False)
    dst = row_array(target_xy, 2, "align(): target_xy", EvaluationError, copy=False)
    if not (np.all(np.isfinite(src)) and np.all(np.isfinite(dst))):
        raise EvaluationError("align(): points must be finite")
    if src.shape != dst.shape:
        raise EvaluationError(f"align(): {len(src)} source points but {len(dst)} targets")
    if len(src) < 3:
        raise TooFewLandmarksError(f"alignment needs at least 3 common landmarks, got {len(src)}")
    mu_s, mu_d = _mean(src), _mean(dst)
    a, b = src - mu_s, dst - mu_d
    ea, eb = (e if abs(e) >= _SAFE_EXP else 0 for e in (_exponent(a), _exponent(b)))
    a, b = np.ldexp(a, -ea), np.ldexp(b, -eb)  # exact rescaling (each set): the same rotation
    u, sv, vt = np.linalg.svd(b.T @ a)
    d = np.ones(2)
    if not allow_reflection and np.linalg.det(u @ vt) < 0:
        d[-1] = -1.0
    rank = 0 if not (sv[0] > 0 and np.any(a) and np.any(b)) else (
        1 if sv[1] <= RANK_TOL * sv[0] else 2)
    signs = [d] if (rank != 1 or not allow_reflection) else [d, d * np.array([1.0, -1.0])]
    out = []
    for dd in signs:
        r = (u * dd) @ vt
        scale = 1.0
        if with_scale:
            var = float((a ** 2).sum())
            if var == 0:
                raise UndeterminedAlignmentError("align(): all source points coincide; scale "
                                                 "is undefined")
            try:
                scale = math.ldexp(float((sv * dd).sum() / var), eb - ea)
            except OverflowError:
                raise OutOfRangeError("align(): the scale between the source and the target "
                                      "points leaves the floating-point range") from None
        out.append(Alignment(r, mu_d - scale * r @ mu_s, scale, rank))
    return tuple(out)


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

    A collinear set has two equally good fits (``rank`` 1): this returns the first of
    :func:`align_candidates`; :func:`score_estimate` breaks the tie with the poses.
    """
    return align_candidates(source_xy, target_xy, allow_reflection=allow_reflection,
                            with_scale=with_scale)[0]


ALIGN_ON = ("landmarks", "trajectory", "both")
"""What the alignment is fitted on: the common landmarks (the paper's), the robot positions
(evo's trajectory alignment) or both together."""

#: A reference to score against: the stream's truth, or another estimate (no truth).
Reference = Union[Truth, MapEstimate]


@dataclass(frozen=True)
class MapScore:
    """Errors of one estimate after alignment (metres, radians).

    ``robot_*`` and the pose errors are NaN when the estimate or the reference has no poses,
    or when the alignment leaves the robot undetermined (``ambiguous``: a collinear set whose
    mirror tie nothing breaks, or a rank-0 set). ``robot_last_m`` is the error of the latest
    estimated pose; ``robot_mean_m`` averages over all estimated poses. ``ape_*`` and
    ``rpe_*`` are RMS values of :mod:`bomgraph.trajectory`'s errors (``ape``, ``rpe``).
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
    align_on: str = "landmarks"
    ambiguous: bool = False
    ape_trans_rmse_m: float = math.nan
    ape_heading_rmse_rad: float = math.nan
    rpe_trans_rmse_m: float = math.nan
    rpe_heading_rmse_rad: float = math.nan
    rpe_delta: int = 1
    n_rpe_pairs: int = 0
    ape: PoseErrors | None = None
    rpe: PoseErrors | None = None

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for k, v in self.__dict__.items():
            if isinstance(v, (bool, np.bool_, str)):
                out[k] = v if isinstance(v, str) else bool(v)
            elif isinstance(v, (int, float, np.integer, np.floating)):
                out[k] = float(v) if isinstance(v, (float, np.floating)) else int(v)
        out["alignment_rank"] = self.alignment.rank
        out["reflected"] = self.alignment.reflected
        return out

    def __repr__(self) -> str:
        """The scalars only (the per-landmark arrays and pose errors are attributes)."""
        head = ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v!r}"
                         for k, v in self.as_dict().items())
        return f"MapScore({head})"


def _reference_poses(ref: Reference, est: MapEstimate) -> tuple[np.ndarray, np.ndarray,
                                                               np.ndarray] | None:
    """Rows of ``est``'s poses, and the reference poses, at the steps both hold (or None)."""
    if est.poses is None or not len(est.poses) or ref.poses is None:
        return None
    if isinstance(ref, MapEstimate):
        common, ie, ir = np.intersect1d(est.pose_t, ref.pose_t, return_indices=True)
        return (ie, common, ref.poses[ir]) if common.size else None
    ok = (est.pose_t >= 0) & (est.pose_t < len(ref.poses))
    if not np.all(ok):
        raise EvaluationError(f"estimate has poses at steps "
                              f"{est.pose_t[~ok][:5].tolist()} outside the truth's "
                              f"0..{len(ref.poses) - 1}")
    return np.arange(len(est.pose_t)), est.pose_t, ref.poses[est.pose_t]


def _sse(x: np.ndarray, y: np.ndarray) -> float:
    d = np.asarray(x, float) - np.asarray(y, float)
    m = float(np.max(np.abs(d))) if d.size else 0.0
    return 0.0 if m == 0 else float(((d / m) ** 2).sum()) * m * m


def _break_tie(cands: tuple[Alignment, ...], keys: list[Callable[[Alignment], float]]
               ) -> tuple[Alignment, bool]:
    """The candidate that is lower on the first key where the two differ (relative 1e-9);
    ``True`` with the first candidate when no key separates them."""
    if len(cands) == 1:
        return cands[0], cands[0].rank == 0
    for key in keys:
        v = [key(c) for c in cands]
        if abs(v[0] - v[1]) > 1e-9 * max(abs(v[0]), abs(v[1])) + 1e-300:
            return cands[int(np.argmin(v))], False
    return cands[0], True


def _check_pair(estimate: Any, truth: Any, where: str) -> None:
    """Refuse an estimate that is no MapEstimate and a reference that is neither."""
    if not isinstance(estimate, MapEstimate):
        hint = (" (arguments swapped? the estimate comes first)" if isinstance(estimate, Truth)
                else " (result.final or result.at(t))" if isinstance(estimate, RunResult)
                else "")
        raise EvaluationError(f"{where}(): estimate must be a MapEstimate, got "
                              f"{type(estimate).__name__}{hint}")
    if not isinstance(truth, (Truth, MapEstimate)):
        raise EvaluationError(f"{where}(): truth must be a Truth (stream.truth) or a reference "
                              f"MapEstimate, got {type(truth).__name__}"
                              + (" (the stream has no truth)" if truth is None else ""))


def score_estimate(estimate: MapEstimate, truth: Reference, *, allow_reflection: bool = True,
                   with_scale: bool = False, align_on: str = "landmarks",
                   delta: int = 1) -> MapScore:
    """Align ``estimate`` to ``truth`` and measure the landmark and pose errors.

    Parameters
    ----------
    truth : Truth, or a MapEstimate used as the reference (poses matched by step)
    align_on : ``"landmarks"`` (the paper's: the common landmarks), ``"trajectory"`` (the
        positions of the common poses, evo's APE alignment) or ``"both"`` (with no common
        pose, the landmarks alone, and the score's ``align_on`` says ``"landmarks"``)
    delta : steps between the two poses of a relative pose error

    A collinear fitting set (``Alignment.rank`` 1) has two mirror-image fits of equal cost:
    the tie is broken by the set not fitted (the positions, for a landmark fit; the landmarks,
    for a trajectory fit), then by the headings. When nothing breaks it, ``ambiguous`` is set
    and the pose errors are NaN, never a silent mirror.

    Raises
    ------
    TooFewLandmarksError
        If fewer than 3 landmarks are common to the estimate and the truth.
    UndeterminedAlignmentError
        For a trajectory fit, fewer than 3 common poses; with ``with_scale``, every fitted
        point of the estimate at one place.
    OutOfRangeError
        A common landmark or pose beyond :data:`MAX_SCORED_M` (a diverged map).
    """
    _check_pair(estimate, truth, "score_estimate")
    if not (is_integer(delta) and delta >= 1):
        raise EvaluationError(f"delta must be an integer >= 1 (steps between the two poses "
                              f"of a relative pose error), got {delta!r:.40}")
    if align_on not in ALIGN_ON:
        raise EvaluationError(f"align_on must be one of {', '.join(ALIGN_ON)}, got {align_on!r}")
    common, ie, it = np.intersect1d(estimate.landmark_ids, truth.landmark_ids,
                                    return_indices=True)
    whose = "reference estimate" if isinstance(truth, MapEstimate) else "truth"
    if common.size < 3 and align_on != "trajectory":
        raise TooFewLandmarksError(f"the estimate shares {counted(common.size, 'landmark')} "
                                   f"with the {whose}; alignment needs at least 3")
    est_xy = estimate.landmarks_xy[ie]
    true_xy = truth.landmarks_xy[it]
    pr = _reference_poses(truth, estimate)
    est_p = estimate.poses[pr[0]] if pr is not None else np.zeros((0, 3))
    ref_p = pr[2] if pr is not None else np.zeros((0, 3))
    if align_on == "trajectory" and len(est_p) < 3:
        without = ("estimate" if estimate.poses is None or not len(estimate.poses) else
                   whose if truth.poses is None or not len(truth.poses) else None)
        raise UndeterminedAlignmentError(
            f"a trajectory alignment needs at least 3 common poses, got {len(est_p)}"
            + (f" (the {without} has no poses: align on landmarks)" if without else ""))
    _check_range([("estimate's landmark coordinates", est_xy),
                  ("estimate's robot positions", est_p[:, :2]),
                  (f"{whose}'s landmark coordinates", true_xy),
                  (f"{whose}'s robot positions", ref_p[:, :2])])
    if align_on == "both" and not len(est_p):  # no common poses: a fit on the landmarks,
        align_on = "landmarks"                  # and said so (MapScore.align_on)
    src = {"landmarks": est_xy, "trajectory": est_p[:, :2],
           "both": np.vstack([est_xy, est_p[:, :2]])}[align_on]
    dst = {"landmarks": true_xy, "trajectory": ref_p[:, :2],
           "both": np.vstack([true_xy, ref_p[:, :2]])}[align_on]
    cands = align_candidates(src, dst, allow_reflection=allow_reflection,
                             with_scale=with_scale)
    keys = {"landmarks": [lambda c: _sse(c.apply(est_p[:, :2]), ref_p[:, :2])],
            "trajectory": [lambda c: _sse(c.apply(est_xy), true_xy)],
            "both": []}[align_on]
    keys.append(lambda c: _sse(angle_residual(c.apply_poses(est_p)[:, 2], ref_p[:, 2]), 0.0))
    al, ambiguous = _break_tie(cands, keys)
    err = (np.hypot(*(al.apply(est_xy) - true_xy).T) if common.size
           else np.zeros(0))
    nan = math.nan
    robot_last = robot_mean = nan
    n_poses = 0
    ape = rpe = None
    if pr is not None and not (ambiguous and align_on == "landmarks"):
        t = pr[1]
        moved = al.apply_poses(est_p)
        ape = absolute_pose_errors(t, moved, ref_p)
        rpe = relative_pose_errors(t, moved, ref_p, delta)
        robot_last = float(ape.translation_m[np.argmax(t)])
        robot_mean = float(_mean(ape.translation_m))
        n_poses = int(len(t))
    if ambiguous and align_on != "landmarks":
        err = np.full(len(err), nan)
    stat = (lambda f: float(f(err))) if err.size else (lambda f: nan)
    return MapScore(mpe_m=stat(_mean), rmse_m=rms(err),
                    median_m=stat(np.median), max_m=stat(np.max),
                    n_mapped=int(len(estimate.landmark_ids)),
                    n_truth=int(len(truth.landmark_ids)), n_common=int(common.size),
                    robot_last_m=robot_last, robot_mean_m=robot_mean, n_poses=n_poses,
                    landmark_ids=common, errors_m=err, alignment=al, align_on=align_on,
                    ambiguous=ambiguous,
                    ape_trans_rmse_m=ape.translation_rmse_m if ape else nan,
                    ape_heading_rmse_rad=ape.heading_rmse_rad if ape else nan,
                    rpe_trans_rmse_m=rpe.translation_rmse_m if rpe else nan,
                    rpe_heading_rmse_rad=rpe.heading_rmse_rad if rpe else nan,
                    rpe_delta=delta, n_rpe_pairs=len(rpe) if rpe else 0, ape=ape, rpe=rpe)


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
    ape_trans_rmse_m: float = math.nan
    ape_heading_rmse_rad: float = math.nan
    rpe_trans_rmse_m: float = math.nan
    rpe_heading_rmse_rad: float = math.nan


def score_checkpoints(result: RunResult | Sequence[Checkpoint], truth: Reference, *,
                      nees: bool = True, align_on: str = "landmarks", delta: int = 1,
                      with_scale: bool = False) -> list[CheckpointScore]:
    """Score every checkpoint of a run (or a sequence of checkpoints) against ``truth`` (or a
    reference estimate), aligned as :func:`score_estimate` with ``align_on``.

    A checkpoint whose map shares fewer than 3 landmarks with the truth (or fewer than 3
    poses, for a trajectory alignment; or, with ``with_scale``, whose landmarks all sit at one
    point) gets NaN errors (and its counts); any other evaluation error is raised.
    ``nees=False`` leaves the NEES NaN (as does a reference estimate).
    """
    if isinstance(result, MapEstimate) or not isinstance(result, (RunResult, Sequence)):
        raise EvaluationError(f"score_checkpoints(): result must be a RunResult or a sequence "
                              f"of Checkpoint, got {type(result).__name__}"
                              + (" (score one map with score_estimate)"
                                 if isinstance(result, MapEstimate) else ""))
    checkpoints = result.checkpoints if isinstance(result, RunResult) else tuple(result)
    bad = next((c for c in checkpoints if not isinstance(c, Checkpoint)), None)
    if bad is not None:
        raise EvaluationError(f"score_checkpoints(): items must be Checkpoint, got "
                              f"{type(bad).__name__}")
    if checkpoints:
        _check_pair(checkpoints[0].estimate, truth, "score_checkpoints")
    return [_score_checkpoint(c, truth, nees and isinstance(truth, Truth), align_on, delta,
                              with_scale) for c in checkpoints]


def _score_checkpoint(c: Checkpoint, truth: Reference, nees: bool, align_on: str,
                      delta: int, with_scale: bool) -> CheckpointScore:
    nan = math.nan
    try:
        s = score_estimate(c.estimate, truth, align_on=align_on, delta=delta,
                           with_scale=with_scale)
    except (TooFewLandmarksError, UndeterminedAlignmentError, OutOfRangeError):
        common = np.intersect1d(c.estimate.landmark_ids, truth.landmark_ids).size
        return CheckpointScore(c.t, len(c.estimate), c.estimate_s, nan, nan, nan, nan,
                               int(common), nan, nan, nan, nan)
    nl = np_ = nan
    if nees:
        nl, np_ = mean_landmark_nees(c.estimate, truth, s.alignment), pose_nees(
            c.estimate, truth, s.alignment)
    return CheckpointScore(c.t, len(c.estimate), c.estimate_s, s.mpe_m, s.rmse_m, s.median_m,
                           s.max_m, s.n_common, s.robot_last_m, s.robot_mean_m, nl, np_,
                           s.ape_trans_rmse_m, s.ape_heading_rmse_rad, s.rpe_trans_rmse_m,
                           s.rpe_heading_rmse_rad)


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

    The covariance is carried with the map, ``(s R) P (s R)^T`` for the alignment's rotation
    ``R`` and scale ``s``; values are only meaningful when the method's frame is anchored like
    the truth's (a rigid alignment of a consistent estimate).
    Returns shape ``(n_common,)``, NaN for a landmark whose covariance block is all NaN (the
    method reports none for it: not defined) or leaves the floating-point range when carried;
    ``inf`` for a NEES beyond that range (computed without overflow below it).
    """
    if estimate.landmark_cov is None:
        raise EvaluationError("the estimate has no landmark covariances (landmark_cov): use a "
                              "method that gives them, ekf, ekf-invdepth, or a GTSAM method "
                              "with covariances=True")
    common, ie, it = np.intersect1d(estimate.landmark_ids, truth.landmark_ids,
                                    return_indices=True)
    e = alignment.apply(estimate.landmarks_xy[ie]) - truth.landmarks_xy[it]
    r = alignment.scale * alignment.rotation
    with np.errstate(over="ignore", invalid="ignore"):  # a scale of 1e300: not defined
        cov = r @ estimate.landmark_cov[ie] @ r.T
    out = np.full(len(ie), math.nan)
    defined = np.isfinite(cov).all(axis=(1, 2))
    k = _exponent(e[defined])   # e scaled by 2^-k (exactly): NEES = 4^k e'^T P^-1 e'
    q = np.einsum("ni,nij,nj->n", np.ldexp(e[defined], -k), np.linalg.inv(cov[defined]),
                  np.ldexp(e[defined], -k))
    with np.errstate(over="ignore"):  # beyond the floating-point range: inf
        out[defined] = np.ldexp(q, 2 * k)
    return out


def mean_landmark_nees(estimate: MapEstimate, truth: Truth, alignment: Alignment) -> float:
    """The mean of :func:`landmark_nees` over the common landmarks that have a covariance
    (those without one, all-NaN blocks, are left out, never counted as a value); NaN without
    covariances, with none defined, or with a singular one."""
    if estimate.landmark_cov is None:
        return math.nan
    try:
        nees = landmark_nees(estimate, truth, alignment)
    except np.linalg.LinAlgError:
        return math.nan
    nees = nees[~np.isnan(nees)]  # inf (beyond the floating-point range) is a value
    return float(_mean(nees)) if nees.size else math.nan


def pose_nees(estimate: MapEstimate, truth: Truth, alignment: Alignment) -> float:
    """NEES ``e^T P^-1 e`` of the latest estimated pose (x, y, psi) in the aligned frame.

    The error is ``(dx [m], dy [m], dpsi [rad])``; the 3x3 pose covariance is transformed by
    ``diag(s R, det R)`` of the alignment (a reflection negates the heading; a similarity's
    scale ``s`` scales the position, not the heading). NaN when the
    estimate has no poses or no pose covariances, the truth has no poses, or the covariance is
    singular or not defined (all NaN).
    """
    if (estimate.pose_cov is None or estimate.poses is None or truth.poses is None
            or not len(estimate.poses)):
        return math.nan
    k = int(np.argmax(estimate.pose_t))
    p = alignment.apply_poses(estimate.poses[k:k + 1])[0]
    true = truth.poses[estimate.pose_t[k]]
    e = np.array([p[0] - true[0], p[1] - true[1], float(angle_residual(p[2], true[2]))])
    t = np.eye(3)
    t[:2, :2] = alignment.scale * alignment.rotation
    t[2, 2] = np.linalg.det(alignment.rotation)
    if np.isnan(estimate.pose_cov[k]).all():
        return math.nan
    with np.errstate(over="ignore", invalid="ignore"):
        cov = t @ estimate.pose_cov[k] @ t.T
    if not np.all(np.isfinite(cov)):   # carried beyond the floating-point range
        return math.nan
    scale = _exponent(e)   # e scaled by 2^-scale (exactly), as in landmark_nees
    e = np.ldexp(e, -scale)
    try:
        q = float(e @ np.linalg.solve(cov, e))
    except np.linalg.LinAlgError:
        return math.nan
    try:
        return math.ldexp(q, 2 * scale)
    except OverflowError:   # beyond the floating-point range
        return math.inf


__all__ = ["Alignment", "RANK_TOL", "align_candidates", "align", "ALIGN_ON", "Reference", "MapScore", "score_estimate", "CheckpointScore",
           "score_checkpoints", "ERROR_COLUMNS", "error_table", "landmark_nees",
           "mean_landmark_nees", "pose_nees"]
