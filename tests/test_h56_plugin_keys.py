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
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from bomgraph import plugins


@pytest.fixture
def site(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    root = tmp_path / "site"
    root.mkdir()
    monkeypatch.syspath_prepend(str(root))
    monkeypatch.setattr(plugins, "RACY_NS", 0)
    plugins.refresh()
    yield root
    plugins.refresh()
    for name in [n for n in sys.modules if n.split(".")[0] in ("h56ln", "h56lo")]:
        del sys.modules[name]


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


@pytest.mark.parametrize("target, edited", [("h56ln.m:M", "shared/h.py"),
                                            ("h56ln.inner.m:M", "inner/m.py")])
def test_an_edit_in_a_linked_folder_of_the_package_moves_the_key(
        site: Path, tmp_path: Path, target: str, edited: str) -> None:
    _write(site / "h56ln" / "__init__.py", "")
    _write(site / "h56ln" / "m.py", "from .shared.h import K\nclass M: pass\n")
    _write(tmp_path / "shared" / "__init__.py", "")
    _write(tmp_path / "shared" / "h.py", "K = 1\n")
    _write(tmp_path / "inner" / "__init__.py", "")
    _write(tmp_path / "inner" / "m.py", "class M: pass\n")
    os.symlink(tmp_path / "shared", site / "h56ln" / "shared")
    os.symlink(tmp_path / "inner", site / "h56ln" / "inner")
    os.symlink(site, site / "h56ln" / "loop")  # a link up the tree is not followed
    before = plugins.disk_fingerprint(target)
    time.sleep(0.05)
    (tmp_path / edited).write_text((tmp_path / edited).read_text() + "K = 2\n")
    assert plugins.disk_fingerprint(target) != before, f"an edit of {edited} re-ran nothing"


def test_a_link_to_nothing_named_py_is_not_read(site: Path) -> None:
    _write(site / "h56lo" / "__init__.py", "")
    # imports by name: its key is the whole package's
    _write(site / "h56lo" / "m.py", "import importlib\nclass M:\n    X = importlib.import_module\n")
    before = plugins.disk_fingerprint("h56lo.m:M")
    time.sleep(0.05)  # past the file system's clock tick: the folder's status moves
    os.symlink("user@host.1234:1700000000", site / "h56lo" / ".#m.py")  # Emacs's lock
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
    out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                          "test_h56_rewritten.py"], cwd=tmp_path, capture_output=True,
                         text=True, env={**os.environ, "PYTHONPATH": str(repo)})
    assert out.returncode == 0, out.stdout[-600:]
