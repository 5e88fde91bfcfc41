"""``bomgraph evaluate``: an estimate file scored against a stream file's ground truth, a
reference estimate, or, for a stream with neither, by what the stream itself can tell.

:func:`evaluate_files` reads both files, refuses a mismatched pair (the estimate's recorded
stream identity, checkpoints beyond the stream) and scores every checkpoint
(:func:`bomgraph.evaluate.score_checkpoints`: landmark MPE, APE and RPE, NEES from the file's
covariances); :func:`format_evaluation` prints it as text, JSON, CSV, Markdown or LaTeX. A
stream without ground truth and no ``--reference`` gets the truth-free measures only: per
checkpoint, the landmarks mapped and the RMS bearing residual of the map and trajectory
against the stream's own bearings (:func:`bearing_consistency`), the measure ``compare``
reports for such streams.

The stream is read once and its steps are not kept: what the scores need from it is its
header's truth (poses and landmarks), its identity (hashed as it is read) and the bearing
residuals' sums of squares (:class:`~bomgraph.trajectory.BearingResidualSums`, added up
exactly batch by batch), so memory grows with the poses and landmarks, not the bearings.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, replace
from typing import Any, Sequence

import numpy as np

from .checks import option_named
from .errors import BomgraphError, EvaluationError, StreamFormatError, shown_path
from .evaluate import (CheckpointScore, MapScore, error_table, mean_landmark_nees, pose_nees,
                       score_checkpoints, score_estimate)
from .estimate_file import EstimateFile, read_estimate, stream_identity
from .jsonio import jsonable
from .mapper import MapEstimate
from .stream import Step, Truth
from .stream_file import StreamReader
from .stream_identity import StreamHasher, StreamIdentity
from .tables import Column, counted, fixed_or_exponent, format_table
from .trajectory import BearingResidualSums, bearing_arrays

#: The per-checkpoint table of ``bomgraph evaluate`` (SI in JSON/CSV; cm and deg shown).
EVALUATION_COLUMNS = (
    Column("t", "t"), Column("n_mapped", "mapped"), Column("n_common", "common"),
    Column("mpe_m", "MPE [cm]", 100, ".2f"), Column("rmse_m", "RMSE [cm]", 100, ".2f"),
    Column("median_m", "median [cm]", 100, ".2f"), Column("max_m", "max [cm]", 100, ".2f"),
    Column("robot_last_m", "robot [cm]", 100, ".2f"),
    Column("ape_trans_rmse_m", "APE [cm]", 100, ".2f"),
    Column("ape_heading_rmse_rad", "APE [deg]", 180 / math.pi, ".2f"),
    Column("rpe_trans_rmse_m", "RPE [cm]", 100, ".2f"),
    Column("rpe_heading_rmse_rad", "RPE [deg]", 180 / math.pi, ".2f"),
    Column("nees_landmark", "NEES lm", 1, ".2f"), Column("nees_pose", "NEES pose", 1, ".2f"))

#: The per-checkpoint table of a stream without ground truth (and no reference).
TRUTH_FREE_COLUMNS = (
    Column("t", "t"), Column("n_mapped", "mapped"), Column("n_bearings", "bearings"),
    Column("bearing_rms_rad", "bearing RMS [deg]", 180 / math.pi, ".3f"))


@dataclass(frozen=True)
class BearingConsistency:
    """RMS bearing residual [rad] of an estimate against its own map and trajectory over the
    ``n`` bearings they cover (no truth needed), and the same for its mirror image."""

    n: int
    rms_rad: float
    mirrored_rms_rad: float


def bearing_consistency(estimate: MapEstimate, steps: Sequence[Step]) -> BearingConsistency:
    """:func:`bomgraph.trajectory.bearing_residuals` of ``estimate`` as RMS values (summed
    exactly: :class:`~bomgraph.trajectory.BearingResidualSums`, as ``evaluate`` sums them
    while reading a stream file)."""
    sums = _residual_sums(estimate)
    sums.add_steps(steps)
    return _consistency(sums)


def _residual_sums(estimate: MapEstimate, until_t: int | None = None) -> BearingResidualSums:
    return BearingResidualSums(estimate.landmark_ids, estimate.landmarks_xy, estimate.pose_t,
                               estimate.poses, until_t)


def _consistency(sums: BearingResidualSums) -> BearingConsistency:
    if sums.n == 0:  # no poses, or no bearing covered: as bearing_residuals' empty array
        return BearingConsistency(0, math.nan, math.nan)
    return BearingConsistency(sums.n, sums.rms_rad, sums.mirrored_rms_rad)


def method_label(est: EstimateFile) -> str:
    """The method that wrote ``est`` as ``--methods`` names it: ``NAME@PRESET`` when its
    header's options name a preset (``compare --estimates`` of ``stmds-smacof@improved``),
    else ``NAME``."""
    preset = (est.options or {}).get("preset")
    return f"{est.method}@{preset}" if est.method and isinstance(preset, str) else est.method


@dataclass(frozen=True)
class FileEvaluation:
    """An estimate file scored against a stream file's truth or a reference estimate: the
    final map's score, one :class:`bomgraph.evaluate.CheckpointScore` per checkpoint, and the
    truth-free bearing consistency of the estimate (and of the reference). Against neither
    (``score`` None): ``free_rows``, per checkpoint ``t``, ``n_mapped``, ``n_bearings`` and
    ``bearing_rms_rad``."""

    method: str
    score: MapScore | None
    table: dict[str, np.ndarray] | None
    rows: tuple[CheckpointScore, ...] = ()
    reference: str | None = None
    bearing: BearingConsistency | None = None
    reference_bearing: BearingConsistency | None = None
    nees_landmark: float = math.nan
    nees_pose: float = math.nan
    nees_undefined: tuple[int, bool] = (0, False)
    free_rows: tuple[dict[str, Any], ...] = ()
    poses_revised: bool = False

    def as_dict(self) -> dict[str, Any]:
        if self.score is None:
            return {"method": self.method, "reference": None, "truth": False,
                    **{k: v for k, v in self.free_rows[-1].items() if k != "t"},
                    "checkpoints": {c.name: [r[c.name] for r in self.free_rows]
                                    for c in TRUTH_FREE_COLUMNS}}
        out: dict[str, Any] = {"method": self.method, "reference": self.reference,
                               **self.score.as_dict(), "nees_landmark": self.nees_landmark,
                               "nees_pose": self.nees_pose,
                               "nees_landmarks_without_cov": self.nees_undefined[0],
                               "nees_pose_without_cov": self.nees_undefined[1],
                               "poses_revised": self.poses_revised}
        for name, b in (("bearing", self.bearing), ("reference_bearing", self.reference_bearing)):
            if b is not None:
                out[f"{name}_rms_rad"] = b.rms_rad
                out[f"{name}_mirrored_rms_rad"] = b.mirrored_rms_rad
                out[f"{name}_n"] = b.n
        if self.rows:
            out["checkpoints"] = {c.name: [getattr(r, c.name) for r in self.rows]
                                  for c in EVALUATION_COLUMNS}
        return out


def evaluate_files(estimate_path: str | os.PathLike[str], stream_path: str | os.PathLike[str],
                   *, with_scale: bool = False, align_on: str = "landmarks", delta: int = 1,
                   reference_path: str | os.PathLike[str] | None = None) -> FileEvaluation:
    """Score an estimate file against the ground truth of a stream file, or, with
    ``reference_path``, against another estimate file (its final map and poses).

    A stream without ground truth, and no reference: the truth-free measures of every
    checkpoint (:class:`FileEvaluation`, ``score`` None).

    Raises
    ------
    EvaluationError
        The estimate (or the reference) was computed from another stream (its recorded
        identity differs), or the estimate has checkpoints beyond the stream's last step, or
        the map shares fewer than 3 landmarks with the truth or reference.

    The NEES against the truth (landmarks: the mean over the common ones; pose: the latest)
    come from the file's covariances, carried by the alignment (its scale too, with
    ``with_scale``, as in the checkpoint rows), and are NaN without them.
    """
    est, est_error = _read_estimate_later(estimate_path)
    ref_est, ref_error = (None, None) if reference_path is None else \
        _read_estimate_later(reference_path)
    try:
        with StreamReader(stream_path) as reader:
            truth = reader.truth
            sums = _bearing_sums(est, ref_est, truth)
            ident = _read_steps(reader, list(sums.values()))
    except StreamFormatError as exc:
        if _is_estimate_file(stream_path):
            raise EvaluationError(f"{shown_path(stream_path)} is an estimate file, not a stream "
                                  f"(arguments "
                                  f"swapped? usage: bomgraph evaluate ESTIMATE STREAM)") from None
        raise exc from None
    if est is None:  # the stream's errors first, as when it was read whole
        raise est_error  # type: ignore[misc]
    _check_identity(est, ident, estimate_path, stream_path)
    last = ident.n_steps - 1
    beyond = [c.t for c in est.checkpoints if c.t > last]
    if beyond:
        raise EvaluationError(f"{shown_path(estimate_path)}: checkpoint t = {beyond[0]} is beyond "
                              f"the last "
                              f"step t = {last} of {shown_path(stream_path)}")
    if ref_error is not None:
        raise ref_error
    if ref_est is not None:  # scored against its final map: it must be of the same stream
        _check_identity(ref_est, ident, reference_path, stream_path)
    if ref_est is None and truth is None:
        if with_scale or align_on != "landmarks" or delta != 1:
            given = ", ".join(option_named(o, p) for o, p in (
                ("--similarity", "with_scale"), ("--align", "align_on"), ("--delta", "delta")))
            raise EvaluationError(f"{shown_path(stream_path)}: the stream has no ground truth, so "
                                  f"there is "
                                  f"nothing to align to ({given}); give "
                                  f"{option_named('--reference EST', 'reference_path')}, or "
                                  f"drop them for the truth-free measures")
        free = []
        for k, c in enumerate(est.checkpoints or (None,)):
            e = est.final if c is None else c.estimate
            b = _consistency(sums[k])
            free.append({"t": None if c is None else c.t, "n_mapped": len(e),
                         "n_bearings": b.n, "bearing_rms_rad": b.rms_rad})
        return FileEvaluation(method_label(est), None, None,
                              bearing=_consistency(sums["final"]), free_rows=tuple(free))
    target = ref_est.final if ref_est is not None else truth
    kw = dict(with_scale=with_scale, align_on=align_on, delta=delta)
    try:
        score = score_estimate(est.final, target, **kw)
    except EvaluationError as exc:  # say which file and map; the checkpoint rows say '-'
        at = f" (t = {est.checkpoints[-1].t})" if est.checkpoints else ""
        against = ("" if reference_path is None else " against the final map of "
                   + option_named("--reference", "reference_path", reference_path))
        raise type(exc)(f"{shown_path(estimate_path)}: the final map{at}{against}: "
                        f"{exc}") from None
    rows = tuple(score_checkpoints(est.checkpoints, target, **kw)) if est.checkpoints else ()
    revised = est.version >= 2 and poses_revised(est)
    if revised:  # the earlier rows' trajectories are first estimates, not the method's then
        rows = tuple(_without_trajectory(r, align_on) for r in rows[:-1]) + rows[-1:]
    table = (error_table(est.checkpoints, truth)
             if est.checkpoints and ref_est is None and align_on == "landmarks" else None)
    if revised and table is not None:  # as in the rows: no mean over first estimates
        table["robot_mean_m"][:-1] = math.nan
    nl = np_ = math.nan
    undefined = (0, False)
    if ref_est is None and truth is not None:  # the alignment's scale, if fitted, is carried
        nl = mean_landmark_nees(est.final, truth, score.alignment)
        undefined = _undefined_covariances(est.final, truth)
        np_ = pose_nees(est.final, truth, score.alignment)
    return FileEvaluation(method_label(est), score, table, rows,
                          None if ref_est is None else (method_label(ref_est)
                                                        or str(reference_path)),
                          _consistency(sums["final"]),
                          None if ref_est is None else _consistency(sums["reference"]),
                          nl, np_, undefined, poses_revised=revised)


def _read_estimate_later(path: str | os.PathLike[str]) -> tuple[EstimateFile | None,
                                                                 BomgraphError | None]:
    """The estimate file at ``path``, or the error reading it, raised once the stream has
    been read (a broken stream is reported first, as when the stream was read before)."""
    try:
        return read_estimate(path), None
    except BomgraphError as exc:
        return None, exc


def _bearing_sums(est: EstimateFile | None, ref_est: EstimateFile | None,
                  truth: Truth | None) -> dict[Any, BearingResidualSums]:
    """The bearing residual sums :func:`evaluate_files` reports, to be fed the stream:
    ``"final"`` (and ``"reference"``) over every step; without truth or reference, also one
    per checkpoint ``k`` (0, 1, ...) over the steps up to it."""
    if est is None:
        return {}
    sums: dict[Any, BearingResidualSums] = {"final": _residual_sums(est.final)}
    if ref_est is not None:
        sums["reference"] = _residual_sums(ref_est.final)
    elif truth is None:
        for k, c in enumerate(est.checkpoints or (None,)):
            sums[k] = (_residual_sums(est.final) if c is None
                       else _residual_sums(c.estimate, until_t=c.t))
    return sums


#: Steps and bearings read before the bearing sums are fed (bounds :func:`_read_steps`).
_BATCH_STEPS, _BATCH_BEARINGS = 4096, 1 << 16


def _read_steps(reader: StreamReader, sums: Sequence[BearingResidualSums]) -> StreamIdentity:
    """Read the steps of ``reader`` once, feeding their bearings to ``sums`` in batches (the
    steps are not kept: memory bounded by one batch); the stream's identity."""
    hasher = StreamHasher()
    batch: list[Step] = []
    n_bearings = 0
    for st in reader:
        hasher.add(st)
        batch.append(st)
        n_bearings += len(st.landmark_ids)
        if len(batch) >= _BATCH_STEPS or n_bearings >= _BATCH_BEARINGS:
            _feed(batch, sums)
            batch, n_bearings = [], 0
    _feed(batch, sums)
    return hasher.identity


def _feed(steps: list[Step], sums: Sequence[BearingResidualSums]) -> None:
    if not steps:
        return
    t, ids, brg = bearing_arrays(steps)
    for s in sums:
        if s.until_t is None or s.until_t >= steps[0].t:
            s.add(t, ids, brg)


def _undefined_covariances(final: MapEstimate, truth: Truth) -> tuple[int, bool]:
    """How many common landmarks have an all-NaN covariance block (no covariance: left out
    of the landmark NEES) and whether the latest pose has one (no pose NEES)."""
    n_lm = 0
    if final.landmark_cov is not None:
        _, ie, _ = np.intersect1d(final.landmark_ids, truth.landmark_ids, return_indices=True)
        n_lm = int(np.isnan(final.landmark_cov[ie]).all(axis=(1, 2)).sum())
    pose = bool(final.pose_cov is not None and len(final.pose_cov) and
                np.isnan(final.pose_cov[int(np.argmax(final.pose_t))]).all())
    return n_lm, pose


def poses_revised(est: EstimateFile) -> bool:
    """Whether the method revised or dropped poses after first estimating them: the final
    trajectory differs from the one an earlier checkpoint reads back (version 2 keeps each
    pose of an earlier checkpoint as first estimated, docs/FORMATS.md), so the trajectories
    of the earlier checkpoints are not the ones the method held then."""
    if len(est.checkpoints) < 2:
        return False
    before, final = est.checkpoints[-2].estimate, est.final
    if before.poses is None or not len(before.poses):
        return False
    if final.poses is None:
        return True
    at = {int(t): k for k, t in enumerate(final.pose_t)}
    idx = [at.get(int(t), -1) for t in before.pose_t]
    return -1 in idx or not np.array_equal(final.poses[idx], before.poses)


def _without_trajectory(row: CheckpointScore, align_on: str) -> CheckpointScore:
    """``row`` without what its read-back trajectory decides: APE, RPE and the mean robot
    error; with an alignment fitted on the trajectory, every error."""
    nan = math.nan
    if align_on != "landmarks":
        return replace(row, mpe_m=nan, rmse_m=nan, median_m=nan, max_m=nan,
                       robot_last_m=nan, robot_mean_m=nan, nees_landmark=nan, nees_pose=nan,
                       ape_trans_rmse_m=nan, ape_heading_rmse_rad=nan, rpe_trans_rmse_m=nan,
                       rpe_heading_rmse_rad=nan)
    return replace(row, robot_mean_m=nan, ape_trans_rmse_m=nan, ape_heading_rmse_rad=nan,
                   rpe_trans_rmse_m=nan, rpe_heading_rmse_rad=nan)


def check_stream_identity(est: EstimateFile, steps: Sequence[Step],
                          estimate_path: str | os.PathLike[str],
                          stream_path: str | os.PathLike[str],
                          error: type[BomgraphError] = EvaluationError) -> None:
    """Refuse an estimate whose recorded stream identity (:func:`bomgraph.estimate_file.
    stream_identity`) is not that of ``steps``: it was computed from another stream. An
    estimate without a recorded identity (version 1, or written by a library call) passes.
    Raises ``error`` (``evaluate``: :class:`EvaluationError`; ``export``: ExportError)."""
    _check_identity(est, stream_identity(steps), estimate_path, stream_path, error)


def _check_identity(est: EstimateFile, ident: StreamIdentity,
                    estimate_path: str | os.PathLike[str], stream_path: str | os.PathLike[str],
                    error: type[BomgraphError] = EvaluationError) -> None:
    """:func:`check_stream_identity` against the identity ``ident`` of the stream."""
    if est.stream is None:
        return
    if ident != est.stream:
        what = (f"{est.stream.n_steps} steps recorded, the stream has {ident.n_steps}"
                if ident.n_steps != est.stream.n_steps else
                f"steps SHA-256 {est.stream.steps_sha256[:12]}... recorded, the stream's "
                f"is {ident.steps_sha256[:12]}...")
        raise error(f"{shown_path(estimate_path)} was computed from another stream than "
                    f"{shown_path(stream_path)} "
                    f"({what})")


def _is_estimate_file(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is an estimate file, even a broken one (to recognise swapped
    arguments): its first line names the estimate format, or the whole file reads as one."""
    try:
        with open(path, "rb") as fh:
            head = json.loads(fh.readline(2**16))
        if isinstance(head, dict) and head.get("format") == "bomgraph-estimate":
            return True
    except (OSError, ValueError, RecursionError):   # RecursionError: a line nested too deep
        pass
    try:
        read_estimate(path)
    except (StreamFormatError, OSError):
        return False
    return True


def _revised_note(align_on: str) -> str:
    """Said where the rows before the last leave out what their trajectories decide
    (:func:`_without_trajectory`): aligned on the landmarks, the APE and RPE; aligned on the
    trajectory or on both, every error."""
    left_out = ("no APE or RPE ('-')" if align_on == "landmarks" else
                f"no error at all ('-'; aligned on {align_on}, which needs the trajectory)")
    return (f"before the last checkpoint {left_out}: the method revised its poses later and "
            f"the file keeps each pose only as first estimated")


def _fit_note(s: MapScore) -> str:
    """What a rank-deficient fit (:class:`~bomgraph.evaluate.Alignment` ``rank`` < 2) leaves
    undefined, as :func:`~bomgraph.evaluate.score_estimate` decides it: a set at one point
    fixes no rotation; a collinear one has a mirror tie, broken by what was not fitted or by
    the headings, or not at all."""
    undefined = f"{'robot' if s.align_on == 'landmarks' else 'landmark'} errors undefined"
    if s.alignment.rank == 0:
        return f"the fitted set is one point: the rotation is undetermined, {undefined}"
    if s.ambiguous:
        return f"the fitted set is collinear: the mirror tie is unbroken, {undefined}"
    by = {"landmarks": "the robot positions or headings",
          "trajectory": "the landmarks or the headings", "both": "the headings"}[s.align_on]
    return f"the fitted set is collinear: mirror tie broken by {by}"


def format_evaluation(ev: FileEvaluation, fmt: str = "text") -> str:
    """The evaluation as ``fmt`` (:data:`bomgraph.tables.FORMATS`): text gives counts,
    landmark errors [cm], robot errors and the per-checkpoint table; JSON the whole
    evaluation; CSV, Markdown and LaTeX the per-checkpoint table (the final map's row when
    the file has no checkpoints)."""
    if ev.score is None:
        return _format_truth_free(ev, fmt)
    rows = [asdict(r) for r in ev.rows] or [{**ev.score.as_dict(), "t": None}]
    against = f"reference {ev.reference}" if ev.reference else "truth"
    revised = ev.poses_revised and len(ev.rows) > 1
    title = (f"{ev.method} against the {against}, aligned on {ev.score.align_on}; RPE over "
             f"{counted(ev.score.rpe_delta, 'step')}"
             + (f"; {_revised_note(ev.score.align_on)}" if revised else ""))
    if fmt == "json":
        return json.dumps(jsonable(ev.as_dict()), allow_nan=False)
    if fmt != "text":
        return format_table(EVALUATION_COLUMNS, rows, fmt, title=title)
    s = ev.score
    na = (lambda v, k=100, f=".2f", u=" cm": "-" if not math.isfinite(v)
          else fixed_or_exponent(v, f, k) + u)
    lines = [f"method {ev.method}: {s.n_common} of {s.n_truth} landmarks of the {against} "
             f"mapped ({s.n_mapped} in the estimate); aligned on {s.align_on}"
             f"{', reflected' if s.alignment.reflected else ''}",
             f"  landmark MPE {na(s.mpe_m)}, RMSE {na(s.rmse_m)}, "
             f"median {na(s.median_m)}, max {na(s.max_m)}"]
    if s.alignment.rank < 2:
        lines.append(f"  {_fit_note(s)}")
    if s.n_poses:
        lines.append(f"  robot position error: last {na(s.robot_last_m)}, mean over "
                     f"{s.n_poses} poses {na(s.robot_mean_m)}")
        lines.append(f"  APE RMSE {na(s.ape_trans_rmse_m)}, heading "
                     f"{na(s.ape_heading_rmse_rad, 180 / math.pi, '.3f', ' deg')}; RPE "
                     f"(delta {s.rpe_delta}, {s.n_rpe_pairs} pairs) RMSE "
                     f"{na(s.rpe_trans_rmse_m)}, heading "
                     f"{na(s.rpe_heading_rmse_rad, 180 / math.pi, '.3f', ' deg')}")
    n_lm, pose = ev.nees_undefined
    nees = [f"{name} " + (fixed_or_exponent(v, ".2f") if math.isfinite(v) else
                          "beyond the floating-point range") for name, v in (
        ("landmark (mean" + (f"; {n_lm} without a covariance left out)" if n_lm else ")"),
         ev.nees_landmark), ("latest pose", ev.nees_pose)) if not math.isnan(v)]
    if pose:
        nees.append("latest pose none (it has no covariance)")
    if nees:
        lines.append(f"  NEES from the file's covariances: {', '.join(nees)}")
    for name, b in (("estimate", ev.bearing), ("reference", ev.reference_bearing)):
        if b is not None and b.n:
            lines.append(f"  bearing residual RMS of the {name} against its own map and "
                         f"trajectory: {b.rms_rad:.4f} rad over {b.n} bearings (mirrored: "
                         f"{b.mirrored_rms_rad:.4f} rad)")
    if len(ev.rows) > 1:
        lines.append("")
        if ev.poses_revised:
            lines.append(_revised_note(s.align_on))
        lines.append(format_table(EVALUATION_COLUMNS, rows, "text"))
    return "\n".join(lines)



def _format_truth_free(ev: FileEvaluation, fmt: str) -> str:
    """:func:`format_evaluation` of a stream without truth (``ev.score`` None)."""
    title = (f"{ev.method}: no ground truth in the stream (nor --reference): truth-free "
             f"measures only")
    if fmt == "json":
        return json.dumps(jsonable(ev.as_dict()), allow_nan=False)
    if fmt != "text":
        return format_table(TRUTH_FREE_COLUMNS, ev.free_rows, fmt, title=title)
    last = ev.free_rows[-1]
    lines = [title, f"  final map: {counted(int(last['n_mapped']), 'landmark')}"]
    b = ev.bearing
    if b is not None and b.n:
        lines.append(f"  bearing residual RMS against its own map and trajectory: "
                     f"{b.rms_rad:.4f} rad ({math.degrees(b.rms_rad):.3f} deg) over {b.n} "
                     f"bearings (mirrored: {b.mirrored_rms_rad:.4f} rad)")
    else:
        lines.append("  no bearing of the stream is covered by the estimate's map and poses")
    if len(ev.free_rows) > 1:
        lines += ["", format_table(TRUTH_FREE_COLUMNS, ev.free_rows, "text")]
    return "\n".join(lines)


__all__ = ["EVALUATION_COLUMNS", "TRUTH_FREE_COLUMNS", "BearingConsistency",
           "bearing_consistency", "FileEvaluation", "evaluate_files", "check_stream_identity",
           "poses_revised", "format_evaluation"]
