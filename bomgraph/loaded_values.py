"""The values that a loaded method's code reads from its modules, for a serial run's cache key.

A serial run runs the method's modules as this process holds them: their code, which
:mod:`bomgraph.plugins` keys by its files, and the values of their globals, which the user
can change without touching a file: ``mymethod.set_depth(3.0)`` (a function that rebinds
``global DEPTH_M``), ``mymethod.TABLE["scale"] = 3.0`` (a dict changed in place),
``mymethod.TABLE = {...}``. The files' key stayed the same, so the result of the old values
was served from the cache (h64). :func:`values_fingerprint` is a hash of the globals (and of
the classes' data attributes) of the method's loaded modules that the code of any of them
names (``config.PARAMS``, ``self.GAIN``, or in a string: ``getattr(self, "GAIN")``), each by
its value (:func:`_encode`: numbers, strings, containers of them in order, arrays, enums,
dataclasses, functions by their code, else its pickle, or for a compiled object that has
none its printed form and properties, and a gtsam one's getters), of those that differ from
the value their module had when it was loaded: None ("") when none does, so an unchanged method keeps its key, the one worker
processes use (they import the files). The value a module had when loaded is its file's
literal (``DEPTH_M = 1.0``, ``TABLE = {"scale": 1.0}``: a value set before the first sweep is
seen), else the value when bomgraph first saw the module (after a reload, again).

A global that a run of the method changed (a lazy cache: ``global _MODEL``, a memo dict
filled in place, a counter) is the method's own state: it is left out from then on
(:func:`note_run`, once at the end of a sweep), its value at a run's start taken not to change
the result.

Not seen: a global that is not a literal in its file, changed before bomgraph first saw the
module; a global that a run changed, changed again by the user; one read by a name the code
builds at run time (``getattr(self, f"GAIN_{k}")``); a gtsam object's setting
that neither its printed form nor a getter shows (an explicit ``setOrdering``, iterative
solver parameters). A value that cannot be hashed, changed or not (whether it changed cannot
be told: an object that neither the encoding nor pickle reads, a container of more than
:data:`MAX_ITEMS` items, one that holds itself): :func:`values_fingerprint` raises
:class:`Unhashable`, and the runner caches none of that method's serial runs (one log line).
"""

from __future__ import annotations

import ast
import dataclasses
import enum
import functools
import hashlib
import logging
import pathlib
import pickle
import re
import threading
import types
import warnings
from typing import Any, Iterator

import numpy as np

#: Items (container elements, counted recursively) a global's value may hold to be hashed.
MAX_ITEMS = 1_000_000

_PLAIN = (int, float, complex, str, bytes, bool, type(None))
_LOCKS = (type(threading.Lock()), type(threading.RLock()), threading.Condition,
          threading.Event, threading.Semaphore)
_CODE = (types.ModuleType, type, types.FunctionType, types.BuiltinFunctionType,
         types.MethodDescriptorType, types.WrapperDescriptorType, types.MethodWrapperType,
         types.ClassMethodDescriptorType, staticmethod, classmethod, property, np.ufunc)


class Unhashable(Exception):
    """A global's value that :func:`values_fingerprint` cannot hash (the message names it)."""


def _code_like(value: object) -> bool:
    """Whether ``value`` is code, which the files' key covers (a module, class, function,
    a decorated one), or state no result depends on (a logger, a lock, a typing form)."""
    kind = type(value)  # not isinstance: an object may raise for its __class__
    try:
        if issubclass(kind, _CODE):
            owner = getattr(value, "__self__", None)
            return owner is None or issubclass(type(owner), types.ModuleType)
        if issubclass(kind, (logging.Logger, re.Pattern, *_LOCKS)):
            return True
        if kind.__module__ in ("typing", "typing_extensions"):
            return True
        return callable(value) and getattr(value, "__wrapped__", None) is not None
    except Exception:  # an object whose attributes raise
        return False


def _encode(value: object, h: Any, budget: list[int], stack: set[int]) -> None:
    """Feed ``value``, by value, to the hash ``h`` (raises :class:`Unhashable`)."""
    budget[0] -= 1
    if budget[0] < 0:
        raise Unhashable(f"more than {MAX_ITEMS:,} items")
    kind = type(value)
    if kind in _PLAIN:
        h.update(f"{kind.__name__}:{value!r};".encode())
        return
    if id(value) in stack:
        raise Unhashable("it holds itself")
    stack.add(id(value))
    try:
        _encode_object(value, kind, h, budget, stack)
    except Unhashable:
        raise
    except Exception as exc:  # an object whose attributes raise
        raise Unhashable(f"a {kind.__qualname__} whose reading raised {type(exc).__name__}"
                         ) from exc
    finally:
        stack.discard(id(value))


def _encode_object(value: Any, kind: type, h: Any, budget: list[int], stack: set[int]) -> None:
    h.update(f"<{kind.__module__}.{kind.__qualname__}".encode())
    if isinstance(value, enum.Enum):
        h.update(value.name.encode())
    elif isinstance(value, (tuple, list)):  # in order: a method iterates it so
        h.update(f"[{len(value)}".encode())
        for v in value:
            _encode(v, h, budget, stack)
    elif isinstance(value, dict):
        h.update(f"{{{len(value)}".encode())
        for k, v in list(value.items()):
            _encode(k, h, budget, stack)
            _encode(v, h, budget, stack)
    elif isinstance(value, (set, frozenset)):  # its order is the strings' hash seed's
        parts = []
        for v in list(value):
            sub = hashlib.sha256()
            _encode(v, sub, budget, stack)
            parts.append(sub.digest())
        h.update(b"".join(sorted(parts)))
    elif isinstance(value, np.ndarray):
        h.update(f"{value.dtype.str}{value.shape}".encode())
        if value.dtype.hasobject:
            _encode(value.tolist(), h, budget, stack)
        else:
            h.update(np.ascontiguousarray(value).tobytes())
    elif isinstance(value, np.generic):
        h.update(value.dtype.str.encode() + value.tobytes())
    elif isinstance(value, np.random.Generator):
        _encode(value.bit_generator.state, h, budget, stack)
    elif isinstance(value, pathlib.PurePath):
        h.update(str(value).encode())
    elif isinstance(value, functools.partial):
        _encode((value.func, value.args, value.keywords), h, budget, stack)
    elif isinstance(value, types.FunctionType):  # its code, by value, and what it holds
        from .loaded_code import code_shape

        h.update(f"{value.__module__}.{value.__qualname__}".encode())
        h.update(repr(code_shape(value.__code__)).encode())
        cells = tuple(c.cell_contents if _full(c) else _EMPTY for c in value.__closure__ or ())
        _encode((value.__defaults__, value.__kwdefaults__, cells), h, budget, stack)
    elif isinstance(value, types.MethodType):
        _encode((value.__func__, value.__self__), h, budget, stack)
    elif _code_like(value):
        h.update(f"{getattr(value, '__module__', '')}.{getattr(value, '__qualname__', '')}"
                 .encode())
    elif dataclasses.is_dataclass(value):
        for f in dataclasses.fields(value):
            h.update(f.name.encode())
            _encode(getattr(value, f.name), h, budget, stack)
    else:
        try:
            data = pickle.dumps(value, protocol=4)
        except Exception as exc:  # noqa: BLE001 - any object's pickling may raise anything
            if not _gtsam_params(kind) or not _encode_params(value, kind, h, budget, stack):
                raise Unhashable(f"a {kind.__module__}.{kind.__qualname__} that cannot be "
                                 f"pickled ({type(exc).__name__})") from exc
            return
        h.update(hashlib.sha256(data).digest())


#: The form a compiled extension's object prints in when it has no printed form of its own.
_DEFAULT_REPR = re.compile(r"<[\w.]+ object at 0x[0-9a-fA-F]+>")


def _gtsam_params(kind: type) -> bool:
    """Whether ``kind`` is a gtsam parameters class (``LevenbergMarquardtParams``,
    ``ISAM2Params``, ...): only those are read by their printed form and getters; printing
    another gtsam object can crash the process (a default-made factor's does)."""
    return kind.__module__.split(".")[0] == "gtsam" and kind.__name__.endswith("Params")


def _encode_params(value: Any, kind: type, h: Any, budget: list[int], stack: set[int]) -> bool:
    """Feed a gtsam parameters object, which pickle cannot read, by what it tells of its
    value: its printed form (unless the default ``<... object at 0x...>``), its properties
    and what its zero-argument ``get*``/``is*`` methods return:
    ``PARAMS = gtsam.LevenbergMarquardtParams()`` and ``PARAMS.setMaxIterations(300)`` (h69).
    False when it tells nothing (its value cannot be hashed)."""
    told = False
    text = str(value)
    if not _DEFAULT_REPR.fullmatch(text.strip()):
        h.update(b"str:" + text.encode())
        told = True
    props = sorted({n for c in kind.__mro__ for n, a in vars(c).items()
                    if isinstance(a, property) and not n.startswith("_")})
    getters = sorted(n for n in dir(value) if n.startswith(("get", "is")))
    for name in props + getters:
        try:
            part = getattr(value, name)
            if name in getters:
                part = part()
        except TypeError:  # a getter that takes arguments
            continue
        h.update(f";{name}=".encode())
        _encode(part, h, budget, stack)
        told = True
    return told


_EMPTY = "<empty cell>"


def _full(cell: Any) -> bool:
    try:
        cell.cell_contents
    except ValueError:
        return False
    return True


def _digest(value: object) -> bytes:
    h = hashlib.sha256()
    _encode(value, h, [MAX_ITEMS], set())
    return h.digest()


def _code_names(module: types.ModuleType) -> set[str]:
    """The names the module's functions (and its classes' functions) name: the globals and
    attributes its code can read (all its own when among them are ``globals``, ``vars``)."""
    from .loaded_code import module_code, nested_code

    names: set[str] = set()
    filename = getattr(module, "__file__", None)
    if not isinstance(filename, str):
        return names
    for code in module_code(module, filename):
        for c in (code, *nested_code(code)):
            names.update(c.co_names)  # and names in strings: getattr(self, "GAIN") (h69)
            names.update(k for k in c.co_consts if isinstance(k, str) and k.isidentifier())
    return names


def _all_names(modules: list[types.ModuleType]) -> dict[str, set[str] | None]:
    """Per module name, the names that the method's code can read of it: those that any of
    its modules' code names (:func:`_code_names`), as one module's code reads another's
    globals (``config.PARAMS["depth"]``) and a base class's code a subclass's attributes
    (``self.GAIN`` in ``base.py``, ``Mine.GAIN = [3.0]`` set on ``m.Mine``); None (all) for a
    module whose own code names ``globals`` or ``vars``."""
    own = {m.__name__: _code_names(m) for m in modules}
    names = set().union(*own.values())
    return {k: None if {"globals", "vars"} & v else names for k, v in own.items()}


def _values(module: types.ModuleType, names: set[str] | None
            ) -> Iterator[tuple[str, object]]:
    """The data the method's code can read from the module: its globals in ``names``
    (:func:`_all_names`; None: all) and its own classes' data attributes in them
    (``Cls.NAME``), each by key; code and dunder names left out, but for a plain function
    (a global rebound to another function: ``mymethod.scale = lambda: 3.0``, h69)."""
    for k, v in list(vars(module).items()):
        if not isinstance(k, str) or k.startswith(("__", "@")):
            continue
        if issubclass(type(v), type) and v.__dict__.get("__module__") == module.__name__:
            yield from _class_values(k, v, names)
        elif (names is None or k in names) and _data(v):
            yield k, v


def _class_values(key: str, cls: type, names: set[str] | None, depth: int = 0
                  ) -> Iterator[tuple[str, object]]:
    """:func:`_values` of a class: its data attributes in ``names``, and those of the
    classes defined in its body (``Mine.Defaults.GAIN``, h69), each as ``key.NAME``."""
    for a, x in list(cls.__dict__.items()):
        if a.startswith("__") or a == "_abc_impl":
            continue
        if (issubclass(type(x), type) and depth < 4 and x.__dict__.get("__module__")
                == cls.__module__ and x.__qualname__ == f"{cls.__qualname__}.{a}"):
            yield from _class_values(f"{key}.{a}", x, names, depth + 1)
        elif (names is None or a in names) and _data(x):
            yield f"{key}.{a}", x


def _data(value: object) -> bool:
    return type(value) is types.FunctionType or not _code_like(value)


def _literals(module: types.ModuleType) -> dict[str, object]:
    """The module's globals bound once at its top level by a literal (``DEPTH_M = 1.0``),
    named nowhere else at its top level (not changed there: ``ITEMS.append(2)``), by name;
    and so its classes' attributes (``class Mine: GAIN = [1.0]``, as ``Mine.GAIN``: one set
    before the first sweep was taken for the file's, h69)."""
    try:
        with open(module.__file__, "rb") as fh:  # type: ignore[arg-type]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                tree = ast.parse(fh.read())
    except (OSError, TypeError, AttributeError, SyntaxError, ValueError, RecursionError,
            MemoryError):
        return {}
    out: dict[str, object] = {}
    named: dict[str, int] = {}
    attrs: set[str] = set()
    for stmt in tree.body:
        for node in _run_at_import(stmt):
            if isinstance(node, ast.Name):
                named[node.id] = named.get(node.id, 0) + 1
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                named[node.name] = named.get(node.name, 0) + 1
            elif isinstance(node, ast.Attribute):  # Mine.GAIN.append(2): not the file's
                attrs.add(node.attr)
        body = stmt.body if isinstance(stmt, ast.ClassDef) else [stmt]
        for sub in body:
            target = (sub.targets[0] if isinstance(sub, ast.Assign) and len(sub.targets) == 1
                      else sub.target if isinstance(sub, ast.AnnAssign) else None)
            if isinstance(target, ast.Name) and getattr(sub, "value", None) is not None:
                try:
                    value = ast.literal_eval(sub.value)  # type: ignore[arg-type]
                except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError):
                    continue
                if sub is stmt:
                    out[target.id] = value
                elif named.get(stmt.name) == 1 and target.id not in attrs:  # type: ignore
                    out[f"{stmt.name}.{target.id}"] = value  # type: ignore[attr-defined]
    return {k: v for k, v in out.items() if all(named.get(n) == 1 for n in k.split("."))}


def _run_at_import(node: ast.AST) -> Iterator[ast.AST]:
    """``node`` and the nodes under it that run when the module is imported: not those of a
    function's or a lambda's body (a class's body runs)."""
    yield node
    if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
        return
    for child in ast.iter_child_nodes(node):
        yield from _run_at_import(child)


#: Per module name: the module, its ``__spec__`` then (a reload gives a new one) and the
#: digest of each of its values (:func:`_values`) when loaded (None: not known).
_LOADED: dict[str, tuple[types.ModuleType, object, dict[str, bytes | None]]] = {}
#: The values (module name, key) that a run of a method changed: its own state.
_RUN_STATE: set[tuple[str, str]] = set()
#: The digest of each value as last keyed, by (module name, key) (:func:`note_run`), and
#: the modules keyed.
_AT_KEY: dict[tuple[str, str], bytes | None] = {}
_KEYED: set[str] = set()


#: Per (module name, key): a function it held when loaded that cannot be hashed by value
#: (a library's, with an odd default), kept so that it is known as the same object.
_HELD: dict[tuple[str, str], object] = {}


def _safe_digest(value: object) -> bytes | None:
    try:
        return _digest(value)
    except Unhashable:
        return None


def _value_digest(module: types.ModuleType, key: str, value: object) -> bytes:
    """:func:`_digest` of a module's value (raises :class:`Unhashable`); a function by its
    name when it is the module's own (the files' key and :mod:`bomgraph.loaded_code` cover
    its code), else by its code (:func:`_encode`), or as the object held when loaded."""
    if type(value) is not types.FunctionType:
        return _digest(value)
    code = value.__code__
    if value.__module__ == module.__name__ and code.co_filename == getattr(
            module, "__file__", None):
        return f"own function {value.__qualname__}".encode()
    if _HELD.get((module.__name__, key)) is value:
        return f"function held {id(value)}".encode()
    return _digest(value)


def _safe_value_digest(module: types.ModuleType, key: str, value: object) -> bytes | None:
    try:
        return _value_digest(module, key, value)
    except Unhashable:
        return None


def _loaded(module: types.ModuleType) -> dict[str, bytes | None]:
    """The digests of the module's values when it was loaded (:data:`_LOADED`)."""
    name = module.__name__
    seen = _LOADED.get(name)
    if seen is not None and seen[0] is module and seen[1] is module.__spec__:
        return seen[2]
    literals = _literals(module)
    base: dict[str, bytes | None] = {}
    for key, value in _values(module, None):
        now = _safe_value_digest(module, key, value)
        if now is None and type(value) is types.FunctionType:
            _HELD[(name, key)] = value
            now = _value_digest(module, key, value)
        if key in literals:  # set before bomgraph saw it: its value when loaded is unknown
            base[key] = now if now == _safe_digest(literals[key]) else None
        else:
            base[key] = now
    for key in [k for k in _RUN_STATE if k[0] == name]:
        _RUN_STATE.discard(key)  # reloaded: its values are the file's again
    _LOADED[name] = (module, module.__spec__, base)
    return base


def values_fingerprint(modules: list[types.ModuleType]) -> str:
    """A hash of the values of ``modules`` (a method's loaded modules) that differ from
    their values when loaded (:mod:`bomgraph.loaded_values`), "" when none does.

    Raises
    ------
    Unhashable
        Such a value cannot be hashed (the message names the module, the global and why).
    """
    changed, problem = [], ""
    names = _all_names(modules)
    for module in modules:
        base = _loaded(module)
        _KEYED.add(module.__name__)
        for key, value in _values(module, names[module.__name__]):
            where = (module.__name__, key)
            if where in _RUN_STATE:
                continue
            try:
                now = _value_digest(module, key, value)
            except Unhashable as exc:
                _AT_KEY[where] = None
                problem = problem or f"{module.__name__}.{key} is {exc}"
                continue
            _AT_KEY[where] = now
            if base.get(key) is None or base[key] != now:  # changed, or not known
                changed.append(f"{module.__name__}.{key}\0".encode() + now)
    if problem:
        raise Unhashable(problem)
    return hashlib.sha256(b"".join(changed)).hexdigest()[:16] if changed else ""


def note_run(modules: list[types.ModuleType]) -> None:
    """After a run in this process: the values of ``modules`` that differ from their keyed
    ones (:func:`values_fingerprint`), or were made by the run (a class attribute set
    lazily), are the method's own state, left out of the keys from now on."""
    names = _all_names(modules)
    for module in modules:
        if module.__name__ not in _KEYED:  # loaded by the run: nothing to compare with
            continue
        for key, value in _values(module, names[module.__name__]):
            where = (module.__name__, key)
            if where in _RUN_STATE:
                continue
            if where not in _AT_KEY:
                _RUN_STATE.add(where)
            elif _AT_KEY[where] is not None and _safe_value_digest(
                    module, key, value) != _AT_KEY[where]:
                _RUN_STATE.add(where)


def forget() -> None:
    """Forget the values seen (:func:`bomgraph.plugins.refresh`)."""
    _LOADED.clear()
    _HELD.clear()
    _RUN_STATE.clear()
    _AT_KEY.clear()
    _KEYED.clear()


__all__ = ["MAX_ITEMS", "Unhashable", "values_fingerprint", "note_run", "forget"]
