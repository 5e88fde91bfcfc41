"""``scripts/bench_stmds_paired.py`` whole-run mode against a copy of this checkout's package:
the old copy runs on its own Step type, and the two give the same maps bit for bit."""

from __future__ import annotations

import shutil
from pathlib import Path

from _scripts import ROOT, load_script


def test_paired_runs_against_a_copy_of_this_checkout(tmp_path: Path, capsys) -> None:
    shutil.copytree(ROOT / "bomgraph", tmp_path / "bomgraph_pairtest")
    mod = load_script("bench_stmds_paired")
    assert mod.main(["--old", str(tmp_path / "bomgraph_pairtest"), "--runs", "1",
                     "--presets", "paper"]) == 0
    out = capsys.readouterr().out
    assert "paper" in out and "final maps bit for bit: True" in out
