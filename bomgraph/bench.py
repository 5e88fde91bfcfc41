"""The runner (paper section IV's experiments): tasks executed serially, in local processes
(joblib) or on a Dask cluster, and a cache of finished tasks.

:func:`run_task` is a pure function of a :class:`~bomgraph.experiments.Task` (the stream is
simulated from its seed or read from its recording): it runs the method, scores every
checkpoint with :func:`bomgraph.evaluate.score_checkpoints`, and returns a JSON-ready dict.
So results are identical whether tasks run serially, in processes or on Dask, and a finished
task is cached as a small JSON file, keyed by the task and the code that ran it, so an
interrupted sweep resumes.

The core never prints: progress is reported through a callback.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import hashlib
import json
import logging
import os
import socket
import tempfile
import traceback
import uuid
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

import numpy as np

from .checks import echo, instance, is_integer, option_named
from .errors import (BomgraphError, ConfigError, OutOfRangeError, StreamFormatError,
                     TooFewLandmarksError, UnknownMethodError, exception_line)
from .estimate_file import write_estimate
from .evaluate import score_estimate
from .experiments import Task
from .jsonio import jsonable
from .mapper import MapEstimate, RunResult, method_failure_note
from .method_code import (bomgraph_edited, method_code, new_sweep, noting_runs,
                          refuse_runtime_methods, stale_after_run, stale_here, stale_plugin,
                          uncacheable, warn_sourceless, workers_outdated)
from .plugins import code_fingerprint
from .processes import daemonic, workers_asked
from .result_cache import read_cached, strip_timings, write_cached  # re-exported
from .result_cache import remove_cache_leftovers
from .run_scoring import (CheckpointScorer, ReferenceFailure, failed_reference, forget_failures,
                          keep_reference, reference_map, run_arm, runs_as_reference)
from .stream import Stream, Truth
from .file_run import run_example, run_file  # re-exported: bench.run_file, bench.run_example
from .stream_file import count_steps  # re-exported: bench.count_steps
from .stream_identity import identity_of_stream
from .sweep import scheduler_address_problem
from .tables import counted
from .worker_log import SAID, kept_warnings, said_once, say_kept

#: Bump to invalidate every cached result (the code fingerprint covers code changes).
_log = logging.getLogger(__name__)
CACHE_VERSION = 1


def task_key(task: Task, *, disk: bool = False,
             memo: dict[str, str | None] | None = None) -> str:
    """A content hash of the task, the cache version and the code: the same task run by the
    same code always has the same key (its cache file name). The code is the bomgraph and
    baselines sources and, for a plugin or a method registered at run time, the sources of
    its package and its version (:func:`bomgraph.method_code.method_fingerprint`): as this
    process runs them, or with ``disk`` as a worker process that imports them now runs
    them (they differ after an edit that this process has not reloaded). ``memo``: as
    :func:`bomgraph.method_code.method_code` (one dict per sweep and ``disk``)."""
    ident: dict[str, Any] = {**task.identity(), "v": CACHE_VERSION, "code": code_fingerprint()}
    plugin_code = method_code(task, disk=disk, memo=memo)
    if plugin_code:
        ident["method_code"] = plugin_code
    blob = json.dumps(ident, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:20]


def run_task(task: Task) -> dict[str, Any]:
    """Simulate (or read) the task's stream, run its method, and score every checkpoint.

    Returns a JSON-ready dict: per-checkpoint errors, timings, the method's final diagnostics.
    A method that raises is recorded as a failure with the reason, never dropped. The task
    runs with single-threaded BLAS: the matrices are small, parallelism is across tasks, and
    multithreaded BLAS on small matrices stalls on a loaded machine
    (docs/measurements.md).

    A stream without ground truth is scored against the final map (and poses) of the task's
    reference method when it has one (``scored_against``: ``"reference LABEL"``; the arm
    that runs as the reference runs once, scored against its own final map: ``"itself
    (reference LABEL)"``; :mod:`bomgraph.run_scoring`), else only by truth-free metrics:
    landmarks mapped and ``bearing_rms_rad``, the RMS bearing residual of each checkpoint's
    map and trajectory against the stream's own bearings.
    """
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        return _run_task(task)


#: True while :func:`_indexed` runs a task: in a worker (local or Dask), not in the process
#: that made the task (a serial run), for what a failure tells to do.
_IN_WORKER: contextvars.ContextVar[bool] = contextvars.ContextVar("in_worker", default=False)


def _failure(exc: BaseException) -> str:
    """``"Type: message (raised in Name.step() at t = 5)"``: a failed run's error."""
    note = method_failure_note(exc)
    return exception_line(exc) + (f" ({note})" if note else "")


def _unloadable(exc: BaseException) -> str:
    """A failed run's error for a task that a worker cannot key, though the process that made
    the task could: a method it cannot load or hash (no plugin there, or one broken by an
    edit since), a stream file it cannot read, or another error (its traceback is kept)."""
    first = (str(exc).splitlines() or [""])[0].split("; known methods")[0]
    where = (f"{type(exc).__name__}: {first}, in the process {os.getpid()} on "
             f"{socket.gethostname()}, which ran it")
    if isinstance(exc, (UnknownMethodError, ImportError)):
        return (f"{where}; every worker needs bomgraph and your plugins importable (installed "
                f"there, or on the PYTHONPATH the workers start with): fix that and restart "
                f"the workers (finished runs are cached)")
    if isinstance(exc, (StreamFormatError, OSError)):  # FileSource.key hashes the file
        return (f"{where}; every worker reads the stream files at the paths the sweep gives "
                f"(a folder shared at the same path): make the file readable there and run "
                f"again (finished runs are cached)")
    return f"{where} (traceback in results.json)"


def _traceback(exc: BaseException) -> str:
    """The last frames of ``exc``'s traceback (its notes included), for results.json."""
    return "".join(traceback.format_exception(exc, limit=-12))


def _run_task(task: Task) -> dict[str, Any]:
    out: dict[str, Any] = {"experiment": task.experiment, "arm": task.arm.label,
                           "method": task.arm.method, "run": task.source.name, "key": None}
    try:  # in a worker, what the client could key and it cannot: a failed run, not a raise
        out["key"] = task_key(task, disk=_IN_WORKER.get())  # a worker runs the files'
        stale = stale_plugin(task, worker=_IN_WORKER.get())
    except Exception as exc:
        if not _IN_WORKER.get():  # the process that made the task: its error, as it keyed it
            if not isinstance(exc, (StreamFormatError, OSError)):
                raise
            # its stream file went (or changed into garbage) during the sweep: a source that
            # cannot be read is a failed run, as below
            out.update(ok=False, error=exception_line(exc))
            return out
        out.update(ok=False, error=_unloadable(exc))
        if not isinstance(exc, (UnknownMethodError, ImportError, StreamFormatError, OSError)):
            out["traceback"] = _traceback(exc)
        return out
    if stale:
        out.update(ok=False, error=stale)
        return out
    try:
        stream = task.stream()
    except Exception as exc:  # a source that cannot be read is a failed run, with the reason
        out.update(ok=False, error=exception_line(exc))
        return out
    truth: Truth | MapEstimate | None = stream.truth
    own = truth is None and runs_as_reference(task)
    # none with the truth (the paper's results keep their shape), a failed run's too: it
    # was set as "truth" before any run, and a failed run on a stream without truth said
    # so in final_by_run.csv (h68)
    if own:  # this run is the reference's: run once, scored against its own final map
        out["scored_against"] = f"itself (reference {task.reference.label})"
    elif truth is None and task.reference is not None:
        out["scored_against"] = f"reference {task.reference.label}"
        failed = failed_reference(task)  # it failed here already: not run again (h72)
        if failed is None:
            try:
                truth = reference_map(task, stream)
            except Exception as exc:  # no reference, no score: a failed run with the reason
                failed = _reference_failed(task, exc)
        if failed is not None:
            out.update(ok=False, error=failed.error, traceback=failed.traceback)
            return out
    elif truth is None:
        out["scored_against"] = "none"
    score = CheckpointScorer(stream, truth, own=own)  # as the run goes, outside its timing
    try:
        result = run_arm(task, task.arm, stream, score)
    except Exception as exc:  # a failing method is a result, reported with its reason
        out.update(ok=False, error=_failure(exc), traceback=_traceback(exc))
        if own:  # the reference failed: the other arms' runs here fail with it at once
            _reference_failed(task, exc)
        _log.debug("%s on %s failed", task.arm.label, task.source.name,  # the traceback on
                   exc_info=exc)                                           # lines of its own
        return out
    if own:  # kept for the other arms' runs on this stream in this process
        truth = result.final
        keep_reference(task, truth)
        if score.overflow:  # too many maps to keep: the run again, against its final map
            _log.info("%s on %s: its maps are too large to keep: run again, scored against "
                      "its final map", task.arm.label, task.source.name)
            score = CheckpointScorer(stream, truth)
            try:
                result = run_arm(task, task.arm, stream, score)
            except Exception as exc:  # as the first time: a result, with its reason
                out.update(ok=False, error=_failure(exc), traceback=_traceback(exc))
                return out
        else:
            score.against(truth)
    # its package edited during the run (a module it imported since): code of neither key
    if score.failure or (stale := stale_after_run(task, worker=_IN_WORKER.get())):
        out.update(ok=False, error=score.failure or stale)
        return out
    info = jsonable(dict(result.final.info), max_items=64)   # a numpy bool_: a bool
    converged = info.get("converged")
    if not (converged is None or isinstance(converged, bool)):   # h98: see _odd_converged
        converged = None
    final = result.final
    out["final_map"] = None
    if truth is not None:
        try:  # the final map and trajectory in the truth's frame, for the map figures
            al = score_estimate(final, truth).alignment
            out["final_map"] = {
                "landmarks": [[int(i), float(x), float(y)] for i, (x, y)
                              in zip(final.landmark_ids, al.apply(final.landmarks_xy))],
                "poses": ([] if final.poses is None else
                          [[int(t), float(x), float(y)] for t, (x, y)
                           in zip(final.pose_t, al.apply(final.poses[:, :2]))])}
        except (TooFewLandmarksError, OutOfRangeError):  # no map to draw: its rows say '-'
            pass
    out.update(ok=True, checkpoints=score.rows, total_s=result.total_s - score.seconds,
               step_median_s=float(np.median(result.step_s)),
               converged=converged, info=info)
    if task.keep_estimate:
        out["estimate_file"] = _estimate_text(task, stream, result)
    return out


def _reference_failed(task: Task, exc: BaseException) -> ReferenceFailure:
    """The task's reference raised ``exc`` on its stream: kept for the other arms' runs
    there in this process (:func:`~bomgraph.run_scoring.failed_reference`), as its map
    would be."""
    assert task.reference is not None
    failed = ReferenceFailure(f"reference {task.reference.label} failed: " + _failure(exc),
                              _traceback(exc))
    keep_reference(task, failed)
    return failed


def _estimate_text(task: Task, stream: Stream, result: RunResult) -> str:
    """The run's final estimate as the text of an estimate file (version 2: the final map
    and trajectory, covariances if any, the stream's identity, the method's registered name
    and the arm's options: what ``bomgraph run --method`` takes to redo it; the arm's label is
    in ``index.csv``), written by the canonical writer on the worker (remote or not) and
    handed back in the result."""
    with tempfile.TemporaryDirectory(prefix="bomgraph-est-") as d:
        path = os.path.join(d, "final.est")
        write_estimate(replace(result, method=task.arm.method), path,
                       stream=identity_of_stream(stream),
                       options=dict(task.arm.options),
                       checkpoint_every=task.arm.checkpoint_every or task.checkpoint_every)
        with open(path, encoding="utf-8") as fh:
            return fh.read()


@dataclass(frozen=True)
class Executor:
    """Where tasks run: ``"serial"``, ``"processes"`` (joblib, one per core by default) or
    ``"dask"`` (an existing scheduler at ``scheduler`` or a local cluster of
    ``dask_local`` workers). ``scheduler_from``: the words naming where ``scheduler`` came
    from in errors (:meth:`choose`: a sweep file's key; default the ``--scheduler`` flag)."""

    backend: str = "processes"
    n_jobs: int = -1
    scheduler: str | None = None
    dask_local: int = 0
    scheduler_from: str | None = field(default=None, compare=False)

    def scheduler_named(self) -> str:
        """The scheduler address as errors name it: ``--scheduler ADDRESS`` (from Python:
        ``scheduler='ADDRESS'``), or the sweep file's key and value when it came from there."""
        if self.scheduler_from is None:
            return option_named("--scheduler", "scheduler", self.scheduler)
        return f'{self.scheduler_from} = "{self.scheduler}"'

    def __post_init__(self) -> None:
        if self.backend not in ("serial", "processes", "dask"):
            raise ConfigError(f"backend must be serial, processes or dask, got {self.backend!r}")
        workers_asked(self.n_jobs)
        if not (is_integer(self.dask_local) and self.dask_local >= 0):
            raise ConfigError(f"dask_local must be an integer >= 0, got {self.dask_local!r}")
        if self.backend == "dask" and not (self.scheduler or self.dask_local > 0):
            raise ConfigError("the dask backend needs a scheduler address or dask_local > 0")
        if self.scheduler is not None:
            problem = scheduler_address_problem(self.scheduler)
            if problem:
                raise ConfigError(f"{self.scheduler_named()}: {problem}")

    @classmethod
    def choose(cls, jobs: int | None = None, scheduler: str | None = None,
               dask_local: int | None = None, *,
               defaults: Mapping[str, Any] | None = None) -> "Executor":
        """Dask when a ``scheduler`` or ``dask_local`` workers are given, else serial for
        ``jobs == 1``, else ``jobs`` local processes (-1, the default: one per core). When
        all three are None they are taken from ``defaults`` (a sweep file's ``[executor]``:
        ``jobs``, ``scheduler``, ``dask_local``, and ``file``, its name, for the errors about
        its scheduler); any one given (the command line) sets the whole of ``defaults``
        aside, as ``--jobs 1`` overrides a file's ``dask_local``."""
        if scheduler == "":   # an unset variable: not "no scheduler", nor the file's
            raise ConfigError(f"{option_named('--scheduler', 'scheduler')} is empty; give the "
                              f"address `dask scheduler` printed, e.g. tcp://HOST:8786")
        given = jobs is not None or scheduler is not None or dask_local is not None
        d = {} if given else dict(defaults or {})
        jobs = d.get("jobs", -1) if jobs is None else jobs
        named = None
        if not scheduler and d.get("scheduler"):
            scheduler = d["scheduler"]
            named = f"{d['file']}: executor.scheduler" if d.get("file") else \
                "[executor] scheduler"
        dask_local = d.get("dask_local", 0) if dask_local is None else dask_local
        if scheduler or dask_local:
            return cls("dask", scheduler=scheduler, dask_local=dask_local or 0,
                       scheduler_from=named)
        if jobs == 1:
            return cls("serial")
        return cls("processes", n_jobs=jobs)


def _cache_path(cache_dir: Path, task: Task, key: str | None = None, disk: bool = False
                ) -> Path | None:
    """One file per (arm, source, code) (``key``: the task's :func:`task_key`, computed when
    not given): experiments that share an arm share its runs. None for a task whose method
    has no source file to hash, or, run here (not ``disk``), a value set that cannot be
    hashed (:func:`~bomgraph.method_code.uncacheable`): its results are neither read from
    nor written to the cache."""
    return None if uncacheable(task, disk) else cache_dir / f"{key or task_key(task)}.json"


def is_cached(task: Task, cache_dir: str | os.PathLike[str], executor: Executor = Executor()
              ) -> bool:
    """Whether :func:`execute` with ``executor`` would take ``task``'s result from the cache."""
    return which_cached([task], cache_dir, executor)[0]


def which_cached(tasks: Sequence[Task], cache_dir: str | os.PathLike[str],
                 executor: Executor = Executor()) -> list[bool]:
    """:func:`is_cached` of each task, keyed as one :func:`execute` sweep keys them (each
    plugin's package hashed once)."""
    return [p is not None and read_cached(p) is not None
            for p in _cache_paths(tasks, cache_dir, executor)]


def adds_to_cache(tasks: Sequence[Task], cache_dir: str | os.PathLike[str],
                  executor: Executor = Executor()) -> bool:
    """Whether :func:`execute` with ``executor`` may write a result into ``cache_dir``: a task
    it would cache that is not cached yet. Not a task never cached (a method without a source
    file, a value that cannot be hashed, :func:`~bomgraph.method_code.uncacheable`; h121: an
    unwritable cache was refused for those), nor any while bomgraph's sources changed."""
    return any(p is not None and read_cached(p) is None
               for p in _cache_paths(tasks, cache_dir, executor))


def _cache_paths(tasks: Sequence[Task], cache_dir: str | os.PathLike[str],
                 executor: Executor) -> list[Path | None]:
    """Each task's cache file as one :func:`execute` sweep keys them (each plugin's package
    hashed once); None where the cache is neither read nor written for it."""
    backend = instance(executor, Executor, "is_cached(): executor", ConfigError).backend
    disk = backend == "dask" or (backend == "processes" and not daemonic())  # as execute
    if bomgraph_edited():
        return [None] * len(tasks)
    new_sweep()
    memo: dict[str, str | None] = {}
    stale: dict[tuple[str, ...], bool] = {}
    return [None if not disk and stale_here(t, stale) else
            _cache_path(Path(cache_dir), t, task_key(t, disk=disk, memo=memo), disk)
            for t in tasks]


def execute(tasks: Sequence[Task], executor: Executor = Executor(), *,
            cache_dir: str | os.PathLike[str] | None = None,
            progress: Callable[[int, int], None] | None = None) -> list[dict[str, Any]]:
    """Run ``tasks`` and return their results in the order of ``tasks``.

    Finished tasks found in ``cache_dir`` are not run again; new results are written there as
    they arrive, so an interrupted sweep resumes where it stopped.
    """
    return execute_counted(tasks, executor, cache_dir=cache_dir, progress=progress)[0]


def execute_counted(tasks: Sequence[Task], executor: Executor = Executor(), *,
                    cache_dir: str | os.PathLike[str] | None = None,
                    progress: Callable[[int, int], None] | None = None
                    ) -> tuple[list[dict[str, Any]], int]:
    """:func:`execute`'s results, and how many of them were read from ``cache_dir``. A
    warning is said once (:func:`bomgraph.worker_log.said_once`), however many workers give
    it."""
    with said_once():
        return _execute_counted(tasks, executor, cache_dir, progress)


def _check_arm_options(tasks: Sequence[Task]) -> None:
    """Refuse, before any run, an arm (or reference) whose method or options would fail every
    run alike (an unknown option, a hybrid's ``seed_method``), as ``compare``'s ``--methods``
    and a sweep file's are (h148: ``execute`` ran the sweep, failing each such run)."""
    from .mapper import check_method_options

    seen: set[str] = set()
    for arm in (a for t in tasks for a in (t.arm, t.reference) if a is not None):
        key = json.dumps([arm.method, arm.key()["options"]], sort_keys=True)
        if key in seen:
            continue
        try:
            check_method_options(arm.method, arm.options)
        except BomgraphError as exc:
            raise ConfigError(f"execute(): arm {arm.label!r} ({arm.method}, options "
                              f"{echo(dict(arm.options))}): {exc}") from None
        seen.add(key)


def _execute_counted(tasks: Sequence[Task], executor: Executor,
                     cache_dir: str | os.PathLike[str] | None,
                     progress: Callable[[int, int], None] | None
                     ) -> tuple[list[dict[str, Any]], int]:
    if not isinstance(executor, Executor):
        raise ConfigError(f"execute(): executor must be an Executor (Executor('serial'), "
                          f"Executor.choose(jobs)), got {type(executor).__name__}")
    bad = next((t for t in tasks if not isinstance(t, Task)), None)
    if bad is not None:
        raise ConfigError(f"execute(): tasks must be Task objects (experiment.tasks()), got "
                          f"{type(bad).__name__}")
    if executor.backend == "processes" and daemonic():
        _log.warning("this process is daemonic (a multiprocessing.Pool or Dask worker), which "
                     "cannot start worker processes: running the %s here, one at a time "
                     "(as Executor('serial'), --jobs 1)", counted(len(tasks), "run"))
        executor = Executor("serial")
    if executor.backend != "serial":
        refuse_runtime_methods(tasks, executor.backend)
    _check_arm_options(tasks)
    new_sweep()  # a plugin module reloaded, a value of it set since the last sweep: new keys
    forget_failures()  # a reference that failed in the last sweep here runs again (h73)
    if cache_dir is not None and bomgraph_edited():
        cache_dir = None
    results: list[dict[str, Any] | None] = [None] * len(tasks)
    # each task keyed once, before any runs: a stream file removed or rewritten during the
    # sweep fails or re-keys only the runs that read it then (in the worker), never the sweep
    # worker processes import the plugins' code as it is on disk (outdated local workers are
    # restarted, stale Dask workers refuse), so their runs are keyed with it; a serial run
    # runs the code loaded here, and refuses it if edited since without a reload
    disk = executor.backend != "serial"
    memo: dict[str, str | None] = {}  # each plugin's package hashed once, not once a task
    keys = [task_key(t, disk=disk, memo=memo) for t in tasks]
    cache = Path(cache_dir) if cache_dir is not None else None
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
        remove_cache_leftovers(cache)  # once a sweep, not once a file written (h83)
        warn_sourceless(tasks, disk)
        stale: dict[tuple[str, ...], bool] = {}
        for k, t in enumerate(tasks):
            if not disk and stale_here(t, stale):
                continue
            path = _cache_path(cache, t, keys[k], disk)
            cached = None if path is None else read_cached(path)
            if cached is not None:
                cached.update(experiment=t.experiment, arm=t.arm.label, run=t.source.name)
                results[k] = cached
    n_cached = sum(r is not None for r in results)
    if cache is not None:
        _log.info("%d of %d runs from the cache %s", n_cached, len(tasks), cache)
    # Experiments that share an arm share its runs: a task whose key another task of this
    # sweep already has runs once, and its result is given to both.
    twins: dict[str, list[int]] = {}
    for k, r in enumerate(results):
        if r is None:
            twins.setdefault(keys[k], []).append(k)
    todo = [ks[0] for ks in twins.values()]
    if executor.backend == "serial":
        todo = _streams_in_turn(todo, tasks)
    done = len(tasks) - sum(len(ks) for ks in twins.values())
    if progress:
        progress(done, len(tasks))
    other_key: list[str] = []
    with contextlib.closing(  # closed here when left early (Ctrl-C), not by the collector
            _dispatch([tasks[k] for k in todo], todo, executor,
                      [keys[k] for k in todo])) as dispatched:
        for k, res in dispatched:
            say_kept(res.pop(SAID, ()))  # a worker's warnings, each said once a sweep
            if res.get("key") != keys[k]:  # kept, but a later read would refuse it
                if res.get("ok"):  # a failure is never cached, and says why itself
                    other_key.append(f"{tasks[k].arm.label} on {tasks[k].source.name}")
            elif (cache is not None and res.get("ok")  # failures are re-run next time
                  and (path := _cache_path(cache, tasks[k], keys[k], disk)) is not None):
                write_cached(path, res)
            for j in twins[keys[k]]:
                t = tasks[j]
                results[j] = res if j == k else {**res, "experiment": t.experiment,
                                                 "arm": t.arm.label, "run": t.source.name}
                done += 1
            if progress:
                progress(done, len(tasks))
    if other_key:  # one line, not one a run
        _log.warning("%s not cached (first: %s): the workers keyed them otherwise than "
                     "this process: other bomgraph or plugin code, library versions or data "
                     "files there; give them this process's (and restart them)",
                     counted(len(other_key), "run"), other_key[0])
    _odd_converged(results)
    return [r for r in results if r is not None], n_cached


def _odd_converged(results: Sequence[Mapping[str, Any] | None]) -> None:
    """One warning per method whose ``info["converged"]`` is not True, False or None (a
    string, a number): :func:`run_task` recorded its runs' ``converged`` as unknown (None),
    which the report leaves out of the converged rate, as for a method that says nothing.
    Not a failed run: the map is scored as any other. Recorded as said, the cache's check
    (true, false or null) refused the entry, so the run ran again in every sweep, and the
    report's mean of it raised."""
    said: dict[str, Any] = {}
    for r in results:
        info = r.get("info") if r is not None and r.get("ok") else None
        v = info.get("converged") if isinstance(info, dict) else None
        if not (v is None or isinstance(v, bool)):
            said.setdefault(str(r.get("method")), v)   # type: ignore[union-attr]
    for method, v in said.items():
        _log.warning("method %s: info['converged'] is %s, not True, False or None: its runs "
                     "are recorded as convergence unknown; return a bool", method, echo(v))


def _streams_in_turn(todo: list[int], tasks: Sequence[Task]) -> list[int]:
    """The serial order of the tasks ``todo`` (indices into ``tasks``) of a sweep with a
    reference: stream by stream, each stream's run of the arm that runs as its reference
    first, so that a reference map (of a stream without truth) is made once and is still
    kept when the stream's other runs need it (arm by arm, the reference ran again for
    each arm on more than :data:`~bomgraph.run_scoring.MAX_REFERENCES` streams). Without a
    reference, ``todo`` as it is."""
    if all(tasks[k].reference is None for k in todo):
        return todo
    stream: dict[tuple[str, str], int] = {}
    for k in todo:
        stream.setdefault((tasks[k].experiment, tasks[k].source.name), len(stream))
    return sorted(todo, key=lambda k: (stream[(tasks[k].experiment, tasks[k].source.name)],
                                       not runs_as_reference(tasks[k])))


_SWEEP = ""  # the sweep whose tasks this worker process ran last (_indexed)


def _indexed(k: int, task: Task, sweep: str = "") -> tuple[int, dict[str, Any]]:
    """In a worker: ``k`` and the task's result. ``sweep``: its token; a worker kept from
    another sweep forgets the references that failed there first (h73: never cached)."""
    global _SWEEP
    if sweep != _SWEEP:
        forget_failures()
        _SWEEP = sweep
    token = _IN_WORKER.set(True)
    try:  # its warnings said by the sweep's process, once (h103), not on this one's stderr
        with kept_warnings() as said:
            result = run_task(task)
        return k, ({**result, SAID: said} if said else result)
    finally:
        _IN_WORKER.reset(token)


def _dispatch(tasks: list[Task], index: list[int], executor: Executor,
              keys: Sequence[str] | None = None) -> Iterator[tuple[int, dict[str, Any]]]:
    if not tasks:
        return
    if executor.backend == "serial":
        with noting_runs():  # what the runs change in their modules: noted once, at the end
            for k, t in zip(index, tasks):
                yield k, run_task(t)
        return
    run = functools.partial(_indexed, sweep=uuid.uuid4().hex)  # for workers kept between sweeps
    by_k = dict(zip(index, tasks))
    key_of = dict(zip(index, keys)) if keys is not None else {}

    def failed(k: int, error: str) -> dict[str, Any]:  # the workers could not run the task
        t = by_k[k]
        return {"experiment": t.experiment, "arm": t.arm.label, "method": t.arm.method,
                "run": t.source.name, "key": key_of.get(k) or task_key(t), "ok": False,
                "error": error}

    if executor.backend == "processes":
        from .processes import dispatch

        yield from dispatch(run, index, tasks,
                            executor.n_jobs,
                            failed, fresh=workers_outdated(tasks))
    else:
        from .cluster import dispatch as dispatch_dask

        yield from dispatch_dask(run, index, tasks, scheduler=executor.scheduler,
                                 scheduler_named=executor.scheduler_named(),
                                 n_local=executor.dask_local,
                                 failed=failed)


__all__ = ["Executor", "run_task", "execute", "execute_counted", "is_cached", "which_cached",
           "adds_to_cache", "refuse_runtime_methods", "task_key", "code_fingerprint",
           "strip_timings", "run_file", "count_steps", "run_example", "CACHE_VERSION"]
