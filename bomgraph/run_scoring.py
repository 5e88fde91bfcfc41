"""What one run of a sweep is scored against, checkpoint by checkpoint (paper section IV's
metrics, :func:`bomgraph.evaluate.score_checkpoints`), for the runner
(:func:`bomgraph.bench.run_task`).

A stream with ground truth is scored against it. A stream without is scored against the
final map (and trajectory) of the sweep's reference method: run once per stream in a process
and kept for the other arms' runs there (:func:`reference_map`); the arm that runs exactly as
the reference (:func:`runs_as_reference`) is that run: it runs once, its checkpoints are
scored against its own final map after it (:class:`CheckpointScorer`), and that map is kept
for the others. Without a reference, a run gets the truth-free measures only: landmarks
mapped and the RMS bearing residual of each map and trajectory against the stream's own
bearings (also given beside the scores on a stream without truth).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, replace
from typing import Any, Callable

from .evaluate import CheckpointScore, score_checkpoints
from .experiments import Arm, Task
from .mapper import Checkpoint, MapEstimate, RunResult, create_mapper, method_info, run
from .stream import Stream, Truth
from .trajectory import BearingResidualSums

#: Reference maps kept per process (stream, reference, cadence); the oldest goes first.
MAX_REFERENCES = 8
#: Bytes of maps (landmarks and trajectory, no covariances) a run that is its own reference
#: keeps to score them after it: each holds the trajectory so far, so they grow as T^2
#: (Victoria Park, 6,969 steps, a map every 10: about 80 MB). Beyond this the run is made
#: again, scored against the first run's final map as it goes (the same rows).
MAX_KEPT_BYTES = 256 * 2 ** 20

_REFERENCES: dict[str, MapEstimate] = {}


def run_arm(task: Task, arm: Arm, stream: Stream,
            on_checkpoint: Callable[[Checkpoint], None]) -> RunResult:
    """The arm on the stream, each checkpoint handed to ``on_checkpoint`` as it is taken and
    only the last kept (each map holds the trajectory so far: kept, they grow as T^2)."""
    truth = stream.truth
    needs_truth = method_info(arm.method).needs_truth
    mapper = create_mapper(arm.method, stream.header, truth=truth if needs_truth else None,
                           **dict(arm.options))
    return run(mapper, stream.steps, checkpoint_every=_every(task, arm), method=arm.label,
               on_checkpoint=on_checkpoint, keep_checkpoints=False)


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
    assert task.reference is not None
    return json.dumps({"source": task.source.key(), "ref": task.reference.key(),
                       "every": task.checkpoint_every}, sort_keys=True)


def keep_reference(task: Task, final: MapEstimate) -> MapEstimate:
    """Keep ``final``, the reference method's final map on the task's stream, for the other
    tasks of the same stream and reference that run in this process; returns it."""
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
    if kept is not None:
        return kept
    return keep_reference(task, run_arm(task, task.reference, stream, lambda c: None).final)


def bearing_rms(estimate: MapEstimate, stream: Stream) -> float:
    """RMS bearing residual [rad] of ``estimate`` against the stream's bearings (NaN without
    poses or without a bearing on a mapped landmark): a truth-free score."""
    if estimate.poses is None or not len(estimate):
        return math.nan
    sums = BearingResidualSums(estimate.landmark_ids, estimate.landmarks_xy, estimate.pose_t,
                               estimate.poses)   # summed exactly, as ``evaluate`` sums them
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
            self.failure = f"scoring failed: {type(exc).__name__}: {exc}"
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
                self.failure = f"scoring failed: {type(exc).__name__}: {exc}"

    def _row(self, c: Checkpoint, truth: Truth | MapEstimate | None,
             brg: float | None = None) -> dict[str, Any]:
        row = _unscored(c) if truth is None else asdict(score_checkpoints([c], truth)[0])
        if self.stream.truth is None:
            row["bearing_rms_rad"] = bearing_rms(c.estimate, self.stream) if brg is None else brg
        return row


__all__ = ["CheckpointScorer", "MAX_REFERENCES", "bearing_rms", "keep_reference",
           "reference_map", "run_arm", "runs_as_reference", "same_method"]
