"""Tasks in local worker processes (joblib's loky executor: ``compare --jobs N``), started so
that a Ctrl-C stops the command alone.

A terminal's Ctrl-C reaches the whole process group: workers that took it printed their own
KeyboardInterrupt tracebacks (while they start, importing numpy; between tasks) beside the
command's one line. They start with SIGINT and SIGTERM blocked, which they keep, as do the
workers they start later (a worker replaced after a memory leak); the command stops on the
signal and ends them. A worker whose command is gone (``kill -9``: nothing could end its
workers) ends within a second, in a task or idle (:func:`_watch_parent`), where before it
finished its task and waited out joblib's idle timeout, about five minutes. A Ctrl-C just as
tasks are submitted no longer ends in a KeyError of loky's manager thread on stderr
(:func:`_queue_emptied_before_a_kill`). Imports from
bomgraph only :mod:`bomgraph.stdio`, :mod:`bomgraph.owned_folders`, an error and a check.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import sys
import threading
import time
import warnings
from typing import Any, Callable, Iterator, Sequence

from .checks import is_integer
from .errors import ConfigError
from .owned_folders import OWNER, alive as _alive, owned_folder
from .stdio import signals_held
from .tables import counted

_log = logging.getLogger(__name__)

#: How often, in seconds, a worker checks that the process that started it is there.
PARENT_POLL_S = 0.25

#: The folder of a dispatch's marks (:func:`_marked`), in the temporary folder; a killed
#: dispatch's is removed by the next (:func:`bomgraph.owned_folders.remove_stale`).
MARKS_PREFIX = "bomgraph-running-"

#: local worker processes per core at most: a typo (``--jobs 100000``) started that many.
MAX_WORKERS_PER_CORE = 4


def dispatch(func: Callable[[int, Any], tuple[int, dict[str, Any]]], index: Sequence[int],
             tasks: Sequence[Any], n_jobs: int,
             failed: Callable[[int, str], dict[str, Any]], *, fresh: bool = False
             ) -> Iterator[tuple[int, dict[str, Any]]]:
    """``func(k, task)`` for each ``k`` of ``index`` and its task, in ``n_jobs`` worker
    processes (-1: one per core), as they finish. Closed early (the caller interrupted), the
    runs in flight are cancelled, without joblib's warning that they were. ``fresh``: the
    worker processes joblib kept from an earlier call end first (they keep the code they
    imported then).

    A worker that dies (a crash in native code, the out-of-memory killer, ``os._exit`` in a
    plugin) breaks joblib's whole pool. The tasks it and the other workers were running
    (each worker marks its task in a folder while it runs it) are then run again one at a
    time, each in a pool of its own: the one whose worker dies again is ``failed(k, why)``,
    the others give their results; the rest of the sweep goes on in a new pool. A pool whose
    workers die before any task began or ended is tried once more; twice in a row, the
    workers cannot start, and every task left is ``failed``.

    No task runs in this process, where one that ends its process would end the caller: one
    worker asked for (``n_jobs`` 1, or -1 on one core), which joblib would run here, is two
    given one task at a time (:func:`_pool`). More workers than tasks, or than
    :data:`MAX_WORKERS_PER_CORE` per core, are not started (``n_jobs=10**6`` started a
    thousand): :func:`worker_count`, which logs it.

    Raises
    ------
    ConfigError
        ``n_jobs`` is not an integer >= 1 nor -1 (0, -3, 1.5, True, "2"): at the call, before
        any worker starts (h124: 0 was joblib's ValueError, 1.5 and True were taken).
    """
    n_jobs = worker_count(workers_asked(n_jobs), len(tasks), one_at_a_time=True)
    return _dispatch(func, index, tasks, n_jobs, failed, fresh=fresh)


def usable_cores() -> int:
    """The cores this process may use, as joblib counts them for ``n_jobs=-1``: its CPU
    affinity (``taskset``), a container's CPU quota and ``LOKY_MAX_CPU_COUNT`` taken into
    account, where ``os.cpu_count()`` counts the machine's (h137: the cap counted those, so
    ``taskset -c 0`` with ``--jobs 8`` started 8 workers on one core)."""
    from joblib import cpu_count

    return max(1, int(cpu_count()))


def worker_count(requested: int, n_tasks: int, *, one_at_a_time: bool = False) -> int:
    """The worker processes to start for ``n_tasks`` tasks (the one place that decides it,
    for local processes and a local Dask cluster alike): ``requested`` (-1: one per usable
    core, :func:`usable_cores`), but never more than the tasks nor :data:`MAX_WORKERS_PER_CORE`
    per usable core; logged (INFO) when fewer than asked for are started. h137: -1 was passed
    on to joblib as it was, one worker per core whatever the tasks (64 for 2 tasks on 64
    cores), and the cap was decided twice (the command line's, logged, and
    :func:`dispatch`'s for library callers, silent). ``one_at_a_time``: a pool of one is
    started as two processes that take one task at a time (:func:`_pool`), as the log line
    then says. ``requested`` is checked by the caller (:func:`workers_asked`)."""
    cores = usable_cores()
    asked = cores if requested == -1 else requested
    n = max(1, min(asked, n_tasks, MAX_WORKERS_PER_CORE * cores))
    if n < asked:
        started = ("2, one task at a time (a pool of one would run it in this process)"
                   if one_at_a_time and n == 1 else str(n))
        what = (f"one worker process per core ({cores})" if requested == -1 else
                f"{asked} worker processes")
        _log.info("%s asked for %s on %s: starting %s", what, counted(n_tasks, "task"),
                  counted(cores, "usable core"), started)
    return n


def workers_asked(n_jobs: Any, name: str = "n_jobs") -> int:
    """``n_jobs``, local worker processes: an integer >= 1, or -1 for one per core (joblib's
    other negative counts, all cores but some, are not taken: the command line and a sweep
    file's ``jobs`` refuse them).

    Raises
    ------
    ConfigError
        Anything else, in one line naming ``name``.
    """
    if not (is_integer(n_jobs) and (n_jobs >= 1 or n_jobs == -1)):
        raise ConfigError(f"{name} must be an integer >= 1, or -1 for one process per core, "
                          f"got {n_jobs!r:.40}")
    return int(n_jobs)


def _dispatch(func: Callable[[int, Any], tuple[int, dict[str, Any]]], index: Sequence[int],
             tasks: Sequence[Any], n_jobs: int,
             failed: Callable[[int, str], dict[str, Any]], *, fresh: bool = False
             ) -> Iterator[tuple[int, dict[str, Any]]]:
    from joblib.externals.loky.process_executor import BrokenProcessPool

    if fresh:
        _end_kept_workers()
    pending = dict(zip(index, tasks))
    stalled = False
    with _flushable_std_streams(), owned_folder(MARKS_PREFIX) as marks:
        while pending:
            before = len(pending)
            try:
                with contextlib.closing(_pool(func, pending, n_jobs, marks)) as results:
                    for k, res in results:
                        del pending[k]
                        yield k, res
            except BrokenProcessPool as exc:
                running = [k for k in pending if os.path.exists(_mark(marks, k))]
                why = _died(exc, began=False)  # for workers that cannot start
            else:  # a pool that ended without a task's result (never joblib's): not a loop
                for k in list(pending):
                    del pending[k]
                    yield k, failed(k, "the worker pool ended without its result")
                continue
            _clear(marks)
            idle = not running and len(pending) == before
            if idle and stalled:  # twice in a row no task began or ended: workers cannot start
                for k in list(pending):
                    del pending[k]
                    yield k, failed(k, why)
            stalled = idle
            for k in running:   # each alone, to tell the task that kills its worker
                try:
                    with contextlib.closing(_pool(func, {k: pending[k]}, 1, marks)) as alone:
                        ((_, res),) = list(alone)
                except BrokenProcessPool as exc:
                    res = failed(k, _died(exc))
                    _clear(marks)
                del pending[k]
                yield k, res


#: :func:`_flushable_std_streams`'s: the dispatches under way, the streams put aside for them
_STD_LOCK = threading.Lock()
_STD_HELD: dict[str, tuple[Any, Any]] = {}
_STD_USERS = [0]


@contextlib.contextmanager
def _flushable_std_streams() -> Iterator[None]:
    """``sys.stdout`` and ``sys.stderr`` writing to /dev/null while the workers may start, each
    only where it is None (the shell closed it: ``>&-``) or closed (a caller's
    ``sys.stdout.close()``), and put back after (unless set meanwhile). loky flushes both as
    it starts each worker, from any of its threads: ``compare --jobs 2 >&-`` ended in a
    traceback (AttributeError), and ``compare`` with ``Executor("processes")`` in a process
    whose ``sys.stdout`` was closed raised ValueError (h92). Put back when the last of the
    dispatches under way ends: one in another thread that ended first put back None while
    this one's workers were still starting, AttributeError again (h93)."""
    with _STD_LOCK:
        for name in ("stdout", "stderr"):
            stream = getattr(sys, name)
            if name not in _STD_HELD and (stream is None or getattr(stream, "closed", False)):
                _STD_HELD[name] = (stream, open(os.devnull, "w", encoding="utf-8"))
                setattr(sys, name, _STD_HELD[name][1])
        _STD_USERS[0] += 1
    try:
        yield
    finally:
        with _STD_LOCK:
            _STD_USERS[0] -= 1
            if not _STD_USERS[0]:
                for name, (stream, null) in _STD_HELD.items():
                    if getattr(sys, name) is null:
                        setattr(sys, name, stream)
                    null.close()
                _STD_HELD.clear()


def daemonic() -> bool:
    """Whether this process cannot start worker processes: a daemonic one (a
    ``multiprocessing.Pool`` worker) may have no children, so joblib ran every task in it, one
    at a time, saying only "Loky-backed parallel loops cannot be called in a
    multiprocessing, setting n_jobs=1" after bomgraph's line that it started workers."""
    import multiprocessing

    return bool(multiprocessing.current_process().daemon)


def _pool(func: Callable[[int, Any], tuple[int, dict[str, Any]]], pending: dict[int, Any],
          n_jobs: int, marks: str) -> Iterator[tuple[int, dict[str, Any]]]:
    from joblib import Parallel, delayed, effective_n_jobs, parallel_config
    try:     # joblib's own module, not its public API: a joblib without it runs as before
        from joblib._parallel_backends import LokyBackend
    except ImportError:   # pragma: no cover - joblib >= 1.5 has it
        LokyBackend = None

    # backend: loky, whatever the caller's joblib.parallel_config says (threading ran the
    # tasks in this process; multiprocessing refuses return_as), at nesting level 0: joblib
    # caps a loky pool called from one of its threading workers at one job, run in this
    # process (loky starts its workers by fork+exec, safe from any thread)
    loky: Any = "loky" if LokyBackend is None else LokyBackend(nesting_level=0)
    # joblib runs a pool of one worker in this process: two workers, one task at a time
    if LokyBackend is None:
        with parallel_config(backend="loky"):
            alone = effective_n_jobs(n_jobs) == 1
    else:
        alone = loky.effective_n_jobs(n_jobs) == 1
    one = dict(n_jobs=2, pre_dispatch=1, batch_size=1) if alone else {}
    # initializer: each worker loky starts, the same function and pid each time, so joblib
    # keeps its workers for the next call
    with Parallel(**{"n_jobs": n_jobs, **one}, backend=loky,
                  return_as="generator_unordered",
                  initializer=_watch_parent, initargs=(os.getpid(),)) as par:
        _start_workers(par)
        results = par(delayed(_marked)(func, marks, k, t) for k, t in list(pending.items()))
        try:
            for item in results:
                yield item
        except GeneratorExit:  # logging would print joblib's "N tasks ... were cancelled"
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)
                results.close()
            raise


def _watch_parent(owner: int) -> None:
    """In a worker, as it starts: end it (``os._exit``) as soon as the process that started it
    is gone, which is when the kernel gives it another parent (pid 1 or a subreaper). The
    command's SIGKILL is the case: the workers hold SIGINT and SIGTERM and, left alone,
    finished their task and waited out joblib's idle timeout. ``owner`` is the dispatching
    process, the workers' parent (loky starts them itself, also with ``JOBLIB_START_METHOD``
    spawn or forkserver); were it another process (a start method's server), that parent is
    the one watched.

    A thread polls ``os.getppid()``. It needs the GIL, which GTSAM holds through a whole
    optimisation (5 s of one, measured), so a worker started by the parent's main thread (the
    command's, a notebook's) also asks Linux for SIGKILL when that thread ends
    (``PR_SET_PDEATHSIG``). Only then: the signal follows the *thread* that started the
    worker, and loky also starts workers from its own threads and the caller's (dispatch
    called in a thread), which can end while the process and its kept workers go on."""
    parent = os.getppid()
    if parent != owner and not _alive(owner):  # gone before this worker got here
        os._exit(1)
    if _started_by_main_thread(parent):
        _kill_me_with_my_parent()
        if os.getppid() != parent:  # gone meanwhile
            os._exit(1)
    threading.Thread(target=_exit_when_orphaned, args=(parent,), daemon=True,
                     name="bomgraph-parent-watch").start()


def _started_by_main_thread(parent: int) -> bool:
    """Whether ``parent``'s main thread started this process (Linux lists a process's children
    under the thread that started them; elsewhere, or unreadable: False)."""
    try:
        with open(f"/proc/{parent}/task/{parent}/children", encoding="ascii") as fh:
            return str(os.getpid()) in fh.read().split()
    except OSError:
        return False


def _kill_me_with_my_parent() -> None:
    """``prctl(PR_SET_PDEATHSIG, SIGKILL)``: Linux ends this process when the thread that
    started it ends (no libc or no prctl: nothing; the polling thread remains)."""
    import ctypes
    import signal

    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))  # 1: PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _exit_when_orphaned(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os._exit(1)  # no output: the command's terminal has moved on


def _end_kept_workers() -> None:
    """End the worker processes of joblib's reusable loky executor, kept for the next pool."""
    from joblib.externals.loky import reusable_executor

    kept = getattr(reusable_executor, "_executor", None)
    if kept is not None:
        kept.shutdown(wait=True, kill_workers=True)


def _mark(marks: str, k: int) -> str:
    return os.path.join(marks, str(k))


def _marked(func: Callable[[int, Any], tuple[int, dict[str, Any]]], marks: str, k: int,
            task: Any) -> tuple[int, dict[str, Any]]:
    """In a worker: ``func(k, task)``, with a file named ``k`` in ``marks`` while it runs (left
    behind when the worker dies in it)."""
    path = _mark(marks, k)
    with open(path, "w"):
        pass
    out = func(k, task)
    os.unlink(path)
    return out


def _clear(marks: str) -> None:
    for name in os.listdir(marks):
        if name != OWNER:
            os.unlink(os.path.join(marks, name))


def _died(exc: BaseException, began: bool = True) -> str:
    """A failed run's error for a task whose worker process died, with the exit codes that
    joblib gives (``SIGSEGV(-11)``: a crash in native code; ``SIGKILL(-9)``: often the
    out-of-memory killer). ``began``: False when the workers of two pools in a row died
    before any task began, so no worker ran this one: they cannot start here."""
    codes = re.search(r"exit codes of the workers are (\{[^}]*\})", str(exc))
    codes_text = f" (exit codes {codes.group(1)})" if codes else ""
    if not began:
        return (f"WorkerDied: the worker processes died before any run began, twice in a "
                f"row{codes_text}, so they cannot start here: something at their start kills "
                f"them (a sitecustomize or .pth file, a memory limit, the out-of-memory "
                f"killer); fix that, or run serially (--jobs 1, Executor('serial')); finished "
                f"runs are cached")
    return (f"WorkerDied: the worker process that ran it died{codes_text}: a crash in native "
            f"code, the out-of-memory killer, or os._exit in the method; its warnings died "
            f"with it (a worker sends them back with the result): run it alone with "
            f"--jobs 1 or `bomgraph run STREAM --method NAME` to see them (finished runs "
            f"are cached)")


def _start_workers(par: Any) -> None:
    """Start the workers of joblib's ``par`` (a loky executor; any other backend: nothing)
    with SIGINT and SIGTERM held (blocked): the mask is inherited, and a signal that comes
    meanwhile is this process's when the block ends."""
    from multiprocessing import resource_tracker

    workers = getattr(getattr(par, "_backend", None), "_workers", None)
    if callable(getattr(workers, "submit", None)):
        # first: Python 3.11 starts it with both unblocked after (SIG_UNBLOCK, not the mask
        # it found), which would undo the hold below
        resource_tracker.ensure_running()
        _queue_emptied_before_a_kill(workers)
        with signals_held():
            workers.submit(int)  # the first task starts the processes, in this thread


def _queue_emptied_before_a_kill(executor: Any) -> None:
    """Make ``executor`` (loky's) take the tasks that its manager thread has not yet moved
    to the workers out of that thread's queue when it is shut down with ``kill_workers=True``
    (joblib's abort: a Ctrl-C), before the shutdown itself.

    On that shutdown loky's manager thread empties its dict of pending tasks, not the queue
    of their ids, then looks the next queued id up in the dict: a task submitted since the
    thread last ran (a Ctrl-C just as the first tasks were submitted, on a loaded machine)
    was ``KeyError`` in that thread, "Exception in thread ExecutorManagerThread" and a
    traceback above the command's one line (h151). CPython's ProcessPoolExecutor empties
    that queue too. Here it is emptied under the lock that ``submit`` takes, which then
    flags the shutdown, so that no task is queued between the two; each task taken out
    fails as loky fails those it drops. Once per executor (joblib reuses it); a loky
    without these attributes is left as it is."""
    needed = ("_work_ids", "_pending_work_items", "_flags", "shutdown")
    if getattr(executor, "_bomgraph_queue_emptied", False) or not all(
            hasattr(executor, n) for n in needed):
        return
    shutdown = executor.shutdown

    def emptied_then_shutdown(wait: bool = True, kill_workers: bool = False) -> None:
        if kill_workers:
            _empty_queue(executor)
        shutdown(wait=wait, kill_workers=kill_workers)

    executor.shutdown = emptied_then_shutdown
    executor._bomgraph_queue_emptied = True


def _empty_queue(executor: Any) -> None:
    import queue
    from concurrent.futures import InvalidStateError

    from joblib.externals.loky.process_executor import ShutdownExecutorError

    dropped = []
    flags = executor._flags
    with flags.shutdown_lock:
        while True:
            try:
                work_id = executor._work_ids.get_nowait()
            except queue.Empty:
                break
            dropped.append(executor._pending_work_items.pop(work_id, None))
        flags.shutdown = flags.kill_workers = True  # as flag_as_shutting_down(True)
    for item in filter(None, dropped):
        try:
            item.future.set_exception(ShutdownExecutorError(
                "The Executor was shutdown with `kill_workers=True` before this job could "
                "complete."))
        except InvalidStateError:  # cancelled meanwhile
            pass


__all__ = ["MAX_WORKERS_PER_CORE", "daemonic", "dispatch", "usable_cores", "worker_count",
           "workers_asked"]
