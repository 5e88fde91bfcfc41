"""The modules of a plugin's package that its method's module can run: what its key hashes.

:mod:`bomgraph.plugins` hashes a method's code for its cache key. Hashing its whole top-level
package keyed two methods of one package together: an edit of one method's module re-ran
the other's every run (and, in a notebook, failed them as edited since imported).
:func:`closure` keeps the files of the method's module, of the packages above it (their
``__init__`` runs on import), and of every module of the package that these import, at any
depth, anywhere in the file (in a function too), absolutely or relatively: a helper module
shared by two methods is in both keys. A module that can import by other means (a name in a
string: ``importlib.import_module``, ``__import__``, ``pkgutil``, ``runpy``, ``exec``,
``eval``, a module ``__getattr__``; an unpickled object: ``pickle.load``, ``torch.load``,
``allow_pickle``; bomgraph's registry: ``create_mapper``; :data:`DYNAMIC`) makes the key
the whole package again, as does a package spread over several folders.
"""

from __future__ import annotations

import ast
import warnings
from pathlib import Path
from typing import Iterable, Mapping, Sequence

#: Names (called or read) through which a module can import another that no import
#: statement names: any of them in a module of the closure keys the whole package.
DYNAMIC = frozenset({
    "import_module", "__import__", "iter_modules", "walk_packages", "run_module", "run_path",
    "exec", "eval", "spec_from_file_location", "module_from_spec", "exec_module",
    "load_module", "find_spec", "entry_points", "Unpickler", "create_mapper",
    "method_factory", "register_method", "reload", "extend_path"})

#: Modules whose ``load``/``loads`` unpickle, importing the module of each object's class.
PICKLERS = frozenset({"pickle", "_pickle", "cPickle", "dill", "cloudpickle", "joblib",
                      "torch", "shelve", "marshal", "jsonpickle"})


def _dynamic(node: ast.AST) -> bool:
    """Whether ``node`` may import a module that no import statement names."""
    if isinstance(node, ast.Name):
        return node.id in DYNAMIC or node.id in ("load", "loads")  # from pickle import load
    if isinstance(node, ast.Attribute):
        return node.attr in DYNAMIC or (node.attr in ("load", "loads", "open") and isinstance(
            node.value, ast.Name) and node.value.id in PICKLERS) or (
            node.attr == "modules" and isinstance(node.value, ast.Name)
            and node.value.id == "sys")
    if isinstance(node, ast.keyword):
        return node.arg == "allow_pickle"  # np.load(..., allow_pickle=True)
    return False


#: Per source file: the digest of its contents and what it imports (None: by name too).
PARSED_IMPORTS: dict[Path, tuple[bytes, tuple[str, ...] | None]] = {}


def closure(module: str, files: Sequence[tuple[str, Path]], digests: Mapping[Path, bytes],
            several_roots: bool = False) -> list[tuple[str, Path]]:
    """The files of ``files`` (a top-level package's ``.py`` files, each with its path
    relative to the package folder, and ``digests`` of their contents now, by path) that
    importing ``module`` can run, in their order; all
    of them when a module among those can import by name (:data:`DYNAMIC`), when
    ``module`` is not among them, or when the package has ``several_roots``."""
    top = module.split(".")[0]
    by_name = {name: (rel, path) for rel, path in files
               if (name := _module_name(top, rel)) is not None}
    if several_roots or module not in by_name:
        return list(files)
    todo, kept = [module], set()
    while todo:
        name = todo.pop()
        for up in _with_parents(name):
            if up in kept or up not in by_name:
                continue
            kept.add(up)
            rel, path = by_name[up]
            imported = _imports(path, up, rel.endswith("__init__.py"), digests.get(path))
            if imported is None:
                return list(files)
            for m in imported:
                if m.endswith(".*"):  # every module of that package: __all__ is strings
                    todo += [n for n in by_name if n.rpartition(".")[0] == m[:-2]]
                elif m == top or m.startswith(top + "."):
                    todo.append(m)
    keep = {by_name[m][1] for m in kept}
    return [(rel, path) for rel, path in files if path in keep]


def _module_name(top: str, rel: str) -> str | None:
    parts = rel[:-3].split("/")
    if parts[-1] == "__init__":
        parts = parts[:-1]
    if not all(p.isidentifier() for p in parts):
        return None  # no import statement can name it
    return ".".join([top, *parts])


def _with_parents(name: str) -> Iterable[str]:
    parts = name.split(".")
    return (".".join(parts[:k]) for k in range(1, len(parts) + 1))


def _imports(path: Path, name: str, is_package: bool,
             digest: bytes | None) -> tuple[str, ...] | None:
    """The absolute names of the modules (and of names that may be submodules) that the
    module ``name`` at ``path`` (whose contents have ``digest``) imports; None when it can
    import by name or cannot be read or parsed (it is then keyed with the whole package)."""
    seen = PARSED_IMPORTS.get(path)
    if digest is not None and seen is not None and seen[0] == digest:
        return seen[1]
    try:
        with warnings.catch_warnings():  # the module's import says them (SyntaxWarning)
            warnings.simplefilter("ignore")
            tree = ast.parse(path.read_bytes(), str(path))
    except (OSError, SyntaxError, ValueError, RecursionError, MemoryError):
        return None
    package = name if is_package else name.rpartition(".")[0]
    out: list[str] | None = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if any(a.name in DYNAMIC or (a.name in ("load", "loads") and (
                    node.module or "").split(".")[0] in PICKLERS) for a in node.names):
                out = None  # under another name (from importlib import import_module as im)
                break
            base = node.module or ""
            if node.level:
                up = package.split(".")
                if node.level - 1 >= len(up):
                    continue  # beyond the top-level package: not its code
                base = ".".join(up[:len(up) - (node.level - 1)] + ([base] if base else []))
            # a star import also imports the submodules its package's __all__ names
            out += [base] + [f"{base}.{a.name}" for a in node.names]
        elif _dynamic(node):
            out = None
            break
    if any(isinstance(s, (ast.FunctionDef, ast.AsyncFunctionDef)) and s.name == "__getattr__"
           for s in tree.body):  # a module's lazy attributes (PEP 562): imports by name
        out = None
    found = None if out is None else tuple(dict.fromkeys(out))
    if digest is not None:  # read after the digest: a later edit changes the digest
        PARSED_IMPORTS[path] = (digest, found)
    return found


__all__ = ["closure", "DYNAMIC", "PARSED_IMPORTS"]
