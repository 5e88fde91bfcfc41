"""Review of h119's check of the folders compare writes into (h121).

- A compare of a method that is never cached (a class defined in a notebook cell or
  ``python -c``: no source file to hash) neither reads nor writes ``OUT/cache``, yet an
  unwritable cache refused it: only a cache that would receive a run is refused now.
- A cache that cannot even be listed (another user's, mode 0700) said ``[Errno 13]
  Permission denied: 'OUT/cache/KEY.json'``, by ``--dry-run`` too: now the one line naming
  the folder.
- The refusal of an unwritable cache offers ``--no-cache``, which reads and writes none."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from _depth_mapper import depth_mapper
from _not_writable import not_writable  # tests/_not_writable.py

import bomgraph
from bomgraph import mapper
from bomgraph.bench import Executor
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.report import compare, plan_compare
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream


@pytest.fixture
def stream(tmp_path: Path) -> Path:
    s = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=20), np.random.default_rng(3)), s)
    return s


def test_a_never_cached_method_runs_with_an_unwritable_cache(
        tmp_path: Path, stream: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Fails before: OutputPathError '... the folder OUT/cache is not writable'."""
    mod = types.ModuleType("bomgraph_h121_cell")   # as a notebook's cell: no __file__
    monkeypatch.setitem(sys.modules, mod.__name__, mod)
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    exec(compile(depth_mapper("1.0", "CellMapper"), "<cell>", "exec"), mod.__dict__)
    mapper.register_method("h121-cell", f"{mod.__name__}:CellMapper", "defined in a cell")
    exp = Experiment("cell", "cell", (Arm("h121-cell", "h121-cell"),),
                     sources=(FileSource(str(stream)),))
    out = tmp_path / "out"
    (out / "cache").mkdir(parents=True)
    with not_writable(out / "cache"):
        [plan] = plan_compare([exp], out, executor=Executor("serial"), figures=False)
        assert not plan["cached"]
        result = compare([exp], out, executor=Executor("serial"), figures=False)
    assert [r["ok"] for r in result.results] == [True]
    assert list((out / "cache").iterdir()) == []


def test_a_cache_that_cannot_be_listed_is_one_line_naming_it(tmp_path: Path,
                                                               stream: Path) -> None:
    """Fails before: 'bomgraph: error: [Errno 13] Permission denied: OUT/cache/KEY.json'."""
    out = tmp_path / "out"
    (out / "cache").mkdir(parents=True)
    cmd = [sys.executable, "-c",
           "import sys; from bomgraph.cli import main; sys.exit(main(sys.argv[1:]))",
           "compare", "--streams", str(stream), "--methods", "triangulate", "--jobs", "1",
           "--no-figures", "--out", str(out)]
    if os.geteuid() == 0:   # another user's cache, and no capability overriding modes
        if shutil.which("setpriv") is None:
            pytest.skip("root needs setpriv to run without override capabilities")
        os.chown(out / "cache", 65534, 65534)
        caps = "-dac_override,-dac_read_search,-fowner"
        cmd = ["setpriv", f"--bounding-set={caps}", f"--inh-caps={caps}", *cmd]
    env = {**os.environ, "PYTHONPATH": str(Path(bomgraph.__file__).parent.parent)}
    (out / "cache").chmod(0o700 if os.geteuid() == 0 else 0o000)
    try:
        for dry in ((), ("--dry-run",)):
            proc = subprocess.run([*cmd, *dry], env=env, capture_output=True, text=True)
            assert proc.returncode == 2, proc.stderr
            [line] = proc.stderr.strip().splitlines()
            assert f"the folder {out / 'cache'} is not writable" in line, line
    finally:
        (out / "cache").chmod(0o755)


def test_an_unwritable_cache_says_no_cache_runs(tmp_path: Path, stream: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """The refusal of an unwritable cache offers ``--no-cache`` (which reads and writes no
    cache, so runs); another folder's does not. Fails before (no ``--no-cache`` said)."""
    from bomgraph.cli import main

    out = tmp_path / "out"
    (out / "cache").mkdir(parents=True)
    cmd = ["compare", "--streams", str(stream), "--methods", "triangulate", "--jobs", "1",
           "--no-figures", "--out", str(out)]
    with not_writable(out / "cache"):
        for dry in ((), ("--dry-run",)):
            assert main([*cmd, *dry]) == 2
            [line] = capsys.readouterr().err.strip().splitlines()
            assert line.endswith("or run without the cache (--no-cache)"), line
        assert main([*cmd, "--no-cache"]) == 0
    (out / "estimates").mkdir()
    with not_writable(out / "estimates"):
        assert main([*cmd, "--no-cache", "--estimates"]) == 2
        [line] = capsys.readouterr().err.strip().splitlines()
        assert f"{out / 'estimates'} is not writable" in line and "--no-cache" not in line
