"""Whether a loaded module runs the code that its source file holds now.

:mod:`bomgraph.plugins` keys a loaded module's file by its contents when it first hashes it,
taken for the code that runs. A module imported before that (by the user, in a notebook:
``import mymethod``, then ``import bomgraph`` and a sweep) may have been edited in between:
the file is then not the code that runs, and a result of the old code would be cached under
the new file's key (and served to the new code later). :func:`runs_file` compares the code
the module runs with a compilation of the file's text: every function's and method's byte
code, names and constants (line numbers aside: moving code changes no result), and the
constants bound once by a plain literal at module or class level (``DEPTH_M = 1.0``).

A module whose asserts pytest rewrote on import (a test module) is compared with the file
compiled both plainly and as pytest rewrites it.

Not seen: an edit between import and first hash of a value that is not such a literal
(``W = np.array([1, 2])``, a dict or list, which the module may fill at run time), nor of code
a function does not hold (a module-level statement's side effects).
"""

from __future__ import annotations

import ast
import functools
import inspect
import sys
import types
import warnings
from typing import Any, Callable, Iterator

#: Literal values compared by value: what no code of the module can change in place.
_IMMUTABLE = (int, float, complex, str, bytes, bool, type(None), tuple, frozenset)


#: ``co_flags`` bits that a decorator sets on a loaded function's code (``types.coroutine``).
_SET_BY_DECORATORS = inspect.CO_ITERABLE_COROUTINE


def runs_file(module: types.ModuleType, source: bytes) -> bool:
    """Whether ``module`` (loaded) runs the code of ``source`` (its file's contents now).
    False also when the text no longer compiles; True when the module's file name or code
    cannot be read (nothing to compare)."""
    filename = getattr(module, "__file__", None)
    if not isinstance(filename, str):
        return True
    try:
        with warnings.catch_warnings():  # its import said them (SyntaxWarning: "\\d")
            warnings.simplefilter("ignore")
            fresh = compile(source, filename, "exec", dont_inherit=True)
            tree = ast.parse(source, filename)
            rewritten = _pytest_rewritten(module, source, filename)
    except (SyntaxError, ValueError):  # the file does not compile now: not the loaded code
        return False
    compiled: dict[str, set[Any]] = {}
    for code in (nested_code(fresh) if rewritten is None
                 else (*nested_code(fresh), *nested_code(rewritten))):
        compiled.setdefault(code.co_qualname, set()).add(code_shape(code))
    for code in module_code(module, filename):
        if code_shape(code) not in compiled.get(code.co_qualname, ()):
            return False
    return _same_literals(module, tree)


def _pytest_rewritten(module: types.ModuleType, source: bytes,
                      filename: str) -> types.CodeType | None:
    """``source`` compiled as pytest compiles a module whose asserts it rewrites (a test
    module, a conftest, a ``register_assert_rewrite`` one), when ``module`` is one such
    (its globals hold ``@pytest_ar``): its functions' code is then not the plain file's."""
    if "@pytest_ar" not in vars(module):
        return None
    try:
        from _pytest.assertion.rewrite import rewrite_asserts

        tree = ast.parse(source, filename)
        rewrite_asserts(tree, source, filename)
        return compile(tree, filename, "exec", dont_inherit=True)
    except (ImportError, SyntaxError, ValueError, TypeError):  # another pytest: compared plainly
        return None


def nested_code(code: types.CodeType) -> Iterator[types.CodeType]:
    """The code objects inside ``code`` (its functions, classes, comprehensions), depth first."""
    for c in code.co_consts:
        if isinstance(c, types.CodeType):
            yield c
            yield from nested_code(c)


def code_shape(code: types.CodeType) -> tuple[Any, ...]:
    """What a code object computes: all but its line numbers."""
    consts = tuple(code_shape(c) if isinstance(c, types.CodeType) else _const(c)
                   for c in code.co_consts)
    return (code.co_qualname, code.co_code, code.co_names, code.co_varnames,
            code.co_freevars, code.co_cellvars, code.co_argcount, code.co_posonlyargcount,
            code.co_kwonlyargcount, code.co_flags & ~_SET_BY_DECORATORS,
            code.co_exceptiontable, consts)


def _const(value: object) -> tuple[str, str]:
    if isinstance(value, frozenset):
        return ("frozenset", repr(sorted(map(repr, value))))
    return (type(value).__qualname__, repr(value))


def module_code(module: types.ModuleType, filename: str) -> Iterator[types.CodeType]:
    """The code objects of the functions ``module`` defines (its own file's), at module
    level and in its classes, through decorators that keep ``__wrapped__``."""
    seen: set[int] = set()

    def walk(obj: object, depth: int) -> Iterator[types.CodeType]:
        if id(obj) in seen or depth > 6:
            return
        seen.add(id(obj))
        try:
            if isinstance(obj, types.FunctionType):
                if obj.__code__.co_filename == filename:
                    yield obj.__code__
            elif isinstance(obj, (staticmethod, classmethod)):
                yield from walk(obj.__func__, depth + 1)
            elif isinstance(obj, property):
                for part in (obj.fget, obj.fset, obj.fdel):
                    yield from walk(part, depth + 1)
            elif isinstance(obj, type):
                if obj.__dict__.get("__module__") == module.__name__:
                    for v in list(obj.__dict__.values()):
                        yield from walk(v, depth + 1)
                return
            wrapped = getattr(obj, "__wrapped__", None) if not isinstance(
                obj, types.ModuleType) else None
            if wrapped is not None:
                yield from walk(wrapped, depth + 1)
        except Exception:  # an object whose attributes raise: nothing to compare
            return

    for value in list(vars(module).values()):
        yield from walk(value, 0)


def rebound_at_run_time(source: bytes) -> tuple[frozenset[str], frozenset[str]]:
    """The globals and the attributes that the code of ``source`` (a module's file) may
    rebind after its import: declared ``global`` in a function; set as an attribute
    (``cls.NAME = ...``, ``setattr(obj, "NAME", ...)``). Empty when it does not parse."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tree = ast.parse(source)
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        return frozenset(), frozenset()
    names: set[str] = set()
    attrs: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Global):
            names.update(node.names)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            attrs.add(node.attr)
        elif isinstance(node, ast.Call) and getattr(node.func, "id", None) == "setattr" and len(
                node.args) > 1 and isinstance(node.args[1], ast.Constant):
            attrs.add(str(node.args[1].value))
    return frozenset(names), frozenset(attrs)


#: Per source digest: its module-level ``from M import NAME`` bindings (M absolute, NAME,
#: the name bound), those of names the file binds nowhere else.
FROM_IMPORTS: dict[bytes, tuple[tuple[str, str, str], ...]] = {}


def stale_imports(module: types.ModuleType, source: Callable[[], bytes], digest: bytes,
                  top: str) -> list[str]:
    """The names ``module`` bound at its import by ``from M import NAME`` (at module level,
    ``M`` a module of package ``top``; ``source()``: the file's text, of ``digest``) that no
    longer hold what ``M`` holds: ``M`` was reloaded (``importlib.reload``, IPython's
    autoreload of an edited ``M``) and ``module`` was not, so it still runs ``M``'s old
    ``NAME`` (a constant, a function, a class). Each as ``"module.NAME (M)"``."""
    if digest not in FROM_IMPORTS:
        FROM_IMPORTS[digest] = _from_imports(source(), getattr(module, "__name__", ""),
                                             hasattr(module, "__path__"))
    out, names = [], vars(module)
    for src, name, bound in FROM_IMPORTS[digest]:
        origin = sys.modules.get(src)
        if (origin is None or src.split(".")[0] != top or bound not in names
                or name not in vars(origin)):
            continue
        if not _same_object(names[bound], vars(origin)[name]) and (
                name not in rebound_globals(origin)):  # M's own code rebinds it: not stale
            out.append(f"{getattr(module, '__name__', '?')}.{bound} ({src})")
    return out


def rebound_globals(module: types.ModuleType) -> frozenset[str]:
    """:func:`rebound_at_run_time`'s globals of a loaded module's file (none unreadable)."""
    try:
        with open(module.__file__, "rb") as fh:  # type: ignore[arg-type]
            return rebound_at_run_time(fh.read())[0]
    except (OSError, TypeError, AttributeError):
        return frozenset()


def _from_imports(source: bytes, name: str, is_package: bool) -> tuple[tuple[str, str, str], ...]:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tree = ast.parse(source)
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        return ()
    stores: dict[str, int] = {}
    for node in ast.walk(tree):
        bound = (node.id if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store)
                 else node.name if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                     ast.ClassDef))
                 else (node.asname or node.name).split(".")[0] if isinstance(node, ast.alias)
                 else None)
        if bound is not None:
            stores[bound] = stores.get(bound, 0) + 1
        elif isinstance(node, ast.Global):
            for n in node.names:
                stores[n] = 2
    package = name if is_package else name.rpartition(".")[0]
    out = []
    body = list(tree.body)
    while body:  # module level, in if/try blocks too, not in functions or classes
        stmt = body.pop()
        if isinstance(stmt, (ast.If, ast.Try, ast.With)):
            body += [*stmt.body, *getattr(stmt, "orelse", []), *getattr(stmt, "finalbody", []),
                     *[s for h in getattr(stmt, "handlers", []) for s in h.body]]
        if not isinstance(stmt, ast.ImportFrom):
            continue
        base = stmt.module or ""
        if stmt.level:
            up = package.split(".")
            if stmt.level - 1 >= len(up):
                continue
            base = ".".join(up[:len(up) - (stmt.level - 1)] + ([base] if base else []))
        out += [(base, a.name, a.asname or a.name) for a in stmt.names
                if a.name != "*" and stores.get(a.asname or a.name) == 1]
    return tuple(out)


def _same_object(old: object, new: object, depth: int = 0) -> bool:
    """Whether ``old`` (bound before a reload) computes what ``new`` does, as far as
    :func:`runs_file` compares code: equal plain constants (and tuples, frozensets of them);
    functions of the same code (line numbers aside) and defaults, through decorators that
    keep ``__wrapped__`` and ``functools.partial``; classes whose functions and constants
    are such. Any other value (a list, an array, an instance) is taken for the same: not
    seen, as a module's own such values are not."""
    if old is new:
        return True
    if isinstance(old, type) and isinstance(new, type):
        if old.__qualname__ != new.__qualname__ or depth >= 2:
            return old.__qualname__ == new.__qualname__
        a, b = dict(old.__dict__), dict(new.__dict__)
        return a.keys() == b.keys() and all(_same_object(a[k], b[k], depth + 1) for k in a
                                            if k not in _CLASS_BOOKKEEPING)
    if type(old) is not type(new):
        # another type: a plain one (1 -> 1.0), or one the reload made again (an Enum's)
        return not (type(old) in _IMMUTABLE or type(new) in _IMMUTABLE) and (
            type(old).__qualname__ == type(new).__qualname__)
    if type(old) in (tuple, frozenset):
        return (len(old) == len(new) and all(  # type: ignore[arg-type]
            _same_object(x, y, depth) for x, y in zip(old, new))  # type: ignore[call-overload]
            if type(old) is tuple else _const(old) == _const(new))
    if type(old) in _IMMUTABLE:
        return _const(old) == _const(new)
    if isinstance(old, types.FunctionType):
        return (code_shape(old.__code__) == code_shape(new.__code__)  # type: ignore[attr-defined]
                and _same_object(old.__defaults__, new.__defaults__, depth)  # type: ignore
                and _same_object(old.__kwdefaults__, new.__kwdefaults__, depth)  # type: ignore
                and _same_object(getattr(old, "__wrapped__", None),  # functools.wraps
                                 getattr(new, "__wrapped__", None), depth))
    if isinstance(old, dict) and depth == 0:  # a function's keyword defaults
        return old.keys() == new.keys() and all(  # type: ignore[attr-defined]
            _same_object(v, new[k], 1) for k, v in old.items())  # type: ignore[index]
    if isinstance(old, (staticmethod, classmethod)):
        return _same_object(old.__func__, new.__func__, depth)  # type: ignore[attr-defined]
    if isinstance(old, property):
        return all(_same_object(getattr(old, p), getattr(new, p), depth)
                   for p in ("fget", "fset", "fdel"))
    if isinstance(old, functools.partial):
        return _same_object((old.func, old.args), (new.func, new.args),  # type: ignore
                            depth) and _same_object(old.keywords, new.keywords, 0)  # type: ignore
    try:
        wrapped = getattr(old, "__wrapped__", None), getattr(new, "__wrapped__", None)
    except Exception:  # an object whose attributes raise
        return True
    return True if wrapped[0] is None else _same_object(*wrapped, depth)


#: A class's attributes that say where and how it was made, not what it computes.
_CLASS_BOOKKEEPING = frozenset({
    "__dict__", "__weakref__", "__module__", "__doc__", "__firstlineno__",
    "__static_attributes__", "__annotations__", "__qualname__", "__parameters__",
    "__orig_bases__", "_abc_impl"})


def _same_literals(module: types.ModuleType, tree: ast.Module) -> bool:
    """Whether each name bound once in the file, by an immutable literal at module level or
    in a module-level class's body, has that value in the loaded module."""
    stores: dict[str, int] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            stores[node.id] = stores.get(node.id, 0) + 1
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            stores[node.attr] = 2  # set again by the module's code (``Cls.X = ...``)
        elif isinstance(node, ast.Call) and getattr(node.func, "id", None) == "setattr" and len(
                node.args) > 1 and isinstance(node.args[1], ast.Constant):
            stores[str(node.args[1].value)] = 2
        elif isinstance(node, (ast.Global, ast.Nonlocal)):
            for name in node.names:
                stores[name] = 2  # bound elsewhere too
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            stores[node.name] = stores.get(node.name, 0) + 1
        elif isinstance(node, ast.alias):
            name = (node.asname or node.name).split(".")[0]
            stores[name] = stores.get(name, 0) + 1

    def same(body: list[ast.stmt], where: dict[str, Any]) -> bool:
        for stmt in body:
            target = (stmt.targets[0] if isinstance(stmt, ast.Assign) and len(stmt.targets) == 1
                      else stmt.target if isinstance(stmt, ast.AnnAssign) else None)
            value = getattr(stmt, "value", None)
            if not (isinstance(target, ast.Name) and value is not None
                    and stores.get(target.id) == 1 and target.id in where):
                continue
            try:
                literal = ast.literal_eval(value)
            except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError):
                continue
            if not isinstance(literal, _IMMUTABLE):
                continue
            loaded = where[target.id]
            if type(loaded) not in _IMMUTABLE:  # made another object (an Enum's member)
                continue
            if type(loaded) is not type(literal) or _const(loaded) != _const(literal):
                return False
        return True

    names = vars(module)
    if not same(tree.body, names):
        return False
    for stmt in tree.body:
        cls = names.get(stmt.name) if isinstance(stmt, ast.ClassDef) else None
        if isinstance(cls, type) and stores.get(stmt.name) == 1 and not same(
                stmt.body, dict(cls.__dict__)):
            return False
    return True


__all__ = ["runs_file", "rebound_at_run_time", "stale_imports", "nested_code", "code_shape",
           "module_code", "FROM_IMPORTS"]
