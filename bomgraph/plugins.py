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
libraries that compute their numbers; :func:`source_fingerprint` hashes a method's code (every
``.py`` file of the top-level package of its module, or the module's one file) with the
distribution's version. The runner puts both in the cache key, so editing a plugin (or
upgrading numpy, scipy, gtsam or filterpy) re-runs it. This module imports nothing from
bomgraph but the errors (the registry in :mod:`bomgraph.mapper` builds on it).
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import importlib.util
import logging
import sys
import traceback
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

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
    """Forget what :func:`discover` read (after installing a plugin in a running process)."""
    discover.cache_clear()
    source_fingerprint.cache_clear()
    importlib.invalidate_caches()


def load(target: str, name: str) -> object:
    """Import ``"module:attribute"`` and return the attribute.

    Raises
    ------
    UnknownMethodError
        The module cannot be imported or has no such attribute (the message says which).
    """
    module, _, attr = target.partition(":")
    try:
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
    return obj


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


def _source_files(module_name: str) -> list[tuple[str, Path]]:
    """The ``.py`` files of the top-level package of ``module_name`` (or its one file), each
    with its name relative to the package folder, in a fixed order."""
    top = module_name.split(".")[0]
    mod = sys.modules.get(top) or importlib.import_module(top)
    out: list[tuple[str, Path]] = []
    for root in sorted(getattr(mod, "__path__", []) or []):
        out += [(f.relative_to(root).as_posix(), f) for f in Path(root).rglob("*.py")]
    if not out and getattr(mod, "__file__", None):
        out = [(Path(mod.__file__).name, Path(mod.__file__))]
    return sorted(out)


#: The libraries whose versions :func:`code_fingerprint` holds: they compute the numbers, and
#: another version of one can give other bits for the same bomgraph code.
NUMERIC_LIBRARIES = ("numpy", "scipy", "gtsam", "filterpy")


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """A hash of the installed ``bomgraph`` and ``baselines`` sources and of the versions of
    :data:`NUMERIC_LIBRARIES`: the runner's cache key (:func:`bomgraph.bench.task_key`), so a
    cached result is reused only by the code that produced it. 16 hex digits."""
    h = hashlib.sha256()
    for pkg in ("bomgraph", "baselines"):
        spec = importlib.util.find_spec(pkg)
        if spec is None or not spec.submodule_search_locations:
            continue
        root = Path(list(spec.submodule_search_locations)[0])
        for f in sorted(root.rglob("*.py")):
            h.update(str(f.relative_to(root)).encode())
            h.update(f.read_bytes())
    for lib in NUMERIC_LIBRARIES:
        try:
            h.update(f"{lib}=={metadata.version(lib)};".encode())
        except metadata.PackageNotFoundError:
            h.update(f"{lib} missing;".encode())
    return h.hexdigest()[:16]


@functools.lru_cache(maxsize=64)
def source_fingerprint(target: str, version: str | None = None) -> str | None:
    """A hash of the code behind ``"module:attribute"``: every ``.py`` file of the module's
    top-level package (path relative to the package and contents; the module's own file for
    a single-file module) and ``version``. 16 hex digits; None when the module has no source
    file (a class defined in a notebook cell or in ``python -c``): there is nothing to hash,
    and the runner does not cache such a method's runs (:func:`bomgraph.bench.execute`).

    Raises
    ------
    UnknownMethodError
        The module cannot be imported.
    """
    module = target.partition(":")[0]
    try:
        files = _source_files(module)
    except ImportError as exc:
        _reraise_interrupt(exc)
        raise UnknownMethodError(f"cannot read the source of {target!r}: {exc}") from exc
    if not files:
        return None
    h = hashlib.sha256(f"version={version};".encode())
    for rel, f in files:
        try:
            data = f.read_bytes()
        except OSError:  # a file removed while we read: hash its name only
            data = b""
        h.update(f"{rel}\0{len(data)}\0".encode())
        h.update(data)
    return h.hexdigest()[:16]


__all__ = ["GROUP", "PluginEntry", "discover", "refresh", "load", "source_fingerprint",
           "code_fingerprint", "NUMERIC_LIBRARIES"]
