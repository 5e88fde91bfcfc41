"""Tasks on a Dask cluster: a local one (``--dask-local N``) or an existing scheduler
(``--scheduler ADDRESS``, e.g. ``dask scheduler`` and ``dask worker`` started by hand).

Before connecting, the scheduler is asked who it is within Dask's connect timeout
(:func:`check_scheduler`): ``distributed.Client`` waits forever on a port that accepts the
connection and never answers (a dashboard's), and dies with a traceback on one that answers
something else; an address that does not resolve is refused at once, one that refuses the
connection after :data:`REFUSED_GRACE_S` (Dask retries both until its timeout:
:func:`_connect`). A task that fails on the cluster itself (every worker that ran it died, or a
worker could not import it) becomes a failed run with the reason, so the other runs finish and
are cached. Ctrl-C kills a local cluster's workers at once (:func:`_end_local_workers`); they
never take it themselves (:func:`_workers_hold_signals`). Imports from bomgraph only the
errors, an option's name, :func:`bomgraph.stdio.signals_held` and
:func:`bomgraph.owned_folders.owned_folder` and
:func:`bomgraph.processes.worker_count`.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import errno
import importlib
import logging
import socket
from concurrent.futures import CancelledError
from typing import Any, Callable, Iterator, Sequence

from .checks import integer, option_named
from .errors import ConfigError, UnknownMethodError, shown_path
from .owned_folders import owned_folder
from .processes import worker_count
from .stdio import signals_held

_log = logging.getLogger(__name__)

#: seconds between looks at the cluster while no run finishes (for the no-worker warning)
POLL_S = 5.0

#: The local cluster's scheduler without a dashboard still serves HTTP (Dask's health and
#: metrics routes), on port 8787 unless told otherwise: while anything else held 8787 (a
#: notebook's cluster, another compare) every ``--dask-local`` run warned "UserWarning: Port
#: 8787 is already in use" (an error under ``-W error``). A free port of this host instead.
LOCAL_SCHEDULER_HTTP = {"dashboard_address": "127.0.0.1:0"}

#: The local cluster's scratch space (its scheduler's and workers' folders and locks), a
#: folder of its own in the temporary folder (Dask's ``temporary-directory`` when set:
#: :func:`_dask_temp`), removed as the cluster ends: Dask's default, ``dask-scratch-space``
#: there, was left behind by every ``--dask-local`` compare (its lock
#: files; SIGTERM: the workers' too; SIGKILL: their folders); one left by a compare ended by
#: SIGKILL is removed by the next (:func:`bomgraph.owned_folders.remove_stale`).
SCRATCH_PREFIX = "bomgraph-dask-"


def _dask_temp() -> str | None:
    """Dask's ``temporary-directory`` (``DASK_TEMPORARY_DIRECTORY``: a disk with room where
    the temporary folder is a small tmpfs), where Dask puts its scratch space, or None: the
    temporary folder. h130: the local cluster's folder went to the temporary folder always."""
    import dask.config

    return dask.config.get("temporary-directory", None) or None


@contextlib.contextmanager
def _scratch_folder() -> Iterator[str]:
    """The local cluster's own folder (:data:`SCRATCH_PREFIX`) for the block.

    Raises
    ------
    ConfigError
        Dask's ``temporary-directory`` is set to where no folder can be made (a file)."""
    root = _dask_temp()
    with contextlib.ExitStack() as stack:
        try:
            folder = stack.enter_context(owned_folder(SCRATCH_PREFIX, root))
        except OSError as exc:
            if root is None:
                raise
            raise ConfigError(f"Dask's temporary-directory {shown_path(root)} "
                              f"(DASK_TEMPORARY_DIRECTORY, "
                              f"or temporary-directory in Dask's configuration): no folder "
                              f"can be made there ({exc.strerror or exc}); give a folder you "
                              f"can write to") from None
        yield folder


#: Starts of the local cluster before its runs fail (:func:`start_failure`): Dask closes the
#: whole cluster when one worker dies as it starts, and one killed once (the out-of-memory
#: killer, a kill) failed every run where ``--jobs N`` tries a pool whose workers died
#: before any task once more (h130). Not tried again: a cluster that could not listen or
#: connect on 127.0.0.1 (no port, no loopback: the same the next time).
START_TRIES = 2


#: How to see the warnings of a run whose worker died: a worker keeps them for its result
#: (:mod:`bomgraph.worker_log`), so they end with it; run serially, they reach stderr at once.
ALONE_HINT = ("run it alone with --jobs 1 (without --dask-local or --scheduler) to see its "
              "warnings")


def connect_timeout() -> float:
    """Dask's connect timeout (``distributed.comm.timeouts.connect``, 30 s by default) [s]."""
    import dask.config
    from dask.utils import parse_timedelta

    return float(parse_timedelta(dask.config.get("distributed.comm.timeouts.connect"),
                                 default="seconds"))


#: Seconds :func:`check_scheduler` leaves Dask's connect alone before it tries a TCP address
#: itself (:func:`_connect`): Dask retries an address that refuses the connection or does
#: not resolve until its connect timeout, so a typo in a port or host took 30 s (h161).
PROBE_AFTER_S = 0.5
#: Seconds a refused connection is tried again (every :data:`PROBE_AFTER_S`) before it is
#: given up: a scheduler started beside the command (``dask scheduler & bomgraph compare
#: --scheduler ...``) listens a second or two later. A host that does not resolve is given
#: up at once.
REFUSED_GRACE_S = 5.0


async def _reachable(address: str, timeout: float) -> None:
    """Connect once to ``address`` if it is a TCP one (``tcp://``, ``tls://``, no scheme),
    raising the OSError of a refusal or a host that does not resolve at once."""
    from distributed.comm.addressing import parse_address, parse_host_port

    scheme, loc = parse_address(address)
    if scheme in ("tcp", "tls"):
        host, port = parse_host_port(loc)
        loop = asyncio.get_running_loop()

        async def probe() -> None:
            await _connect_any(await loop.getaddrinfo(host, port, type=socket.SOCK_STREAM))
        await asyncio.wait_for(probe(), timeout)


async def _connect_any(infos: Sequence[tuple]) -> None:
    """Connect to the first of ``getaddrinfo``'s addresses that takes it. If none does, a
    ConnectionRefusedError if one refused: ``localhost`` is ``::1`` and ``127.0.0.1`` on many
    hosts, and asyncio's ``open_connection`` raised a plain ``OSError("Multiple exceptions:
    ...")`` for two refusals, which :func:`_connect` gave up at once (h168)."""
    loop = asyncio.get_running_loop()
    errors: list[OSError] = []
    for family, kind, proto, _, sockaddr in infos:
        with socket.socket(family, kind, proto) as sock:
            sock.setblocking(False)
            try:
                await loop.sock_connect(sock, sockaddr)
                return
            except OSError as exc:
                errors.append(exc)
    refused = [e for e in errors if isinstance(e, ConnectionRefusedError)]
    raise (refused or errors or [OSError("the host name resolves to no address")])[0]


async def _connect(address: str, timeout: float) -> Any:
    """Dask's connect to ``address``; one still trying after :data:`PROBE_AFTER_S` (retrying
    a refusal?) is given up once a connection of :func:`_reachable`'s fails: at once for a
    host that does not resolve, after :data:`REFUSED_GRACE_S` of refusals."""
    from distributed.comm import connect

    loop = asyncio.get_running_loop()
    give_up_at = loop.time() + min(REFUSED_GRACE_S, timeout)
    task = asyncio.ensure_future(connect(address, timeout=timeout))
    done, _ = await asyncio.wait({task}, timeout=min(PROBE_AFTER_S, timeout))
    while not done:
        try:
            await _reachable(address, timeout)
            break
        except BaseException as exc:
            if not (isinstance(exc, ConnectionRefusedError) and loop.time() < give_up_at):
                task.cancel()
                await asyncio.gather(task, return_exceptions=True)
                raise
        done, _ = await asyncio.wait({task}, timeout=PROBE_AFTER_S)
    return await asyncio.wait_for(task, timeout)


async def _identity(address: str, timeout: float) -> Any:
    comm = await _connect(address, timeout)
    try:
        await asyncio.wait_for(comm.write({"op": "identity"}), timeout)
        return await asyncio.wait_for(comm.read(), timeout)
    finally:
        comm.abort()


def check_scheduler(address: str, timeout: float | None = None, *,
                    named: str | None = None) -> int:
    """The number of workers of the Dask scheduler at ``address``, asked within ``timeout``
    seconds (default :func:`connect_timeout`). ``named``: how the errors name the address
    (default ``--scheduler ADDRESS``, from Python ``address='ADDRESS'``; a sweep file's key
    when it came from there).

    Raises
    ------
    ConfigError
        Nothing answers there in time, or what answers is no Dask scheduler (a worker, a
        dashboard, another service): one line saying which, and what to check.
    """
    timeout = connect_timeout() if timeout is None else timeout
    named = option_named("--scheduler", "address", address) if named is None else named
    hint = ("is `dask scheduler` running, and is this the address it printed (not its "
            "dashboard's or a worker's)?")
    with concurrent.futures.ThreadPoolExecutor(1) as pool:  # also under a running event loop
        try:
            reply = pool.submit(asyncio.run, _identity(address, timeout)).result()
        except (asyncio.TimeoutError, TimeoutError):
            raise ConfigError(f"{named}: no Dask scheduler answered within "
                              f"{timeout:g} s; {hint}") from None
        except Exception as exc:  # refused, unresolvable, or a reply Dask cannot read
            reason = ("the connection was refused: nothing listens on that port"
                      if isinstance(exc, ConnectionRefusedError) else
                      f"the host name does not resolve: {exc.strerror}"
                      if isinstance(exc, socket.gaierror) else
                      (str(exc).splitlines() or [type(exc).__name__])[0]
                      if isinstance(exc, OSError) else "what answers speaks no Dask")
            raise ConfigError(f"{named}: no Dask scheduler there ({reason}); "
                              f"{hint}") from None
    kind = reply.get("type") if isinstance(reply, dict) else None
    if kind != "Scheduler":
        raise ConfigError(f"{named}: that is a Dask {kind or 'service'}, not a "
                          f"scheduler; give the address `dask scheduler` printed")
    return int(reply.get("n_workers", len(reply.get("workers", {}))))


def worker_failure(exc: BaseException) -> str:
    """A failed run's error for a task the cluster could not run (one line)."""
    from distributed.scheduler import KilledWorker

    if isinstance(exc, CancelledError):
        reason = getattr(exc, "reason", None) or "cancelled"
        return (f"the Dask scheduler dropped it ({reason}: the scheduler stopped or the "
                f"connection to it was lost); finished runs are cached: start the scheduler "
                f"and run again")
    if isinstance(exc, KilledWorker):
        return ("KilledWorker: every Dask worker that ran it died (a crash in native code, "
                "the out-of-memory killer, or a worker stopped); see the workers' logs, and "
                f"{ALONE_HINT} (a worker sends them back with the result: they died with "
                "it); finished runs are cached")
    first = (str(exc).splitlines() or [""])[0].split("; known methods")[0]
    reason = f"{type(exc).__name__}: {first}" if first else type(exc).__name__
    if isinstance(exc, (UnknownMethodError, ImportError)):
        return (f"on a Dask worker, {reason}; every worker needs bomgraph and your plugins "
                f"importable (installed there, or on the PYTHONPATH `dask worker` starts "
                f"with): fix that and restart the workers")
    return f"on a Dask worker, {reason}"


#: What keeps a local cluster from listening or connecting on 127.0.0.1 (:func:`start_failure`)
_NETWORK_ERRNOS = frozenset({errno.EADDRINUSE, errno.EADDRNOTAVAIL, errno.EACCES, errno.EPERM,
                             errno.ENETUNREACH, errno.ECONNREFUSED})


def start_timeout() -> float:
    """How long a local cluster's worker may take to start, in seconds: twice Dask's connect
    timeout (:func:`connect_timeout`; 60 s by default). h137: nothing bounded it, so a worker
    whose start hung (a sitecustomize, a network file system) hung ``--dask-local``."""
    return 2 * connect_timeout()


def _causes(exc: BaseException | None) -> list[BaseException]:
    """``exc`` and what it came from (``__cause__``, else ``__context__``), outermost first."""
    out: list[BaseException] = []
    while exc is not None and len(out) < 12 and exc not in out:
        out.append(exc)
        exc = exc.__cause__ or exc.__context__
    return out


def _start_kind(exc: BaseException | None) -> str:
    """Why a local cluster did not start: ``"network"`` (no port, no loopback, not allowed),
    ``"timeout"`` (a worker did not start within :func:`start_timeout`), ``"died"`` (a worker
    process ended as it started) or ``"other"`` (what Dask raised is in the message)."""
    chain = _causes(exc)
    if any(isinstance(e, OSError) and e.errno in _NETWORK_ERRNOS for e in chain):
        return "network"
    if any(isinstance(e, (TimeoutError, asyncio.TimeoutError)) for e in chain):
        return "timeout"
    if any(isinstance(e, RuntimeError) and "failed to start worker process" in str(e)
           for e in chain):  # Dask's Nanny: the worker process ended before it said it ran
        return "died"
    return "other"


def start_failure(exc: BaseException, tries: int = START_TRIES) -> str:
    """A failed run's error when the local cluster could not start ``tries`` times in a row,
    saying why and what to fix: it could not listen or connect on 127.0.0.1 (a port, the
    loopback interface, a sandbox), a worker did not start in time, a worker died as it
    started (h124: a worker killed then, or ended by a sitecustomize, was Dask's
    ``RuntimeError: Nanny failed to start.`` traceback out of ``compare``, exit 1), or
    anything else Dask raised (h137: every one of these was called a worker death). ``exc``:
    the last start's error."""
    causes = []
    for e in _causes(exc)[:3]:
        first = (str(e).splitlines() or [""])[0].strip()
        causes.append(f"{type(e).__name__}: {first}" if first else type(e).__name__)
    said = "; ".join(causes)
    times = "once" if tries == 1 else f"{tries} times in a row"
    instead = ("or run in local processes (--jobs N, without --dask-local); finished runs are "
               "cached")
    kind = _start_kind(exc)
    if kind == "network":
        said = next(f"{type(e).__name__}: {e}" for e in _causes(exc)
                    if isinstance(e, OSError) and e.errno in _NETWORK_ERRNOS)
        return (f"ClusterNetwork: the local Dask cluster could not listen or connect on "
                f"127.0.0.1 ({said}): no free port on this machine (every port of "
                f"net.ipv4.ip_local_port_range in use), no loopback interface or address (a "
                f"sandbox, a container without a network), or not allowed here; free ports "
                f"or bring the loopback interface up (ip link set lo up), {instead}")
    if kind == "timeout":
        return (f"WorkerStartTimeout: a worker of the local Dask cluster did not start within "
                f"{start_timeout():g} s, {times}: the machine is overloaded or "
                f"something at the workers' start waits (a sitecustomize or .pth file, a slow "
                f"network file system); fix that, give them longer (twice Dask's "
                f"distributed.comm.timeouts.connect: DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT="
                f"60s), {instead}")
    if kind == "died":
        return (f"WorkerDied: the local Dask cluster's workers could not start, {times} "
                f"({said}): they died as they started; something at their start kills them "
                f"(a sitecustomize or .pth file, a memory limit, the out-of-memory killer, a "
                f"kill); fix that, {instead}")
    return (f"ClusterNotStarted: the local Dask cluster could not start, {times} ({said}); "
            f"fix that (Dask's configuration, DASK_* variables, what the workers import as "
            f"they start), {instead}")


def quiet_dask_logging() -> Callable[[], None]:
    """Dask's own log lines (its client reconnecting with a traceback, "Couldn't gather") at
    CRITICAL only, so that a failure is the failed runs' one line: for the command line without
    ``-v`` (:mod:`bomgraph.cli`), never called by the library in its caller's process (only
    on a local cluster's workers as they end: :func:`_quiet_worker`). Returns what gives each
    of those loggers its level back: the command run in its caller's process calls it at
    the end (:func:`bomgraph.log_setup.restore_after`); the program does not (the client's
    reconnect task logs its traceback when the process ends)."""
    importlib.import_module("distributed")  # its logging configuration first, ours over it

    loggers = [logging.getLogger(name) for name in ["distributed",
                                                    *list(logging.root.manager.loggerDict)]
               if name.split(".")[0] == "distributed"]  # some set a level
    levels = {lg: lg.level for lg in loggers}
    for lg in loggers:
        lg.setLevel(logging.CRITICAL)

    def restore() -> None:
        for lg, level in levels.items():
            lg.setLevel(level)
    return restore


def _quiet_worker() -> None:
    """On a worker of the local cluster, just before it is closed: Dask's log lines from then
    on at CRITICAL only. A heartbeat that met the scheduler closing printed "Failed to
    communicate with scheduler during heartbeat" and a ``StreamClosedError`` traceback on the
    worker's stderr, the user's (h106: once in 9 compares). Never on a ``--scheduler``'s
    workers (the user's), nor in the caller's process."""
    quiet_dask_logging()


@contextlib.contextmanager
def _workers_hold_signals() -> Iterator[None]:
    """Start a local cluster in the block: its workers start with SIGINT and SIGTERM held
    (blocked), as :mod:`bomgraph.processes` starts joblib's, and keep that mask, so a
    terminal's Ctrl-C, which reaches the whole process group, stops the command alone, which
    ends them. A worker that took it logged "Async instruction ... ended with CancelledError"
    on the user's stderr beside the command's one line (h110: 2 of 3 Ctrl-Cs). A signal that
    comes meanwhile is this process's when the block ends: assign the cluster inside it."""
    from multiprocessing import resource_tracker

    # first: Python 3.11 starts it with both unblocked after (SIG_UNBLOCK, not the mask it
    # found), which would undo the hold in the thread that starts the workers
    resource_tracker.ensure_running()
    with signals_held():  # the cluster's event loop thread, which starts them, inherits it
        yield


def _recording_nanny(started: list[Any]) -> type:
    """Dask's ``Nanny``, keeping in ``started`` each worker process it starts (Dask's
    ``WorkerProcess``, as it sets ``Nanny.process``): the workers of this cluster and no
    other, for :func:`_end_strays`."""
    from distributed import Nanny as DaskNanny

    class Nanny(DaskNanny):  # named as Dask's: its errors say "Nanny failed to start."
        @property
        def process(self) -> Any:
            return self.__dict__.get("_bomgraph_process")

        @process.setter
        def process(self, value: Any) -> None:
            self.__dict__["_bomgraph_process"] = value
            if value is not None:
                started.append(value)

    return Nanny


def _end_strays(started: list[Any]) -> None:
    """Kill (SIGKILL) the workers a failed start left (``started``: :func:`_recording_nanny`'s,
    those still children of this process): Dask cannot end a worker that has not yet started
    (its nanny's kill asserts that it did: the ``AssertionError: Status.starting`` of a start
    that timed out), so one whose start hung went on, and the command waited for it as it
    ended (h137: 2 minutes, a sitecustomize's sleep). Only this start's: h137 killed every
    Dask worker of this process started meanwhile, a caller's own cluster's too (h142)."""
    import multiprocessing

    ours = {getattr(w, "pid", None) for w in started} - {None}
    for p in multiprocessing.active_children():
        if p.pid in ours:
            p.kill()
            p.join(5)


def _end_local_workers(cluster: Any) -> None:
    """End the local cluster's worker processes now (SIGKILL), their runs unfinished: nobody
    waits for those, and nothing of the command's output is theirs to write. Closing the
    cluster waited up to 4 s for each worker's run (Dask's nanny) before it killed the worker:
    Ctrl-C took 4.3 s to stop a ``--dask-local`` compare, 0.25 s a ``--jobs`` one, whose
    workers are killed too (h110). Told to close instead, a worker logged its cancelled run
    unless quieted first, which waits for a worker whose run holds the GIL (GTSAM through an
    optimisation). No worker is started again in a killed one's place. With a Dask without
    these calls, the cluster's close ends them, as before."""

    async def end(nanny: Any) -> None:
        nanny.close_gracefully()  # no worker is started again in its place
        process = getattr(nanny.process, "process", None)  # the worker's
        if process is not None:
            await process.kill()
            await process.join()

    async def end_all() -> None:
        for outcome in await asyncio.gather(*(end(n) for n in list(cluster.workers.values())),
                                            return_exceptions=True):
            if isinstance(outcome, BaseException):
                _log.debug("could not end a local worker at once", exc_info=outcome)

    try:
        cluster.sync(end_all)
    except Exception:  # the cluster's close ends them, as before
        _log.debug("could not end the local workers at once", exc_info=True)


def dispatch(func: Callable[[int, Any], tuple[int, dict[str, Any]]], index: Sequence[int],
             tasks: Sequence[Any], *, scheduler: str | None, n_local: int,
             failed: Callable[[int, str], dict[str, Any]], scheduler_named: str | None = None
             ) -> Iterator[tuple[int, dict[str, Any]]]:
    """``func(k, task)`` for each pair on the cluster, yielded as they finish; a task the
    cluster could not run is ``(k, failed(k, reason))``. ``scheduler_named``: how errors
    name the address (:func:`check_scheduler`). Without ``scheduler``, ``n_local`` (the
    local cluster's workers) must be an integer >= 1: else :class:`ConfigError` at the call,
    before any cluster starts (h123: ``n_local=-3`` waited forever for a worker). No more
    workers are started than tasks, nor than :data:`~bomgraph.processes.MAX_WORKERS_PER_CORE`
    per core (:func:`~bomgraph.processes.worker_count`, as for local processes).

    Raises
    ------
    ConfigError
        ``n_local`` is not an integer >= 1 and no ``scheduler`` is given.
    """
    if not scheduler:
        integer(n_local, option_named("--dask-local", "n_local"), ConfigError, minimum=1)
        n_local = worker_count(n_local, len(tasks))
    return _dispatch(func, index, tasks, scheduler=scheduler, n_local=n_local,
                     failed=failed, scheduler_named=scheduler_named)


def _dispatch(func: Callable[[int, Any], tuple[int, dict[str, Any]]], index: Sequence[int],
              tasks: Sequence[Any], *, scheduler: str | None, n_local: int,
              failed: Callable[[int, str], dict[str, Any]], scheduler_named: str | None = None
              ) -> Iterator[tuple[int, dict[str, Any]]]:
    from distributed import Client, LocalCluster, wait

    cluster = client = None
    finished = False  # every result yielded; else the runs were left (Ctrl-C, SIGTERM)
    scratch = contextlib.ExitStack()  # a local cluster's folder, removed last
    try:
        alone = False  # warned that no worker is there
        if scheduler:
            alone = check_scheduler(scheduler, named=scheduler_named) == 0
            if alone:
                _log.warning("the Dask scheduler at %s has no workers: the runs wait for one "
                             "(start `dask worker %s`)", scheduler, scheduler)
            client = Client(scheduler, timeout=connect_timeout())
        else:
            folder = scratch.enter_context(_scratch_folder())
            not_started: Exception | None = None
            tries = 0
            while cluster is None and tries < START_TRIES:
                tries += 1
                started: list[Any] = []
                with _workers_hold_signals():
                    try:
                        cluster = LocalCluster(n_workers=n_local, threads_per_worker=1,
                                               processes=True, host="127.0.0.1",
                                               dashboard_address=None, local_directory=folder,
                                               death_timeout=start_timeout(),
                                               worker_class=_recording_nanny(started),
                                               scheduler_kwargs={**LOCAL_SCHEDULER_HTTP,
                                                                 "local_directory": folder})
                    except Exception as exc:  # start_failure's kinds; Dask closed the rest
                        not_started = exc
                        _end_strays(started)
                if cluster is None:
                    _log.debug("the local Dask cluster did not start", exc_info=not_started)
                    if _start_kind(not_started) == "network":  # the same again: not tried
                        break
            if cluster is None:
                why = start_failure(not_started, tries)
                for k in index:
                    yield k, failed(k, why)
                finished = True
                return
            client = Client(cluster)
        futures = client.map(func, list(index), list(tasks), pure=False)
        which = {f.key: k for f, k in zip(futures, index)}
        pending = set(futures)
        while pending:
            try:
                done, pending = wait(pending, timeout=POLL_S, return_when="FIRST_COMPLETED")
            except CancelledError:  # the scheduler is gone: what finished, and failed runs
                done, pending = pending, set()
            except TimeoutError:
                try:
                    idle = not client.nthreads()
                except Exception:  # the scheduler is going: its futures say so
                    continue
                if idle and not alone:
                    _log.warning("no Dask worker left at %s: the runs wait for one (start "
                                 "`dask worker %s`, or Ctrl-C: finished runs are cached)",
                                 client.scheduler.address, client.scheduler.address)
                alone = idle
                continue
            for fut in done:
                try:
                    out = fut.result()
                except Exception as exc:  # the cluster's failure, not the method's
                    _log.debug("task %s failed on the cluster", fut.key, exc_info=exc)
                    out = (which[fut.key], failed(which[fut.key], worker_failure(exc)))
                yield out
        finished = True
    finally:
        if cluster is not None and not finished:  # left early: its runs are nobody's
            _end_local_workers(cluster)
        elif cluster is not None and client is not None:  # its workers are ours, and end
            try:  # now: quiet first (h106)
                client.run(_quiet_worker, on_error="ignore")
            except Exception:  # the scheduler is gone: nothing more to say to them
                _log.debug("could not quiet the local workers", exc_info=True)
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
        scratch.close()


__all__ = ["check_scheduler", "connect_timeout", "dispatch", "worker_failure"]
