"""The code of a plugin as the runner keys and checks it (h53).

- A worker checks a plugin's package before and after each run; each check listed and read
  every file of it: 20 ms a check on a package of 300 files (800 runs: 33 s of CPU). A file
  is now read again only when its status changed, a folder listed again only when its
  status changed; an edit is still seen at the next check, however it is made.
- A module the user imported before bomgraph first loaded it (a notebook: ``import mymethod``,
  then a sweep), edited in between: its file was taken for the code that runs, so the old
  code's result was cached under the edited file's key, and served to that code later. Its
  code is now compared with the file's: a serial run fails saying to reload, caching nothing.
- Two methods of one package were keyed with the whole package: an edit of one's module
  re-ran the other's every run, and in a notebook failed the other's runs as edited. A key
  now holds the modules of the package that the method's module imports (a shared helper:
  both keys), the whole package when one of those imports by name.
"""

from __future__ import annotations

import importlib
import os
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from _depth_mapper import depth_mapper

from bomgraph import file_digest, mapper, plugins
from bomgraph.bench import Executor, execute
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream


@pytest.fixture
def package(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A plugin package of a few modules in two folders, importable, its files' status
    trusted at once (``file_digest.RACY_NS`` 0: the tests sleep past the file system's clock
    tick)."""
    pkg = tmp_path / "site" / "h53pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    for i in range(5):
        (pkg / f"m{i}.py").write_text(f"X = {i}\n")
        (pkg / "sub" / f"s{i}.py").write_text(f"Y = {i}\n")
    # the method's module, parsed (never run): the modules below are in its key
    (pkg / "m0.py").write_text("from .sub import s0, s1, s2, s3, s4, s9, new\n"
                               "from .sub.deeper import d\nX = 0\n")
    monkeypatch.syspath_prepend(str(pkg.parent))
    monkeypatch.setattr(file_digest, "RACY_NS", 0)
    plugins.refresh()
    yield pkg
    plugins.refresh()
    for name in [n for n in sys.modules if n == "h53pkg" or n.startswith("h53pkg.")]:
        del sys.modules[name]


def _fp() -> str | None:
    return plugins.disk_fingerprint("h53pkg.m0:X")


def test_an_unchanged_package_is_not_read_again(package: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    first = _fp()
    reads: list[Path] = []
    read_bytes = Path.read_bytes

    def counted(self: Path) -> bytes:
        reads.append(self)
        return read_bytes(self)

    monkeypatch.setattr(Path, "read_bytes", counted)
    assert _fp() == first and reads == [], f"{len(reads)} files read again"


def _later() -> None:
    time.sleep(0.05)  # past the file system's timestamp tick (a jiffy)


@pytest.mark.parametrize("edit", ["same size, mtime put back", "file added", "file removed",
                                  "folder added", "file renamed"])
def test_every_edit_is_seen_at_the_next_check(package: Path, edit: str) -> None:
    first = _fp()
    _later()
    target = package / "sub" / "s3.py"
    if edit == "same size, mtime put back":
        st = target.stat()
        target.write_text("Y = 9\n")
        os.utime(target, ns=(st.st_atime_ns, st.st_mtime_ns))
        assert target.stat().st_size == st.st_size and target.stat().st_mtime_ns == st.st_mtime_ns
    elif edit == "file added":
        (package / "sub" / "new.py").write_text("Z = 1\n")
    elif edit == "file removed":
        target.unlink()
    elif edit == "folder added":
        (package / "sub" / "deeper").mkdir()
        (package / "sub" / "deeper" / "d.py").write_text("Z = 1\n")
    else:
        target.rename(package / "sub" / "s9.py")
    assert _fp() != first, edit


METHOD = depth_mapper("DEPTH_M", "Mine") + "\nDEPTH_M = 1.0\n"


@pytest.fixture
def imported_first(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """A method module the user imported before bomgraph loaded it, registered at run time,
    and a one-run sweep of it with a cache."""
    src = tmp_path / "code" / f"h53mine_{tmp_path.name}.py"
    src.parent.mkdir()
    src.write_text(METHOD)
    monkeypatch.syspath_prepend(str(src.parent))
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    importlib.import_module(src.stem)  # the notebook's first cell
    mapper.register_method("mine", f"{src.stem}:Mine")
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=40), np.random.default_rng(3)), stream)
    exp = Experiment("e", "e", (Arm("mine", "mine"),), sources=(FileSource(str(stream)),))
    yield src, exp, tmp_path / "cache"
    sys.modules.pop(src.stem, None)


@pytest.mark.parametrize("edit", [("DEPTH_M = 1.0", "DEPTH_M = 3.0"),
                                  ("+ DEPTH_M *", "+ 3.0 * DEPTH_M *")])
def test_an_edit_before_the_first_load_is_not_taken_for_the_code_that_runs(
        imported_first: tuple[Path, Experiment, Path], edit: tuple[str, str]) -> None:
    src, exp, cache = imported_first
    assert edit[0] in METHOD
    src.write_text(METHOD.replace(*edit))  # edited, not reloaded; then the sweep
    (res,) = execute(exp.tasks(), Executor("serial"), cache_dir=cache)
    assert not res["ok"], "the old code's result was taken for the edited file's"
    assert "was edited since this process imported it" in res["error"], res["error"]
    assert list(cache.glob("*.json")) == []


def test_an_unedited_or_only_moved_module_imported_first_runs_and_is_cached(
        imported_first: tuple[Path, Experiment, Path]) -> None:
    src, exp, cache = imported_first
    src.write_text("# a comment and a blank line move every line down\n\n" + METHOD)
    (res,) = execute(exp.tasks(), Executor("serial"), cache_dir=cache)
    assert res["ok"], res.get("error")
    assert len(list(cache.glob("*.json"))) == 1


def test_a_constant_set_in_memory_is_not_keyed_as_the_files(
        imported_first: tuple[Path, Experiment, Path]) -> None:
    """``mymethod.DEPTH_M = 3.0`` in a notebook between two sweeps, the file unchanged: the
    module looked reloaded, its file (1.0) was keyed again, and the second sweep returned
    the first's cached result of 1.0 for code that runs 3.0."""
    src, exp, cache = imported_first
    (first,) = execute(exp.tasks(), Executor("serial"), cache_dir=cache)
    sys.modules[src.stem].DEPTH_M = 3.0
    (second,) = execute(exp.tasks(), Executor("serial"), cache_dir=cache)
    assert first["ok"] and not second["ok"], "the 1.0 code's cached result was returned"
    assert "set in memory" in second["error"], second["error"]


PAIR = {"__init__.py": "",
        "helpers.py": "SCALE = 1.0\n",
        "a.py": depth_mapper("DEPTH_M * SCALE", "AMapper") + "\nfrom .helpers import SCALE\n"
                "DEPTH_M = 1.0\n",
        "b.py": depth_mapper("DEPTH_M * helpers.SCALE", "BMapper") + "\nfrom . import helpers\n"
                "DEPTH_M = 2.0\n",
        "c.py": "from importlib import import_module as im\nLATER = im('h53pair.d')\n",
        "d.py": "X = 1\n",
        "e.py": "from .pkg import *\nX = 1\n",  # imports pkg/f.py through pkg's __all__
        "pkg/__init__.py": "__all__ = ['f']\n",
        "pkg/f.py": "Y = 1\n"}


@pytest.fixture
def pair(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """A package of two methods sharing a helper module, registered at run time."""
    pkg = tmp_path / "site" / "h53pair"
    pkg.mkdir(parents=True)
    (pkg / "pkg").mkdir()
    for name, text in PAIR.items():
        (pkg / name).write_text(text)
    monkeypatch.syspath_prepend(str(pkg.parent))
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    mapper.register_method("meth-a", "h53pair.a:AMapper")
    mapper.register_method("meth-b", "h53pair.b:BMapper")
    mapper.register_method("meth-c", "h53pair.c:LATER")
    mapper.register_method("meth-e", "h53pair.e:X")
    plugins.refresh()
    yield pkg
    for name in [n for n in sys.modules if n == "h53pair" or n.startswith("h53pair.")]:
        del sys.modules[name]
    plugins.refresh()


def _keys() -> dict[str, str]:
    from bomgraph.method_code import method_fingerprint

    return {m: method_fingerprint(m, disk=True) for m in ("meth-a", "meth-b", "meth-c",
                                                          "meth-e")}


# meth-c imports by name (importlib's, renamed): its key is the whole package's, moved by any
# edit
@pytest.mark.parametrize("edited, moved", [("a.py", {"meth-a"}), ("b.py", {"meth-b"}),
                                           ("helpers.py", {"meth-a", "meth-b"}),
                                           ("d.py", set()), ("new.py", set()),
                                           ("pkg/f.py", {"meth-e"})])
def test_a_methods_key_holds_the_modules_it_imports(pair: Path, edited: str,
                                                    moved: set) -> None:
    moved = moved | {"meth-c"}
    before = _keys()
    _later()
    path = pair / edited
    path.write_text((path.read_text() if path.exists() else "") + "# edited\n")
    after = _keys()
    assert {m for m in before if before[m] != after[m]} == moved, edited


def test_an_edit_of_one_method_does_not_fail_the_others_runs_in_a_notebook(
        pair: Path, tmp_path: Path) -> None:
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=40), np.random.default_rng(3)), stream)
    exp = Experiment("e", "e", (Arm("meth-a", "meth-a"), Arm("meth-b", "meth-b")),
                     sources=(FileSource(str(stream)),))
    first = execute(exp.tasks(), Executor("serial"))
    (pair / "a.py").write_text(PAIR["a.py"].replace("DEPTH_M = 1.0", "DEPTH_M = 3.0"))
    a, b = execute(exp.tasks(), Executor("serial"))  # a.py edited, not reloaded
    assert all(r["ok"] for r in first)
    assert not a["ok"] and "edited since" in a["error"]
    assert b["ok"], b.get("error")
    assert b["key"] == first[1]["key"]


def test_keying_a_module_with_an_invalid_escape_prints_no_warning(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Keying parses the method's modules (the imports they name, :mod:`import_closure`) and
    compiles one loaded before (:mod:`loaded_code`): a ``"\\d"`` in a string made each print
    its SyntaxWarning (3.12+; DeprecationWarning in 3.11), which the module's import had
    said once already. Fails before."""
    import warnings

    pkg = tmp_path / "site" / "h53esc"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "m.py").write_text('import re\nPAT = re.compile("\\d+")\nX = 1\n')
    assert '("\\d+")' in (pkg / "m.py").read_text()
    monkeypatch.syspath_prepend(str(pkg.parent))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        importlib.import_module("h53esc.m")  # the user's import, before bomgraph's first hash
    try:
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            plugins.disk_fingerprint("h53esc.m:X")
            plugins.source_fingerprint("h53esc.m:X")
    finally:
        for name in ("h53esc.m", "h53esc"):
            sys.modules.pop(name, None)
        plugins.refresh()
    assert [str(w.message) for w in said] == []
