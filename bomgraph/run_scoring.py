"""What one run of a sweep is scored against, checkpoint by checkpoint (paper section IV's
metrics, :func:`bomgraph.evaluate.score_checkpoints`), for the runner
(:func:`bomgraph.bench.run_task`).

A stream with ground truth is scored against it. A stream without is scored against the
final map (and trajectory) of the sweep's reference method: run once per stream in a process
and kept for the other arms' runs there (:func:`reference_map`); the arm that runs exactly as
the reference (:func:`runs_as_reference`) is that run: it runs once, its checkpoints are
scored against its own final map after it (:class:`CheckpointScorer`), and that map is kept
for the others; a reference that fails there is remembered as well, so that the other arms'
runs fail at once with its error (:func:`failed_reference`), not run it again (in that
sweep: :func:`forget_failures`). Kept maps and failures are keyed by the reference's code as
this process runs it, so an edited and reloaded reference is run anew. Without a
reference, a run gets the truth-free measures only: landmarks mapped and the RMS bearing
residual of each map and trajectory against the stream's own bearings (also given beside
the scores on a stream without truth).

A run scored against its own map (the reference's, or an arm of its method and options at
another cadence: :func:`self_scored`) has errors that are no measure of accuracy: compare
marks it (:func:`mark_self_scored`), and the tables and figures leave them out
(:func:`scores_left_out`).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass, replace
from typing import Any, Callable, Collection, Mapping, Sequence

from .errors import StreamValueError, exception_line
from .evaluate import CheckpointScore, score_checkpoints
from .experiments import Arm, Experiment, Task
from .mapper import Checkpoint, MapEstimate, RunResult, create_mapper, method_info, run
from .method_code import method_code
from .sources import FileSource
from .stream import Stream, Truth
from .stream_file import located
from .trajectory import BearingResidualSums

#: Reference maps kept per process (stream, reference, cadence); the oldest goes first.
MAX_REFERENCES = 8
#: Bytes of maps (landmarks and trajectory, no covariances) a run that is its own reference
#: keeps to score them after it: each holds the trajectory so far, so they grow as T^2
#: (Victoria Park, 6,969 steps, a map every 10: about 80 MB). Beyond this the run is made
#: again, scored against the first run's final map as it goes (the same rows).
MAX_KEPT_BYTES = 256 * 2 ** 20

#: What a run scored against its own map keeps of each checkpoint row for the tables and
#: figures (:func:`scores_left_out`): its counts, time and truth-free bearing RMS. Its errors
#: and NEES are against its own map (rounding at its end) or, an arm of the reference's
#: method and options at another cadence, against the same map: no measure of accuracy.
UNSCORED_KEYS = ("t", "n_mapped", "estimate_s", "n_common", "bearing_rms_rad")


@dataclass(frozen=True)
class ReferenceFailure:
    """A reference that raised on a stream: the error its other arms' runs there fail with
    (``"reference LABEL failed: ..."``) and its traceback."""

    error: str
    traceback: str


_REFERENCES: dict[str, MapEstimate | ReferenceFailure] = {}


def run_arm(task: Task, arm: Arm, stream: Stream,
            on_checkpoint: Callable[[Checkpoint], None]) -> RunResult:
    """The arm on the stream, each checkpoint handed to ``on_checkpoint`` as it is taken and
    only the last kept (each map holds the trajectory so far: kept, they grow as T^2)."""
    truth = stream.truth
    needs_truth = method_info(arm.method).needs_truth
    try:
        mapper = create_mapper(arm.method, stream.header,
                               truth=truth if needs_truth else None, **dict(arm.options))
        return run(mapper, stream.steps, checkpoint_every=_every(task, arm), method=arm.label,
                   on_checkpoint=on_checkpoint, keep_checkpoints=False)
    except StreamValueError as exc:  # the method's refusal: a stream file's name and line
        if isinstance(task.source, FileSource):
            raise located(exc, task.source.path, arm.method) from None
        raise


def _every(task: Task, arm: Arm) -> int:
    """The checkpoint cadence ``arm`` runs at in ``task``."""
    return arm.checkpoint_every or task.checkpoint_every


def same_method(arm: Arm, reference: Arm | None) -> bool:
    """Whether ``arm`` runs the method of ``reference`` with the same options, whatever the
    labels and checkpoint cadences."""
    return (reference is not None and reference.method == arm.method
            and json.dumps(dict(reference.options), sort_keys=True)
            == json.dumps(dict(arm.options), sort_keys=True))


def runs_as_reference(task: Task) -> bool:
    """Whether the task's arm runs exactly as its reference does (the same method, options
    and checkpoints, whatever the labels): on a stream without truth its run *is* the
    reference's, scored against its own final map."""
    ref = task.reference
    return (ref is not None and same_method(task.arm, ref)
            and _every(task, ref) == _every(task, task.arm))


def _reference_key(task: Task) -> str:
    """What the kept reference map (or failure) is kept by: the stream, the reference arm,
    the cadence and the code of the reference's methods as this process runs them
    (:func:`bomgraph.method_code.method_code`: a plugin or a run-time method edited and
    reloaded since, or a constant of it set, is another reference; h73: a library user who
    fixed a failing reference got its old failure again in the next compare)."""
    assert task.reference is not None
    code = method_code(replace(task, arm=task.reference))
    return json.dumps({"source": task.source.key(), "ref": task.reference.key(),
                       "every": task.checkpoint_every, "code": code}, sort_keys=True)


def keep_reference(task: Task, final: MapEstimate | ReferenceFailure
                   ) -> MapEstimate | ReferenceFailure:
    """Keep ``final``, the reference method's final map on the task's stream (or how it
    failed there), for the other tasks of the same stream and reference that run in this
    process; returns it."""
    key = _reference_key(task)
    _REFERENCES.pop(key, None)
    while len(_REFERENCES) >= MAX_REFERENCES:
        _REFERENCES.pop(next(iter(_REFERENCES)))
    _REFERENCES[key] = final
    return final


def reference_map(task: Task, stream: Stream) -> MapEstimate:
    """The final estimate of the task's reference method on its stream: run here, unless a
    task of this process has run it (or was it) already."""
    assert task.reference is not None
    kept = _REFERENCES.get(_reference_key(task))
    if isinstance(kept, MapEstimate):
        return kept
    final = run_arm(task, task.reference, stream, lambda c: None).final
    keep_reference(task, final)
    return final


def failed_reference(task: Task) -> ReferenceFailure | None:
    """How the task's reference failed on its stream, if a task of this process saw it fail
    (:func:`keep_reference`): the task fails with that, not running it again."""
    kept = _REFERENCES.get(_reference_key(task)) if task.reference is not None else None
    return kept if isinstance(kept, ReferenceFailure) else None


def forget_failures() -> None:
    """Forget the references that failed in this process (:func:`failed_reference`): a new
    sweep runs them again, as a failure is never cached (what it failed on may be fixed);
    their maps are kept."""
    for key in [k for k, v in _REFERENCES.items() if isinstance(v, ReferenceFailure)]:
        del _REFERENCES[key]


def self_scored_arms(experiments: Sequence[Experiment]) -> set[tuple[str, str]]:
    """(experiment, label) of each arm of the method and options of its experiment's
    reference (:func:`same_method`), whatever its checkpoint cadence."""
    return {(e.name, a.label) for e in experiments for a in e.arms
            if same_method(a, e.reference)}


def self_scored(result: Mapping[str, Any], alike: Collection[tuple[str, str]]) -> str:
    """How a run (a result of :func:`bomgraph.bench.run_task`, or a row of
    :func:`bomgraph.summaries.final_by_run`) was scored against its own map, on a stream
    without truth: ``"itself"``, the run was the reference's (``scored_against``
    ``"itself (...)"``); ``"method"``, an arm of ``alike`` (:func:`self_scored_arms`: the
    reference's method and options at another checkpoint cadence) scored against the
    reference's map, the same map but for the cadence; ``""``, neither (a score), or a run
    that failed (no map, no score: h73; it was marked ``"itself"``, and the figures' titles
    said its curve was left out as scored against its own map)."""
    if not result.get("ok", True):
        return ""
    if isinstance(result.get("self_scored"), str) and result["self_scored"]:
        return result["self_scored"]
    against = str(result.get("scored_against", ""))
    if against.startswith("itself"):
        return "itself"
    if against.startswith("reference ") and (result.get("experiment"),
                                             result.get("arm")) in alike:
        return "method"
    return ""


def scored_against(result: Mapping[str, Any]) -> str:
    """What a run on a stream without truth was scored against, for the summary: its
    ``scored_against``, and for an arm of the reference's method and options (``self_scored``
    ``"method"``) that this is no score."""
    against = str(result.get("scored_against", "truth"))
    if result.get("self_scored") == "method":
        return f"{against} (its method and options: no score)"
    return against


def mark_self_scored(results: Sequence[dict[str, Any]], experiments: Sequence[Experiment]
                     ) -> list[dict[str, Any]]:
    """``results``, each run scored against its own map (:func:`self_scored`) given
    ``self_scored`` (``"itself"`` or ``"method"``), its values kept (results.json); the
    others as they are (the same objects: a run with truth is never touched)."""
    alike = self_scored_arms(experiments)
    out = []
    for r in results:
        kind = self_scored(r, alike)
        if kind:
            r["self_scored"] = kind
        out.append(r)
    return out


def not_drawn_line(results: Sequence[Mapping[str, Any]]) -> str:
    """A figure title's line naming the arms of ``results`` (one experiment's) whose runs
    marked ``self_scored`` are left out of it: an arm alone when none of its runs is drawn,
    ``ARM on k of n runs`` when its other runs are (its runs on streams with truth); ``""``
    when none is left out."""
    counts: dict[str, list[int]] = {}
    for r in results:
        count = counts.setdefault(r["arm"], [0, 0])
        count[0] += bool(r.get("self_scored"))
        count[1] += 1
    parts = [arm if k == n else f"{arm} on {k} of {n} runs" for arm, (k, n) in counts.items()
             if k]
    return f"\nnot drawn: {', '.join(parts)} (scored against its own map)" if parts else ""


def scores_left_out(result: Mapping[str, Any]) -> Mapping[str, Any]:
    """``result`` for a table or figure: a run marked ``self_scored``
    (:func:`mark_self_scored`) as a copy with only the :data:`UNSCORED_KEYS` of each
    checkpoint (the rest NaN), so that no score of a map against itself is averaged, drawn
    or shown as accuracy; any other run as it is."""
    if not result.get("self_scored"):
        return result
    return {**result, "checkpoints": [{k: v if k in UNSCORED_KEYS else math.nan
                                       for k, v in c.items()}
                                      for c in result.get("checkpoints", [])]}


def bearing_rms(estimate: MapEstimate, stream: Stream) -> float:
    """RMS bearing residual [rad] of ``estimate`` against the stream's bearings (NaN without
    poses or without a bearing on a mapped landmark): a truth-free score."""
    if estimate.poses is None or not len(estimate):
        return math.nan
    sums = BearingResidualSums(estimate.landmark_ids, estimate.landmarks_xy, estimate.pose_t,
                               estimate.poses,   # summed exactly, as ``evaluate`` sums them
                               mirrored=False)
    sums.add_steps(stream.steps)
    return sums.rms_rad


def _unscored(c: Checkpoint) -> dict[str, Any]:
    """A checkpoint row without a reference: the counts, NaN errors (as a map sharing fewer
    than 3 landmarks with the truth)."""
    nan = math.nan
    return asdict(CheckpointScore(c.t, len(c.estimate), c.estimate_s, nan, nan, nan, nan, 0,
                                  nan, nan, nan, nan))


class CheckpointScorer:
    """Scores a run's checkpoints, called with each as the run takes it.

    Against ``truth`` (the stream's, or a reference's final map), as they come; with ``own``
    (the arm is its own reference), each map is kept (without its covariances, which a
    score against a map does not use) and scored by :meth:`against` once the run's final
    map is known, unless they come to more than :data:`MAX_KEPT_BYTES` (``overflow``: none
    kept, the run is to be made again against its final map). ``rows``: the scored
    checkpoints; ``failure``: why a map could not be scored (the rest are then left);
    ``seconds``: the time taken while the run ran, to be taken off its wall time.
    """

    def __init__(self, stream: Stream, truth: Truth | MapEstimate | None, *,
                 own: bool = False) -> None:
        self.stream, self.truth, self.own = stream, truth, own
        self.rows: list[dict[str, Any]] = []
        self.failure = ""
        self.seconds = 0.0
        self.overflow = False
        self._kept: list[tuple[Checkpoint, float]] = []
        self._bytes = 0

    def __call__(self, c: Checkpoint) -> None:
        if self.failure:  # the run has failed already; its later maps are not scored
            return
        t0 = time.perf_counter()
        try:
            if self.own and not self.overflow:
                slim = replace(c.estimate, landmark_cov=None, pose_cov=None, info={})
                self._bytes += sum(a.nbytes for a in (slim.landmark_ids, slim.landmarks_xy,
                                                      slim.pose_t, slim.poses) if a is not None)
                self._kept.append((Checkpoint(c.t, slim, c.estimate_s),
                                   bearing_rms(c.estimate, self.stream)))
                if self._bytes > MAX_KEPT_BYTES:
                    self.overflow, self._kept = True, []
            else:
                self.rows.append(self._row(c, self.truth))
        except Exception as exc:  # an unscorable estimate is a failed run, with the reason
            self.failure = "scoring failed: " + exception_line(exc)
        self.seconds += time.perf_counter() - t0

    def against(self, reference: MapEstimate) -> None:
        """Score the kept checkpoints of an ``own`` run against its final map."""
        kept, self._kept = self._kept, []
        for c, brg in kept:
            if self.failure:
                return
            try:
                self.rows.append(self._row(c, reference, brg))
            except Exception as exc:
                self.failure = "scoring failed: " + exception_line(exc)

    def _row(self, c: Checkpoint, truth: Truth | MapEstimate | None,
             brg: float | None = None) -> dict[str, Any]:
        row = _unscored(c) if truth is None else asdict(score_checkpoints([c], truth)[0])
        if self.stream.truth is None:
            row["bearing_rms_rad"] = bearing_rms(c.estimate, self.stream) if brg is None else brg
        return row


__all__ = ["CheckpointScorer", "MAX_REFERENCES", "ReferenceFailure", "UNSCORED_KEYS",
           "bearing_rms", "failed_reference", "forget_failures", "keep_reference",
           "mark_self_scored", "reference_map", "run_arm", "runs_as_reference", "same_method",
           "scored_against", "scores_left_out", "self_scored", "self_scored_arms"]
