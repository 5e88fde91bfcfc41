"""Faults helper h148 found reviewing h146's change: each test failed before its fix."""

from __future__ import annotations

import glob
from pathlib import Path

import pytest
from hostile_helpers import HEADER, bomgraph, odd_steps, one_error, write_jsonl

from bomgraph.stream_globs import GlobTooWideError, bounded_glob


def test_the_star_levels_before_a_double_star_are_bounded(tmp_path: Path) -> None:
    """h146 bounded the ``*`` levels of a glob without ``**`` only: ``loop/*/.../*/x/**``
    through a folder holding two links to itself still expanded ``loop/*/.../*/x`` first,
    2^k paths for k levels (16 levels: 3.5 s; 40: without end), before ``**`` was counted."""
    (tmp_path / "loop").mkdir()
    for name in ("a", "b"):
        (tmp_path / "loop" / name).symlink_to(".")
    pattern = f"{tmp_path}/loop/" + "*/" * 4 + "x/**/*.jsonl"   # 1 + 2 + 4 + 8 searched
    assert bounded_glob(pattern, limit=15) == []
    with pytest.raises(GlobTooWideError, match="more than 14 folders below"):
        bounded_glob(pattern, limit=14)
    with pytest.raises(GlobTooWideError, match="more than 10,000 folders below"):
        bounded_glob(f"{tmp_path}/loop/" + "*/" * 40 + "x/**/*.jsonl")


def test_a_double_star_glob_is_glob_below_its_bound(tmp_path: Path) -> None:
    for rel in ("r1/a/x.jsonl", "r1/b/c/y.jsonl", "r2/.h/z.jsonl", "r2/d/w.jsonl", "s/v.jsonl"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text("")
    for pattern in (f"{tmp_path}/r*/*/**/*.jsonl", f"{tmp_path}/[rs]?/**/*.jsonl",
                    f"{tmp_path}/*/**/*.jsonl"):
        assert bounded_glob(pattern) == sorted(glob.glob(pattern, recursive=True)) != []


def test_an_ekf_step_turning_too_far_for_its_sub_steps_is_refused(tmp_path: Path) -> None:
    """With ``max_predict_turn_rad`` a step turning 1e12 rad (the reader warns and accepts
    it) was predicted in 2e12 sub-steps, without end; now it is refused at its line."""
    stream = write_jsonl(tmp_path / "odd.jsonl", HEADER, odd_steps(odom=[0.1, 0.0, 1e12]))
    proc = bomgraph("run", stream, "--method", "ekf", "--option", "max_predict_turn_rad=0.5",
                    "--out", tmp_path / "e.json", timeout=120)
    one_error(proc, f"{stream}, line 6: 'odom': step 4: ekf cannot use",
              "more than 10,000 predicts of max_predict_turn_rad = 0.5 rad each")
    assert not (tmp_path / "e.json").exists()
