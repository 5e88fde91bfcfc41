"""The layout of the house (issue 12): one job per file, data flowing one way.

Read from the source with ``ast``, counting imports inside functions too: no import cycle
among the modules of ``bomgraph`` and ``baselines``, ``bomgraph`` never imports ``baselines``,
``plots`` imports no other bomgraph module, no file is over 600 lines, and no module (nor a
script) imports another module's private (underscore) name.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("bomgraph", "baselines")
MAX_LINES = 600


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for f in sorted((ROOT / pkg).rglob("*.py")):
            parts = list(f.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = f
    return out


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    """Every project module ``name`` imports, at the top or inside functions."""
    is_pkg = path.name == "__init__.py"
    base = name.split(".") if is_pkg else name.split(".")[:-1]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            mod = node.module or ""
            if node.level:
                anchor = base[:len(base) - node.level + 1]
                mod = ".".join(anchor + ([mod] if mod else []))
            targets = [mod] + [f"{mod}.{a.name}" for a in node.names]
        for t in targets:
            while t and t not in known:
                t = t.rpartition(".")[0]
            if t and t != name:
                found.add(t)
    return found


def _graph() -> dict[str, set[str]]:
    mods = _modules()
    return {m: _imports(m, p, set(mods)) for m, p in mods.items()}


def test_no_file_is_over_600_lines() -> None:
    long = {m: len(p.read_text().splitlines()) for m, p in _modules().items()}
    assert {m: n for m, n in long.items() if n > MAX_LINES} == {}


def test_bomgraph_never_imports_baselines() -> None:
    bad = {m: sorted(d for d in deps if d.startswith("baselines"))
           for m, deps in _graph().items() if m.startswith("bomgraph")}
    assert {m: d for m, d in bad.items() if d} == {}


def test_plots_import_no_other_bomgraph_module() -> None:
    assert _graph()["bomgraph.plots"] == set()


def test_no_import_cycle() -> None:
    graph = _graph()
    # a package's __init__ re-exporting its modules is its face, not an arrow back up
    edges = {m: {d for d in deps if not m.startswith(d + ".")} for m, deps in graph.items()}
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> list[str] | None:
        state[m] = 1
        stack.append(m)
        for d in sorted(edges[m]):
            if state.get(d) == 1:
                return stack[stack.index(d):] + [d]
            if d not in state:
                cycle = visit(d)
                if cycle:
                    return cycle
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(edges):
        if m not in state:
            cycle = visit(m)
            assert cycle is None, " -> ".join(cycle)


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _private_imports(name: str, path: Path, known: set[str]) -> list[str]:
    """The underscore names of other project modules that ``path`` imports (``from M import
    _x``) or reads off an imported module (``M._x``), and the private modules (``_text``) it
    imports from outside their own package: each as ``"file:line: M._x"``."""
    is_pkg = path.name == "__init__.py"
    base = name.split(".") if is_pkg else name.split(".")[:-1]
    tree = ast.parse(path.read_text(), str(path))
    where = f"{path.relative_to(ROOT)}"
    found: list[str] = []
    bound: dict[str, str] = {}  # local name -> the project module it is

    def outside(mod: str) -> bool:  # a private module seen from outside its package
        parts = mod.split(".")
        return any(_private(p) and name.split(".")[:i] != parts[:i]
                   for i, p in enumerate(parts))

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            bound.update({a.asname or a.name: a.name for a in node.names if a.name in known})
        elif isinstance(node, ast.ImportFrom):
            mod = node.module or ""
            if node.level:
                anchor = base[:len(base) - node.level + 1]
                mod = ".".join(anchor + ([mod] if mod else []))
            for a in node.names:
                full = f"{mod}.{a.name}"
                if full in known:
                    bound[a.asname or a.name] = full
                if (full in known and outside(full)) or (mod in known and mod != name and (
                        _private(a.name) and full not in known or outside(mod))):
                    found.append(f"{where}:{node.lineno}: {full}")
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and _private(node.attr):
            chain, head = [node.attr], node.value
            while isinstance(head, ast.Attribute):
                chain.append(head.attr)
                head = head.value
            if isinstance(head, ast.Name) and head.id in bound:
                mod = ".".join([bound[head.id], *chain[:0:-1]])
                if mod in known and mod != name:
                    found.append(f"{where}:{node.lineno}: {mod}.{node.attr}")
    return found


def test_no_module_imports_another_modules_private_name() -> None:
    """A name used across modules is public in its home module (in its ``__all__``); tests
    may reach into privates, scripts and the packages may not."""
    mods = _modules()
    files = {**mods, **{f"scripts.{f.stem}": f for f in sorted((ROOT / "scripts").glob("*.py"))}}
    bad = [hit for m, p in files.items() for hit in _private_imports(m, p, set(mods))]
    assert not bad, "\n".join(bad)


def test_no_recorded_data_is_committed() -> None:
    """Streams, estimates and dataset files stay out of the repository (the brief: data are
    read from ``../shared/data``, never copied in); only ``tests/data`` holds a reference."""
    import subprocess

    tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True,
                             check=True).stdout.split()
    data_like = (".jsonl", ".g2o", ".dat", ".dat.gz", ".jsonl.gz", ".txt.gz", ".mat")
    bad = [f for f in tracked if f.endswith(data_like) and not f.startswith("tests/data/")]
    assert not bad, f"data files committed: {bad}"
    assert not [f for f in tracked if "/" not in f and f.endswith(".json")], tracked
