"""Method plugins: mappers other packages add through the entry-point group ``bomgraph.methods``.

A plugin package declares, in its ``pyproject.toml``::

    [project.entry-points."bomgraph.methods"]
    mine = "mypackage.module:MyMapper"

and, once installed (``pip install .`` or ``pip install -e .``), ``mine`` is a method like the
built-in ones: ``bomgraph methods`` lists it, ``bomgraph run``/``compare`` run it, and so do the
worker processes of a local pool or a Dask cluster, because every process reads the installed
entry points (not the memory of the process that started the sweep). The factory is called as
``Factory(header, **options)`` and returns a :class:`bomgraph.mapper.Mapper`; an optional
``description`` attribute (else the first docstring line) is what ``bomgraph methods`` shows.

:func:`code_fingerprint` hashes the code of bomgraph and baselines and the versions of the
libraries that compute their numbers; :func:`source_fingerprint` hashes a method's code (the
``.py`` files of the top-level package of its module that the module imports, or the whole
package when one of them imports by name: :mod:`bomgraph.import_closure`; or the module's one
file) with the distribution's version. The runner puts both in the cache key, so editing a
plugin (or upgrading numpy, scipy, gtsam or filterpy) re-runs it. The files are listed and
read by :mod:`bomgraph.source_files`; this module adds what a loaded module runs. It imports
nothing else from bomgraph but the errors (the registry in :mod:`bomgraph.mapper` builds on
it).
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import importlib.util
import logging
import sys
import traceback
import types
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

from . import source_files
from .errors import UnknownMethodError

#: The entry-point group a plugin package registers its methods in.
GROUP = "bomgraph.methods"

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PluginEntry:
    """One entry point of the group: the method name, its ``"module:attribute"`` target and
    the distribution that declares it (name and version; None when unknown)."""

    name: str
    target: str
    distribution: str | None
    version: str | None


def name_problem(name: str) -> str:
    """Why ``name`` cannot be a method's name ("" when it can): ``compare --methods
    NAME@PRESET,...`` and ``--option NAME:KEY=VALUE`` split on ``@``, ``,`` and ``:``, so a
    name holding one (or a space) could be listed but never run from the command line."""
    bad = sorted({c for c in name if c in "@,:" or c.isspace()})
    if bad:
        return (f"method name {name!r} holds {', '.join(repr(c) for c in bad)}, which "
                f"`compare --methods NAME@PRESET,...` and `--option NAME:KEY=VALUE` split on, "
                f"so compare cannot run it; rename it (letters, digits, '-', '_', '.')")
    return ""


def warn_name(name: str, where: str) -> None:
    """Log a warning when ``name`` is a method name ``compare`` cannot run (:func:`name_problem`;
    ``bomgraph run --method`` still can, so the method is kept)."""
    problem = name_problem(name)
    if problem:
        _log.warning("%s: %s", where, problem)


@functools.lru_cache(maxsize=1)
def discover() -> dict[str, PluginEntry]:
    """The installed plugins by method name (read once per process; :func:`refresh` reads
    again). Two distributions declaring one name: the first found wins, with a warning."""
    found: dict[str, PluginEntry] = {}
    for ep in metadata.entry_points(group=GROUP):
        dist = getattr(ep, "dist", None)
        entry = PluginEntry(ep.name, ep.value, dist.name if dist else None,
                            dist.version if dist else None)
        warn_name(ep.name, f"method plugin of {entry.distribution or 'an unknown distribution'}"
                           f" (entry point group {GROUP!r})")
        if ep.name in found and found[ep.name].target != entry.target:
            _log.warning("method plugin %r is declared twice (%s and %s); using %s", ep.name,
                         found[ep.name].target, entry.target, found[ep.name].target)
            continue
        found.setdefault(ep.name, entry)
    return found


def refresh() -> None:
    """Forget what :func:`discover` read (after installing a plugin in a running process),
    and the source contents :func:`source_fingerprint` kept for loaded modules."""
    discover.cache_clear()
    source_fingerprint.cache_clear()
    _LOADED.clear()
    _RECORDED.clear()
    source_files.forget()
    from .import_closure import PARSED_IMPORTS
    from .loaded_code import FROM_IMPORTS
    from .loaded_values import forget

    PARSED_IMPORTS.clear()
    FROM_IMPORTS.clear()
    _MODULES.clear()
    forget()
    importlib.invalidate_caches()


def load(target: str, name: str, *, record: bool = True) -> object:
    """Import ``"module:attribute"`` and return the attribute.

    The first time this process loads the module (whoever imported it: this call, another
    plugin's module, the user), the contents of its package's loaded files are recorded
    (:func:`source_fingerprint` keys a loaded file by the contents it had when first hashed):
    an edit made after that and before the first key is then seen as an edit not reloaded,
    not taken for the code that runs. ``record`` False (a built-in method, whose code the
    runner keys whole by :func:`code_fingerprint`): nothing is recorded.

    Raises
    ------
    UnknownMethodError
        The module cannot be imported or has no such attribute (the message says which).
    """
    module, _, attr = target.partition(":")
    try:
        before = set(sys.modules)
        obj: object = importlib.import_module(module)
        for part in attr.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError) as exc:
        _reraise_interrupt(exc)
        raise UnknownMethodError(f"method {name!r} is registered as {target!r} but cannot be "
                                 f"loaded: {exc}") from exc
    except Exception as exc:  # the module itself raised (a SyntaxError, a bad dataclass, ...)
        _reraise_interrupt(exc)
        top = module.split(".")[0]  # the last line of the plugin's own code that ran
        frames = [f for f in traceback.extract_tb(exc.__traceback__)
                  if top in Path(f.filename).parts or Path(f.filename).stem == top]
        where = ("" if isinstance(exc, SyntaxError) or not frames
                 else f" (at {frames[-1].filename}, line {frames[-1].lineno})")
        raise UnknownMethodError(f"method {name!r} is registered as {target!r} but cannot be "
                                 f"loaded: importing it raised {type(exc).__name__}: {exc}"
                                 f"{where}") from exc
    if record and module not in _RECORDED:  # its files now, not as first hashed later
        try:
            # the modules this import loaded run their files' code: not compared again
            _fingerprint(target, None, loaded=True, fresh=set(sys.modules) - before)
            _RECORDED.add(module)
        except UnknownMethodError:  # said again where its key is taken
            pass
    return obj


#: The modules whose package's loaded files :func:`load` recorded (:func:`refresh` forgets).
_RECORDED: set[str] = set()


def _reraise_interrupt(exc: BaseException) -> None:
    """Raise the Ctrl-C (or the CLI's SIGTERM exit) that ``exc`` stands for, if any: an
    extension module whose initialisation is interrupted (pybind11's: GTSAM) reports
    ``ImportError: initialization failed`` caused by the KeyboardInterrupt, which must stop
    the command, not be taken for a method that cannot be loaded."""
    seen: BaseException | None = exc
    while seen is not None:
        if isinstance(seen, (KeyboardInterrupt, SystemExit)):
            raise seen
        seen = seen.__cause__ or seen.__context__


#: The libraries whose versions :func:`code_fingerprint` holds: they compute the numbers, and
#: another version of one can give other bits for the same bomgraph code.
NUMERIC_LIBRARIES = ("numpy", "scipy", "gtsam", "filterpy")


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """A hash of the installed ``bomgraph`` and ``baselines`` sources and of the versions of
    :data:`NUMERIC_LIBRARIES`: the runner's cache key (:func:`bomgraph.bench.task_key`), so a
    cached result is reused only by the code that produced it. 16 hex digits. Taken once
    per process (:func:`code_changed` tells when the sources changed since)."""
    global _CODE_AT_KEY
    _CODE_AT_KEY = _code_state()
    h = hashlib.sha256()
    for root in _code_roots():
        # as rglob's order (the paper's keys kept), no editor's lock (a link to nothing)
        for rel, f in sorted(source_files.py_files(str(root)), key=lambda rf: rf[1]):
            h.update(rel.encode())
            h.update(source_files.read(f))
    for lib in NUMERIC_LIBRARIES:
        try:
            h.update(f"{lib}=={metadata.version(lib)};".encode())
        except metadata.PackageNotFoundError:
            h.update(f"{lib} missing;".encode())
    return h.hexdigest()[:16]


def _code_roots() -> list[Path]:
    roots = []
    for pkg in ("bomgraph", "baselines"):
        spec = importlib.util.find_spec(pkg)
        if spec is not None and spec.submodule_search_locations:
            roots.append(Path(list(spec.submodule_search_locations)[0]))
    return roots


def _code_state() -> list[tuple[str, bytes]]:
    return [(f"{root}/{rel}", source_files.disk_digest(f)) for root in _code_roots()
            for rel, f in sorted(source_files.py_files(str(root)))]


#: :func:`_code_state` when :func:`code_fingerprint` hashed the sources.
_CODE_AT_KEY: list[tuple[str, bytes]] | None = None


def code_changed() -> bool:
    """Whether the ``bomgraph`` or ``baselines`` sources changed since this process took
    :func:`code_fingerprint` (once, for every key it makes): its keys then no longer tell
    which code a run ran (this process's, reloaded or not, or a new worker's)."""
    code_fingerprint()
    return _code_state() != _CODE_AT_KEY


@functools.lru_cache(maxsize=64)
def source_fingerprint(target: str, version: str | None = None) -> str | None:
    """A hash of the code behind ``"module:attribute"`` as this process would run it: the
    ``.py`` files of the module's top-level package that importing it can run
    (:func:`bomgraph.import_closure.closure`: path relative to the package and contents;
    the module's own file for a single-file module) and ``version``. 16 hex
    digits; None when the module has no source file (a class defined in a notebook cell or
    in ``python -c``): there is nothing to hash, and the runner does not cache such a
    method's runs (:func:`bomgraph.bench.execute`).

    A file whose module is loaded counts with the contents it had when this process first
    hashed it, until the module is reloaded (``importlib.reload``, IPython's autoreload:
    its code or its constants change), so the key follows the code that runs, not an edit
    the process has not loaded (:func:`disk_fingerprint` is the file as it is now). Kept
    for the process; :func:`bomgraph.bench.execute` forgets it at each call, so a reload
    between two sweeps is seen; :func:`refresh` forgets the loaded contents too.

    Raises
    ------
    UnknownMethodError
        The module cannot be imported.
    """
    return _fingerprint(target, version, loaded=True)


def disk_fingerprint(target: str, version: str | None = None) -> str | None:
    """:func:`source_fingerprint` of the files as they are on disk now: what a process that
    imports the method from now on runs."""
    return _fingerprint(target, version, loaded=False)


#: Per source file of a loaded module: the digest of its contents when this process first
#: hashed it, and :func:`_module_state` of the module then (a change of that: a reload).
_LOADED: dict[Path, tuple[bytes, dict[Any, tuple[str, object]]]] = {}


def _fingerprint(target: str, version: str | None, loaded: bool,
                 fresh: set[str] | frozenset[str] = frozenset()) -> str | None:
    from .import_closure import closure

    module = target.partition(":")[0]
    try:
        files, several_roots = source_files.package_files(module)
    except ImportError as exc:
        _reraise_interrupt(exc)
        raise UnknownMethodError(f"cannot read the source of {target!r}: {exc}") from exc
    except Exception as exc:  # its package raised while imported (an edit that broke it)
        _reraise_interrupt(exc)
        raise UnknownMethodError(f"cannot read the source of {target!r}: importing it raised "
                                 f"{type(exc).__name__}: {exc}") from exc
    if not files:
        return None
    disk = {f: source_files.disk_digest(f) for _, f in files}
    # the files importing the module can run (not another method's module of the package)
    files = closure(module, files, disk, several_roots=several_roots)
    top = module.split(".")[0]
    modules = {Path(m.__file__).resolve(): m for name, m in list(sys.modules.items())
               if (name == top or name.startswith(top + ".") or name == "__main__")
               and isinstance(getattr(m, "__file__", None), str)} if loaded else {}
    h = hashlib.sha256(f"version={version};".encode())
    for rel, f in files:
        h.update(f"{rel}\0".encode())
        mod = modules.get(f.resolve()) if modules else None
        h.update(disk[f] if mod is None else
                 _file_digest(f, mod, getattr(mod, "__name__", None) not in fresh))
        if mod is not None and _stale_imports(mod, f, disk[f], top):
            # it holds a name of a module reloaded since (from .helpers import SCALE): it
            # runs that module's old code, which no file holds now
            h.update(b"holds names of a module reloaded since")
    if loaded:
        _MODULES[target] = [m for _, f in files if (m := modules.get(f.resolve())) is not None]
    return h.hexdigest()[:16]


#: Per target: the loaded modules of its files, when :func:`source_fingerprint` last hashed it.
_MODULES: dict[str, list[types.ModuleType]] = {}


def loaded_modules(target: str, version: str | None = None) -> list[types.ModuleType]:
    """The modules of the files of ``target``'s key (:func:`source_fingerprint`) that this
    process has loaded, in their order."""
    source_fingerprint(target, version)
    return list(_MODULES.get(target, []))


def _stale_imports(module: types.ModuleType, path: Path, digest: bytes, top: str) -> bool:
    from .loaded_code import stale_imports

    try:
        return bool(stale_imports(module, lambda: source_files.read(path), digest, top))
    except Exception:  # a loaded object whose comparison raises: taken as the file's
        return False


def _file_digest(path: Path, module: object | None, check: bool = True) -> bytes:
    """The digest of a source file's contents: as read now, or for a loaded ``module`` as
    read when this process first hashed it, as long as the module is as it was then.
    ``check``: whether the module may have been loaded before (not by the import that has
    just loaded it), so its code is compared with the file's (:mod:`.loaded_code`)."""
    state = None if module is None else _module_state(module)
    seen = _LOADED.get(path)
    if state is not None and seen is not None and _same_state(seen[1], state):
        return seen[0]
    if state is None:
        return source_files.disk_digest(path)
    from .loaded_code import runs_file

    data = source_files.read(path)
    digest = source_files.digest(data)
    if seen is not None and digest != seen[0] and not _reloaded(seen[1], state, data):
        # only globals its own code rebinds changed (a lazy cache: ``global _MODEL``), not a
        # reload: it runs the code first hashed, not the file edited since (whose changes to
        # values that are not literals, ``W = np.array(...)``, the comparison cannot see)
        _LOADED[path] = (seen[0], state)
        return seen[0]
    # imported before this first hash (by the user, in a notebook), and edited between: the
    # file is not the code that runs, which no file's key is then to stand for
    if check and data and not runs_file(module, data):  # type: ignore[arg-type]
        digest = hashlib.sha256(b"loaded code is not the file's\0" + digest).digest()
    _LOADED[path] = (digest, state)
    return digest


_PLAIN = (int, float, complex, str, bytes, bool, type(None))


def _module_state(module: object) -> dict[Any, tuple[str, object]]:
    """What a reload of ``module`` changes, to be compared within this process
    (:func:`_same_state`): each global, a plain constant (numbers, strings and tuples of them)
    by value and anything else by identity (an assignment run again binds a new object;
    ``importlib.reload``, and IPython's autoreload through it, give the module a new
    ``__spec__``), and the code and defaults of the functions and of the classes' functions
    defined in it (IPython 9's autoreload replaces those in place). The objects are held, so
    that no identity is reused; only a function's or a class's own attributes are read (an
    arbitrary object's may raise)."""
    name = getattr(module, "__name__", None)
    out: dict[Any, tuple[str, object]] = {}

    def add(key: Any, value: object, depth: int = 0) -> None:
        kind = type(value)
        try:
            plain = issubclass(kind, _PLAIN) or (issubclass(kind, tuple) and all(
                issubclass(type(v), _PLAIN) for v in value))  # type: ignore[attr-defined]
        except Exception:  # a tuple subclass whose iteration raises
            plain = False
        out[key] = ("=" if plain else "is", value)
        try:
            if issubclass(kind, (staticmethod, classmethod)):
                add((key, "__func__"), value.__func__, depth)  # type: ignore[attr-defined]
            elif issubclass(kind, property):
                for part in ("fget", "fset", "fdel"):
                    add((key, part), getattr(value, part), depth)
            elif issubclass(kind, types.FunctionType) and value.__module__ == name:
                for part in ("__code__", "__defaults__", "__kwdefaults__"):
                    out[(key, part)] = ("is", getattr(value, part))
            elif issubclass(kind, type) and depth < 4 and value.__dict__.get(
                    "__module__") == name:
                for k, v in list(value.__dict__.items()):
                    add((key, k), v, depth + 1)
        except Exception:  # an attribute that raises: the object's identity stands alone
            pass

    for k, v in list(vars(module).items()):
        add(k, v)
    return out


def _reloaded(a: dict[Any, tuple[str, object]], b: dict[Any, tuple[str, object]],
              source: bytes) -> bool:
    """Whether the module of :func:`_module_state` ``a``, now ``b``, may run other code than
    then: a global (or a class attribute) changed that its ``source`` does not rebind at run
    time (``global NAME`` in a function, ``obj.NAME = ...``): a reload (a new ``__spec__``,
    new functions; IPython 9's autoreload runs an edited assignment again in place), or a
    constant set in memory by the user."""
    from .loaded_code import rebound_at_run_time

    names, attrs = rebound_at_run_time(source)
    for k in a.keys() | b.keys():
        if k in a and k in b and _same_state({k: a[k]}, {k: b[k]}):
            continue
        if isinstance(k, str) and k in names:
            continue  # global NAME in a function
        if (isinstance(k, tuple) and len(k) == 2 and isinstance(k[0], str) and k[1] in attrs
                and not k[1].startswith("__")):
            continue  # a class attribute: cls.NAME = ...
        return True
    return False


def _same_state(a: dict[Any, tuple[str, object]], b: dict[Any, tuple[str, object]]) -> bool:
    """Whether two :func:`_module_state` are of the same loaded code."""
    if a.keys() != b.keys():
        return False
    for k, (how, x) in a.items():
        how_b, y = b[k]
        if x is y:
            continue
        if how != "=" or how_b != "=" or type(x) is not type(y):
            return False
        try:
            if not x == y:  # a float NaN bound anew counts as a change (a reload, or not)
                return False
        except Exception:
            return False
    return True


__all__ = ["GROUP", "PluginEntry", "discover", "refresh", "load", "source_fingerprint",
           "disk_fingerprint",
           "code_fingerprint", "code_changed", "NUMERIC_LIBRARIES"]
