"""A plugin's key and loaded-code check in cases h53's review (h56) found wrong.

- A package with a linked folder (``mypkg/shared -> ../shared``, a helper folder linked into
  two plugins): the listing followed no link to a folder, so the linked modules were in no
  key: an edit of them, or of a method module inside one, re-ran nothing (a stale cached
  result).
- A method defined in a pytest test module (or a module pytest rewrites the asserts of):
  its loaded code is the rewritten one, never the file's compiled plainly, so every serial
  run with a cache failed as "edited since this process imported it" on unedited code.
- An editor's lock file (Emacs: ``.#bench.py``, a link to nothing) in bomgraph's or a
  plugin's folder: ``code_fingerprint`` read it and every sweep failed with
  ``No such file or directory``.
- A module whose own code rebinds a global (``global _MODEL``: a lazy cache) looked
  reloaded at the next sweep: an edit made and not reloaded was keyed as the code that runs.
"""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from _depth_mapper import depth_mapper
from _plugin_site import write

from bomgraph import file_digest, mapper, plugins, source_files
from bomgraph.bench import Executor, execute
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream


@pytest.mark.parametrize("target, edited", [("h56ln.m:M", "shared/h.py"),
                                            ("h56ln.inner.m:M", "inner/m.py")])
def test_an_edit_in_a_linked_folder_of_the_package_moves_the_key(
        plugin_site: Path, tmp_path: Path, target: str, edited: str) -> None:
    write(plugin_site / "h56ln" / "__init__.py", "")
    write(plugin_site / "h56ln" / "m.py", "from .shared.h import K\nclass M: pass\n")
    write(tmp_path / "shared" / "__init__.py", "")
    write(tmp_path / "shared" / "h.py", "K = 1\n")
    write(tmp_path / "inner" / "__init__.py", "")
    write(tmp_path / "inner" / "m.py", "class M: pass\n")
    os.symlink(tmp_path / "shared", plugin_site / "h56ln" / "shared")
    os.symlink(tmp_path / "inner", plugin_site / "h56ln" / "inner")
    os.symlink(plugin_site, plugin_site / "h56ln" / "loop")  # a link up is not followed
    write(tmp_path / "data" / "deep" / "x.csv", "1\n")  # nor one to a data folder
    os.symlink(tmp_path / "data", plugin_site / "h56ln" / "data")
    before = plugins.disk_fingerprint(target)
    time.sleep(0.05)
    (tmp_path / edited).write_text((tmp_path / edited).read_text() + "K = 2\n")
    assert plugins.disk_fingerprint(target) != before, f"an edit of {edited} re-ran nothing"
    listed = {Path(d).name for d, _ in source_files._LISTED[str(plugin_site / "h56ln")][0]}
    # the data folder's status is watched (h57: code written into it is listed), but it is
    # not walked: its subfolder is not listed
    assert listed == {"h56ln", "shared", "inner", "data"}, listed


def test_a_link_to_nothing_named_py_is_not_read(plugin_site: Path) -> None:
    write(plugin_site / "h56lo" / "__init__.py", "")
    # imports by name: its key is the whole package's
    write(plugin_site / "h56lo" / "m.py",
          "import importlib\nclass M:\n    X = importlib.import_module\n")
    before = plugins.disk_fingerprint("h56lo.m:M")
    time.sleep(0.05)  # past the file system's clock tick: the folder's status moves
    os.symlink("user@host.1234:1700000000", plugin_site / "h56lo" / ".#m.py")  # Emacs's lock
    assert plugins.disk_fingerprint("h56lo.m:M") == before


def test_bomgraphs_key_reads_no_link_to_nothing(tmp_path: Path) -> None:
    """In a copy of the sources (bomgraph's own folder is never touched)."""
    repo = Path(__file__).resolve().parents[1]
    for pkg in ("bomgraph", "baselines"):
        subprocess.run(["cp", "-r", str(repo / pkg), str(tmp_path / pkg)], check=True)
    os.symlink("user@host.1234:1700000000", tmp_path / "baselines" / ".#triangulate.py")
    out = subprocess.run([sys.executable, "-c", "from bomgraph import plugins as p\n"
                          "print(p.code_fingerprint(), p.code_changed())"],
                         cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(tmp_path)},
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-300:]
    assert out.stdout.split()[1] == "False"


METHOD = textwrap.dedent('''
    import numpy as np
    from bomgraph import mapper
    from bomgraph.bench import Executor, execute
    from bomgraph.experiments import Arm, Experiment, FileSource
    from bomgraph.mapper import MapEstimate
    from bomgraph.sim import SimConfig, simulate
    from bomgraph.stream_file import write_stream

    class AssertMapper:
        def __init__(self, header, **options):
            self.seen = {}
        def step(self, step):
            assert step is not None, "a step"
            for lid, b in zip(step.landmark_ids.tolist(), step.bearings_rad.tolist()):
                self.seen.setdefault(lid, np.array([np.cos(b), np.sin(b)]))
        def estimate(self):
            ids = np.array(sorted(self.seen), dtype=np.int64)
            return MapEstimate(ids, np.array([self.seen[i] for i in ids.tolist()]).reshape(-1, 2))

    def test_cached(tmp_path):
        stream = tmp_path / "s.jsonl"
        write_stream(simulate(SimConfig(n_steps=20), np.random.default_rng(3)), stream)
        mapper.register_method("h56-rw", f"{__name__}:AssertMapper")
        exp = Experiment("e", "e", (Arm("h56-rw", "h56-rw"),), sources=(FileSource(str(stream)),))
        for _ in range(2):
            (r,) = execute(exp.tasks(), Executor("serial"), cache_dir=tmp_path / "c")
            assert r["ok"], r.get("error")
        assert len(list((tmp_path / "c").glob("*.json"))) == 1
''')


def test_a_method_in_a_module_pytest_rewrote_runs_and_is_cached(tmp_path: Path) -> None:
    (tmp_path / "test_h56_rewritten.py").write_text(METHOD)
    repo = Path(__file__).resolve().parents[1]
    # its temporary folders in this test's (not a new pytest-N beside this session's), and
    # none of this session's PYTEST_ADDOPTS
    env = {k: v for k, v in os.environ.items() if k != "PYTEST_ADDOPTS"}
    out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                          "--basetemp", str(tmp_path / "basetemp"), "test_h56_rewritten.py"],
                         cwd=tmp_path, capture_output=True, text=True,
                         env={**env, "PYTHONPATH": str(repo)})
    assert out.returncode == 0, out.stdout[-600:]


LAZY = depth_mapper("DEPTH_M", "Mine", attrs="pass").replace(
    "self.pose, self.seen = np.zeros(3), {}",
    "self.pose, self.seen = np.zeros(3), {}\n"
    "        global _CALLS\n        _CALLS = (_CALLS or 0) + 1"
) + "\n_CALLS = None\nDEPTH_M = float(np.float64(1.0))\n"
# the same, counting in a class attribute (a tuple: rebound, not changed in place)
COUNTED = depth_mapper("DEPTH_M", "Mine", attrs="RUNS = ()").replace(
    "self.pose, self.seen = np.zeros(3), {}",
    "self.pose, self.seen = np.zeros(3), {}\n        Mine.RUNS += (object(),)"
) + "\nDEPTH_M = float(np.float64(1.0))\n"


@pytest.mark.parametrize("text", [LAZY, COUNTED], ids=["global", "class attribute"])
def test_an_edit_not_reloaded_of_a_module_with_a_lazy_global_is_not_keyed_as_run(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, text: str) -> None:
    """A module whose code rebinds a global (a lazy cache, a counter), edited and not
    reloaded between two sweeps where the loaded-code comparison cannot see it (a value not
    a literal): the rebinding looked like a reload, the edited file was keyed, and the old
    code's result (MPE 0.22 m) was cached under it, served to a fresh process that runs the
    edit (2.13 m). Fails before this commit; a reload still runs the edit."""
    src = tmp_path / "code" / f"h56lazy_{tmp_path.name}.py"
    write(src, text)
    monkeypatch.syspath_prepend(str(src.parent))
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    mapper.register_method("mine", f"{src.stem}:Mine")
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=40), np.random.default_rng(3)), stream)
    exp = Experiment("e", "e", (Arm("mine", "mine"),), sources=(FileSource(str(stream)),))
    cache = tmp_path / "cache"
    try:
        (first,) = execute(exp.tasks(), Executor("serial"), cache_dir=cache)
        time.sleep(0.05)
        src.write_text(text.replace("np.float64(1.0)", "np.float64(3.0)"))
        (second,) = execute(exp.tasks(), Executor("serial"), cache_dir=cache)
        assert first["ok"] and not second["ok"], "the old code's result was keyed as the edit's"
        assert "edited since" in second["error"], second["error"]
        importlib.reload(sys.modules[src.stem])
        (third,) = execute(exp.tasks(), Executor("serial"), cache_dir=cache)
        (fresh,) = execute(exp.tasks(), Executor("serial"))
    finally:
        sys.modules.pop(src.stem, None)
        plugins.refresh()
    assert third["ok"] and third["key"] != first["key"]
    assert third["checkpoints"][-1]["mpe_m"] == fresh["checkpoints"][-1]["mpe_m"]
    assert third["checkpoints"][-1]["mpe_m"] != first["checkpoints"][-1]["mpe_m"]


HELPERS = """
import dataclasses, enum, functools

SCALE = 1.0
TABLE = {"a": [1, 2]}
ALL = frozenset({"a", "b"})

class Kind(enum.IntFlag):
    A = 1

@dataclasses.dataclass(frozen=True)
class Cfg:
    a: float = 1.0

@functools.lru_cache(maxsize=None)
def cached(x):
    return x

PARTIAL = functools.partial(cached, 2)
"""


@pytest.mark.parametrize("edit, stale", [
    ("SCALE = 3.0\n", True), ("def cached(x):\n    return x", True),
    ("SCALE = 1.0\n# a comment\n", False), ("SCALE = 1.0\ndef unused():\n    return 2\n", False)])
def test_a_name_imported_from_a_module_reloaded_alone_is_not_keyed_as_its_new_code(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, edit: str, stale: bool) -> None:
    """``from .helpers import SCALE`` in the method's module, helpers.py edited and reloaded
    (importlib.reload), the method's module not: it still runs the old SCALE, but was keyed
    with helpers' new file, so the old result (MPE 0.22 m) was cached under the key of the
    edit (2.13 m in a fresh process). Now its serial run fails saying to reload it too; a
    reload that changes no imported name runs. Fails before this commit."""
    pkg = tmp_path / "site" / "h56fi"
    write(pkg / "__init__.py", "")
    write(pkg / "helpers.py", HELPERS)
    write(pkg / "a.py", depth_mapper("DEPTH_M * SCALE", "Mine")
           + "\nfrom .helpers import SCALE, TABLE, ALL, Kind, Cfg, cached, PARTIAL\n"
           "DEPTH_M = 1.0\n")
    monkeypatch.syspath_prepend(str(pkg.parent))
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    mapper.register_method("mine", "h56fi.a:Mine")
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=40), np.random.default_rng(3)), stream)
    exp = Experiment("e", "e", (Arm("mine", "mine"),), sources=(FileSource(str(stream)),))
    try:
        (first,) = execute(exp.tasks(), Executor("serial"), cache_dir=tmp_path / "cache")
        time.sleep(0.05)
        edited = {"def cached(x):\n    return x": HELPERS.replace("return x", "return -x")}
        (pkg / "helpers.py").write_text(edited.get(edit, HELPERS.replace("SCALE = 1.0\n", edit)))
        importlib.reload(sys.modules["h56fi.helpers"])
        (second,) = execute(exp.tasks(), Executor("serial"), cache_dir=tmp_path / "cache")
    finally:
        for name in [n for n in sys.modules if n.split(".")[0] == "h56fi"]:
            del sys.modules[name]
        plugins.refresh()
    assert first["ok"] and second["ok"] is not stale, second.get("error")
    if stale:
        assert "reloaded since: reload it too" in second["error"], second["error"]


def test_an_edit_within_the_clocks_tick_of_the_last_read_is_seen(
        plugin_site: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A file system whose timestamps are coarse (a second: ext3, HFS+; two: FAT) keeps
    size, mtime and ctime through an edit made in the same tick: the status is trusted only
    once older than RACY_NS. No test checked it (h53's set RACY_NS to 0; making ``_aged``
    always true failed none)."""
    monkeypatch.setattr(file_digest, "RACY_NS", 2_000_000_000)
    write(plugin_site / "h56lo" / "__init__.py", "")
    write(plugin_site / "h56lo" / "m.py", "K = 1\nclass M: pass\n")
    now = time.time_ns()
    sig = file_digest._status((plugin_site / "h56lo" / "m.py").stat())
    same_tick = (*sig[:3], now, now)
    monkeypatch.setattr(file_digest, "_status", lambda st: same_tick)
    before = plugins.disk_fingerprint("h56lo.m:M")
    (plugin_site / "h56lo" / "m.py").write_text("K = 2\nclass M: pass\n")  # same size, tick
    assert plugins.disk_fingerprint("h56lo.m:M") != before
