"""The code a task's methods run, as the runner (:mod:`bomgraph.bench`) keys and checks it.

A plugin's or a method registered at run time's code is part of its cache key
(:func:`method_code`; built-in methods are covered by the runner's hash of the bomgraph and
baselines sources), and for a run in this process the values of its modules set since they
were loaded (:func:`method_values`, :mod:`bomgraph.loaded_values`). The code that runs must be the code keyed: a method without a source file
is never cached (:func:`sourceless`), a worker that imported a plugin before an edit does not
run it (:func:`stale_plugin`), the local workers that joblib keeps between sweeps are ended
when a plugin changed since they ran it (:func:`workers_outdated`), and a method registered at
run time is refused to workers, which cannot see it (:func:`refuse_runtime_methods`).
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import logging
from typing import Iterator, Sequence

from .errors import ConfigError, UnknownMethodError
from .experiments import Task
from .loaded_values import Unhashable, note_run, values_fingerprint
from .mapper import method_info
from .plugins import code_changed, disk_fingerprint, loaded_modules, source_fingerprint
from .processes import daemonic
from .tables import counted, plural

_log = logging.getLogger(__name__)

#: :func:`method_fingerprint` of a method whose module has no source file to hash.
NO_SOURCE = "no-source"


def method_fingerprint(name: str, *, disk: bool = False) -> str | None:
    """A hash of the method's own code for the cache key, or None for a built-in method
    (whose code the runner's :func:`bomgraph.plugins.code_fingerprint` of the bomgraph and
    baselines sources covers already, so the paper's cache keys stay as they were). For a
    plugin: the sources of its package that its module imports and its distribution's
    version; for a method registered at run time: the sources of its target's top-level
    package that its module imports (:mod:`bomgraph.plugins`),
    or :data:`NO_SOURCE` when that module has no source file (:func:`method_has_source`).
    The sources as this process runs them, or with ``disk`` as they are on disk now (what
    a worker process that imports them runs)."""
    info = method_info(name)
    if info.origin == "builtin":
        return None
    fp = (disk_fingerprint if disk else source_fingerprint)(info.target, info.version)
    return NO_SOURCE if fp is None else fp


def method_has_source(name: str) -> bool:
    """Whether the code of ``name`` can be hashed for the cache key: False for a method
    registered at run time from a module without a source file (a class defined in a
    notebook cell or in ``python -c``), whose edits no key could follow."""
    return method_fingerprint(name) != NO_SOURCE


def method_code(task: Task, *, disk: bool = False,
                memo: dict[str, str | None] | None = None) -> dict[str, str]:
    """The fingerprints of the task's non-built-in methods (the arm's, the reference's, a
    seed's: :meth:`Task.methods`), by method name: empty for built-in methods, so their keys
    are as before plugins existed. ``disk``: as :func:`method_fingerprint`. ``memo``: the
    fingerprints (of the same ``disk``) already taken by this sweep, by method name, filled
    here: a plugin's package is hashed once per sweep, not once per task. Each fingerprint
    names the method's target too, and ``truth`` when it is given the truth."""
    memo = {} if memo is None else memo
    for m in task.methods():
        if m not in memo:
            memo[m] = _keyed(m, method_fingerprint(m, disk=disk), disk)
    return {m: fp for m in task.methods() if (fp := memo[m]) is not None}


def _keyed(name: str, fingerprint: str | None, disk: bool) -> str | None:
    """A method's fingerprint with what its package's sources do not tell: its target (the
    same name registered again as another factory of the package), whether it is given
    the truth (registered with ``needs_truth``, or its factory says so) and, for a run in
    this process (not ``disk``), the values of its modules set since they were loaded
    (:func:`method_values`)."""
    if fingerprint is None:
        return None
    info = method_info(name)
    values = "" if disk or fingerprint == NO_SOURCE else method_values(info.target,
                                                                       info.version)
    return (f"{fingerprint} {info.target}" + (" truth" if info.needs_truth else "")
            + (f" values={values}" if values else " values unhashable" if values is None
               else ""))


#: Per target: why :func:`method_values` could not hash a value of its modules.
_UNHASHABLE: dict[str, str] = {}


@functools.lru_cache(maxsize=64)
def method_values(target: str, version: str | None = None) -> str | None:
    """A hash of the values of ``target``'s loaded modules set since they were loaded
    (:func:`bomgraph.loaded_values.values_fingerprint`: ``mymethod.set_depth(3.0)``), ""
    when none is, None when one cannot be hashed (the method's runs in this process are then
    not cached: :func:`uncacheable`). Taken once a sweep (:func:`new_sweep`)."""
    try:
        return values_fingerprint(loaded_modules(target, version))
    except Unhashable as exc:
        _UNHASHABLE[target] = str(exc)
        return None


def new_sweep() -> None:
    """Forget the keys' parts taken for the last sweep: a module reloaded, a value set since."""
    source_fingerprint.cache_clear()
    method_values.cache_clear()


def stale_plugin(task: Task, *, worker: bool) -> str:
    """Why this process cannot run the task's plugin as it is now on disk ("" when it can):
    Python does not reload a module, so a process that imported a plugin (its sources hashed
    then, :func:`method_fingerprint`) keeps running that code after an edit, while the
    client keys the task with the new sources. ``worker``: this process is a worker (local
    or Dask), to be restarted; else it is the one that made the task (a serial run), where
    the module is to be reloaded."""
    for m in task.methods():
        loaded = method_fingerprint(m)
        info = method_info(m)
        if loaded not in (None, NO_SOURCE) and disk_fingerprint(info.target,
                                                                info.version) != loaded:
            # the edit may be in another module of the package, which the method imports
            where = f" (a source file of {info.target.split(':')[0].split('.')[0]!r})"
            if not worker:
                return (f"method {m!r} was edited since this process imported it{where} (or "
                        f"a constant of it set in memory, or it holds a name imported from a "
                        f"module reloaded since: reload it too), and Python does not reload a "
                        f"module: reload the module (importlib.reload, IPython's %autoreload) "
                        f"or restart this process (a notebook's kernel), then run again")
            return (f"stale worker: restart the workers and run again (Dask: client.restart(),"
                    f" or restart `dask worker`; in a notebook run serially: reload the module"
                    f" or restart the kernel); method {m!r} was edited since this worker "
                    f"imported it{where}, and a worker does not reload a module")
    return ""


def stale_after_run(task: Task, *, worker: bool) -> str:
    """:func:`stale_plugin` once a run has ended (its package edited during the run: the
    result is of neither key's code), and why the check itself failed if it did (the
    package removed or broken meanwhile): "" only when the code is still the keyed one."""
    try:
        if not worker:  # what the run changed in its modules is its own state
            pending = _PENDING.get()
            for m in task.methods():
                if (info := method_info(m)).origin == "builtin":
                    continue
                if pending is None:
                    note_run(loaded_modules(info.target, info.version))
                else:
                    pending.setdefault((info.target, info.version))
        return stale_plugin(task, worker=worker)
    except Exception as exc:  # a run that cannot be tied to its code is not cached
        return (f"the method's code could not be checked after the run ({type(exc).__name__}: "
                f"{exc}); run again once its package can be read")


#: In :func:`noting_runs`: the (target, version) of the methods whose runs ended.
_PENDING: contextvars.ContextVar[dict[tuple[str, str | None], None] | None] = (
    contextvars.ContextVar("bomgraph_pending_notes", default=None))


@contextlib.contextmanager
def noting_runs() -> Iterator[None]:
    """Within: what the runs in this process change in their modules
    (:func:`bomgraph.loaded_values.note_run`) is noted once, when it ends, not after each
    run: each is compared with its value as keyed at the sweep's start either way, and a
    plugin's module holding a 200,000-item dict (0.5 s to hash) or an 80 MB array (0.23 s)
    cost that at each of its runs (h69). Not noted (the package gone meanwhile): seen as
    set by the user at the next sweep, which runs them again."""
    pending: dict[tuple[str, str | None], None] = {}
    token = _PENDING.set(pending)
    try:
        yield
    finally:
        _PENDING.reset(token)
        for target, version in pending:
            try:
                note_run(loaded_modules(target, version))
            except Exception:  # noqa: BLE001 - its package unreadable now: not noted
                continue


def stale_here(task: Task, seen: dict[tuple[str, ...], bool]) -> bool:
    """Whether a method of ``task`` was edited since this process imported it and not
    reloaded (:func:`stale_plugin`): run here, it fails saying so, so the old code's cached
    result is not to be returned instead. ``seen``: the answers so far, per method set."""
    methods = tuple(task.methods())
    if methods not in seen:
        try:
            seen[methods] = bool(stale_plugin(task, worker=False))
        except UnknownMethodError:  # the run fails with the reason
            seen[methods] = True
    return seen[methods]


def _known(name: str) -> bool:
    try:
        method_info(name)
    except UnknownMethodError:  # recorded as a failed run, with the reason
        return False
    return True


def sourceless(task: Task) -> list[str]:
    """The task's methods whose code has no source file (a class defined in a notebook cell
    or in ``python -c``, :func:`method_has_source`): no key can follow an edit of such code,
    so a cached result could be the old code's."""
    return [m for m in task.methods() if _known(m) and not method_has_source(m)]


def unhashable(task: Task, disk: bool) -> list[str]:
    """The task's methods run in this process (not ``disk``) whose modules hold a value set
    since they were loaded that cannot be hashed (:func:`method_values`): no key can tell
    it, so a cached result could be of another value."""
    return [] if disk else [m for m in task.methods() if _known(m) and (
        info := method_info(m)).origin != "builtin" and method_has_source(m)
        and method_values(info.target, info.version) is None]


def uncacheable(task: Task, disk: bool) -> bool:
    """Whether the task's results are neither read from nor written to the cache
    (:func:`sourceless`, :func:`unhashable`)."""
    return bool(sourceless(task) or unhashable(task, disk))


def warn_sourceless(tasks: Sequence[Task], disk: bool = True) -> None:
    """One log line for the runs left out of the cache by :func:`sourceless`, one for those
    by :func:`unhashable`; for workers (``disk``), one for the methods whose modules hold a
    value set in this process, which the workers do not see."""
    names = dict.fromkeys(m for t in tasks for m in sourceless(t))
    if names:
        n = sum(1 for t in tasks if sourceless(t))
        _log.warning("%s not cached: %s %s %s no source file to hash (defined "
                     "in a notebook cell or `python -c`), so a cached result could be from "
                     "before an edit; put the class in a .py module to cache its runs",
                     counted(n, "run"), plural(len(names), "method"),
                     ", ".join(repr(m) for m in names), "has" if len(names) == 1 else "have")
    if disk:  # the workers import the files: a value set here is not theirs
        unseen = dict.fromkeys(m for t in tasks for m in t.methods() if _known(m) and (
            info := method_info(m)).origin != "builtin" and method_values(info.target,
                                                                          info.version))
        if unseen:
            _log.warning("%s %s: a value of their modules was set in this process "
                         "(a global or class attribute changed since loaded), which the "
                         "worker processes do not see: they run the files' values; run "
                         "serially (--jobs 1, Executor('serial')) to run this process's",
                         plural(len(unseen), "method"), ", ".join(repr(m) for m in unseen))
    odd = dict.fromkeys(method_info(m).target for t in tasks for m in unhashable(t, disk))
    if odd:
        n = sum(1 for t in tasks if unhashable(t, disk))
        _log.warning("%s not cached: %s, a value the method's code reads that bomgraph "
                     "cannot hash, so a cached result could be of another value; make it a "
                     "number, string, array, dataclass or container of them, or make it in "
                     "the method", counted(n, "run"),
                     "; ".join(_UNHASHABLE.get(t, t) for t in odd))


def bomgraph_edited() -> bool:
    """Whether bomgraph's or baselines' sources changed since this process first keyed a run
    (:func:`bomgraph.plugins.code_changed`), logged once a call: the keys are of the code as
    first hashed, while the code that runs may be the new one (a module reloaded:
    ``%autoreload``; a worker started since), so the cache is not to be used."""
    if not code_changed():
        return False
    _log.warning("bomgraph's or baselines' sources changed since this process first keyed a "
                 "run, so its keys no longer tell which code runs: runs are neither read "
                 "from nor written to the cache; restart this process (a notebook's kernel) "
                 "to use it again")
    return True


def refuse_runtime_methods(tasks: Sequence[Task], backend: str) -> None:
    """Raise when a method of a task (:meth:`Task.methods`) was registered at run time: worker
    processes start from the installed packages and never see such a registration.

    Raises
    ------
    ConfigError
        Naming the method and how to make it a plugin (or to run serially).
    """
    if backend == "processes" and daemonic():  # run here, serially (bench.execute)
        return
    names = dict.fromkeys(m for t in tasks for m in t.methods())
    for name in names:
        try:
            info = method_info(name)
        except UnknownMethodError:  # recorded as a failed run, with the reason
            continue
        target = ("yourpackage.module:Factory" if info.target.startswith("__main__:")
                  else info.target)
        if info.origin == "runtime":
            raise ConfigError(
                f"method {name!r} was registered at run time (register_method) and the "
                f"workers of executor {backend!r} cannot see it; make it a plugin: in your "
                f"package's "
                f"pyproject.toml add [project.entry-points.\"bomgraph.methods\"] "
                f"{name} = \"{target}\", then `pip install -e .` it (or run serially: "
                f"--jobs 1, Executor('serial'))")


#: The code of each plugin method (:func:`bomgraph.plugins.disk_fingerprint`) when the local
#: worker processes, which joblib keeps from one sweep to the next, last ran it.
_POOL_CODE: dict[str, str | None] = {}


def workers_outdated(tasks: Sequence[Task]) -> bool:
    """Whether a plugin method of ``tasks`` was edited since the local workers last ran it, or
    was never run by them: a worker keeps the code it imported, so after an edit (and a
    reload in a notebook) the next sweep's runs failed as stale workers until the workers
    ended, and a plugin installed after they started is unknown to them."""
    now: dict[str, str | None] = {}
    for m in dict.fromkeys(m for t in tasks for m in t.methods()):
        if not _known(m) or (info := method_info(m)).origin == "builtin":
            continue
        try:
            now[m] = disk_fingerprint(info.target, info.version)
        except UnknownMethodError:  # its runs fail with the reason
            continue
    outdated = any(m not in _POOL_CODE or _POOL_CODE[m] != fp for m, fp in now.items())
    if outdated:
        _POOL_CODE.clear()
    _POOL_CODE.update(now)
    return outdated


__all__ = ["NO_SOURCE", "bomgraph_edited", "method_fingerprint", "method_has_source",
           "method_code", "method_values", "new_sweep", "noting_runs", "stale_plugin",
           "stale_after_run", "stale_here", "sourceless", "unhashable", "uncacheable", "warn_sourceless",
           "refuse_runtime_methods", "workers_outdated"]
