"""``bomgraph compare --estimates``: each run's final estimate file and its stream, paired in
an index, scored again by ``evaluate`` to the same numbers as the comparison's."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest

from bomgraph.cli import main
from bomgraph.estimate_file import read_estimate
from bomgraph.file_evaluation import evaluate_files


def _index(out: Path) -> list[dict[str, str]]:
    with open(out / "estimates" / "index.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def test_estimates_and_streams_pair_up_and_score_as_in_the_comparison(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "c"
    assert main(["compare", "--quick", "--experiments", "exp3", "--estimates", "--jobs", "1",
                 "--no-figures", "--no-progress", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "8 estimate files under" in printed and "stream files under" in printed
    results = json.loads((out / "results.json").read_text())["results"]
    assert len(results) == 8 and not any("estimate_file" in r for r in results)
    rows = _index(out)
    assert len(rows) == 8
    final = {(r["arm"], r["run"]): r["checkpoints"][-1]["mpe_m"] for r in results}
    for row in rows:
        est = read_estimate(out / row["estimate"])
        assert len(est.checkpoints) == 1 and est.checkpoints[0].t == 150
        ev = evaluate_files(out / row["estimate"], out / row["stream"])   # identity checked
        assert math.isclose(ev.score.mpe_m, final[(row["arm"], row["run"])], rel_tol=1e-12)
    # the arms with and without priors ran on different streams of the same run
    streams = {(r["arm"], r["run"]): r["stream"] for r in rows}
    assert streams[("stmds-smacof", "s0-l0-r0")] != streams[("stmds-smacof+priors", "s0-l0-r0")]
    # a second run reads the cache, estimates included, and writes the same files
    before = {r["estimate"]: (out / r["estimate"]).read_text() for r in rows}
    assert main(["compare", "--quick", "--experiments", "exp3", "--estimates", "--jobs", "1",
                 "--no-figures", "--no-progress", "--out", str(out)]) == 0
    assert {r["estimate"]: (out / r["estimate"]).read_text() for r in _index(out)} == before


def test_a_user_stream_is_named_not_copied(tmp_path: Path) -> None:
    s = tmp_path / "mine.jsonl"
    assert main(["simulate", "--seed", "4", "--steps", "60", "--out", str(s), "-q"]) == 0
    out = tmp_path / "c"
    assert main(["compare", "--streams", str(s), "--methods", "triangulate,ekf", "--estimates",
                 "--jobs", "1", "--no-figures", "--no-progress", "--out", str(out)]) == 0
    rows = _index(out)
    assert [r["arm"] for r in rows] == ["triangulate", "ekf"]
    assert {r["stream"] for r in rows} == {str(s)} and not (out / "streams").exists()
    for row in rows:
        assert evaluate_files(out / row["estimate"], s).score.n_common > 3


def test_a_later_compare_leaves_no_estimate_of_an_earlier_one(tmp_path: Path) -> None:
    """The estimates of an earlier compare in the same folder (other arms, or none asked for
    now) were left there with its index.csv, beside a results.json they no longer match."""
    s = tmp_path / "mine.jsonl"
    assert main(["simulate", "--seed", "4", "--steps", "60", "--out", str(s), "-q"]) == 0
    out = tmp_path / "c"
    args = ["compare", "--streams", str(s), "--jobs", "1", "--no-figures", "--no-progress",
            "--out", str(out), "-q"]
    assert main(args + ["--methods", "triangulate,ekf", "--estimates"]) == 0
    assert len(list((out / "estimates").rglob("*.est"))) == 2
    assert main(args + ["--methods", "triangulate", "--estimates"]) == 0
    assert [r["arm"] for r in _index(out)] == ["triangulate"]
    assert [p.relative_to(out).as_posix() for p in sorted((out / "estimates").rglob("*.est"))
            ] == [_index(out)[0]["estimate"]]
    assert main(args + ["--methods", "triangulate"]) == 0
    assert not [p for p in (out / "estimates").rglob("*") if p.is_file()]


def test_a_stream_an_earlier_compare_wrote_is_kept_when_a_later_one_reads_it(tmp_path: Path
                                                                           ) -> None:
    """The simulated streams compare writes beside its estimates are its own files, but a later
    compare that reads one of them as its input does not remove it."""
    out = tmp_path / "c"
    base = ["compare", "--jobs", "1", "--no-figures", "--no-progress", "--out", str(out), "-q"]
    assert main(base + ["--quick", "--experiments", "exp1", "--estimates"]) == 0
    streams = sorted((out / "streams").rglob("*.jsonl"))
    assert streams
    assert main(base + ["--streams", str(streams[0]), "--methods", "triangulate"]) == 0
    assert streams[0].exists()
    assert not [p for p in streams[1:] if p.exists()]      # the others were its own


def test_an_estimate_file_names_the_method_and_options_that_redo_it(tmp_path: Path) -> None:
    """The header held the arm's label ("ekf@real"), which no --method takes: it now holds
    the registered method and the arm's options, and running those again gives the same map."""
    from bomgraph.bench import run_file

    s = tmp_path / "mine.jsonl"
    assert main(["simulate", "--seed", "5", "--steps", "60", "--out", str(s), "-q"]) == 0
    out = tmp_path / "c"
    assert main(["compare", "--streams", str(s), "--methods", "ekf@real,triangulate",
                 "--jobs", "1", "--no-figures", "--no-progress", "--out", str(out),
                 "--estimates", "-q"]) == 0
    rows = {r["arm"]: r for r in _index(out)}
    assert set(rows) == {"ekf@real", "triangulate"}
    est = read_estimate(out / rows["ekf@real"]["estimate"])
    assert (est.method, dict(est.options or {})) == ("ekf", {"preset": "real"})
    again = run_file(s, est.method, est.options).final
    assert list(again.landmark_ids) == list(est.final.landmark_ids)
    assert (again.landmarks_xy == est.final.landmarks_xy).all()
    assert read_estimate(out / rows["triangulate"]["estimate"]).method == "triangulate"


def test_dry_run_lists_the_runs_and_the_cached_ones_and_writes_nothing(tmp_path: Path,
                                                                      capsys) -> None:
    s = tmp_path / "mine.jsonl"
    assert main(["simulate", "--seed", "6", "--steps", "40", "--out", str(s), "-q"]) == 0
    out = tmp_path / "c"
    args = ["compare", "--streams", str(s), "--methods", "triangulate,ekf", "--jobs", "1",
            "--no-figures", "--no-progress", "--out", str(out), "-q"]
    capsys.readouterr()
    assert main(args + ["--dry-run"]) == 0
    assert not out.exists()                                   # nothing written
    text = capsys.readouterr().out
    assert "2 runs: 2 to run, 0 in" in text and "triangulate" in text
    assert main(args[:4] + ["triangulate"] + args[5:]) == 0   # run one arm only
    capsys.readouterr()
    assert main(args + ["--dry-run"]) == 0
    assert "2 runs: 1 to run, 1 in" in capsys.readouterr().out
    assert main(args + ["--dry-run", "--no-cache"]) == 0
    assert "2 runs: 2 to run, 0 in" in capsys.readouterr().out
