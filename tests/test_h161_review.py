"""Small faults batched in h161: counts printed with their noun in the singular for one
("1 run", not "1 runs" or "1 run(s)"), method refusals that name the method run, and the
bounds of a few refusals."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bomgraph.cli import main


@pytest.fixture()
def one_stream(tmp_path: Path) -> Path:
    s = tmp_path / "s.jsonl"
    assert main(["simulate", "--seed", "1", "--steps", "20", "--out", str(s), "-q"]) == 0
    return s


def test_one_run_is_counted_in_the_singular(tmp_path: Path, one_stream: Path,
                                             capsys: pytest.CaptureFixture) -> None:
    """``compare --dry-run`` of one run printed "1 runs" twice; its sweep's title (figures,
    results.json) said "1 stream(s), 1 method(s)" and the error-vs-time figure "(1 runs)"."""
    out = tmp_path / "c"
    args = ["compare", "--streams", str(one_stream), "--methods", "triangulate", "--jobs", "1",
            "--no-progress", "--out", str(out)]
    capsys.readouterr()
    assert main(args + ["--dry-run"]) == 0
    text = capsys.readouterr().out
    assert "1 runs" not in text and " 1 run, " in text and "\n1 run: 1 to run" in text
    assert main(args + ["--no-figures"]) == 0
    assert "\n1 run in " in capsys.readouterr().out
    titles = [e["title"] for e in json.loads((out / "results.json").read_text())["experiments"]]
    assert titles == ["1 stream, 1 method"]


def test_simulate_counts_one_step_and_one_landmark_in_the_singular(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["simulate", "--steps", "0", "--landmarks", "1", "--out",
                 str(tmp_path / "s.jsonl")]) == 0
    assert ": 1 step, 1 landmark, 0 priors" in capsys.readouterr().out
