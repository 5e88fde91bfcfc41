"""The command line: the simulate -> run -> evaluate pipeline and its user errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from bomgraph.cli import main


def test_pipeline_simulate_run_evaluate(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    run_file, est_file = tmp_path / "run.jsonl", tmp_path / "est.json"
    assert main(["simulate", "--seed", "3", "--steps", "60", "--landmarks", "20",
                 "--prior-fraction", "0.1", "--out", str(run_file)]) == 0
    assert main(["run", str(run_file), "--method", "triangulate", "--out", str(est_file)]) == 0
    capsys.readouterr()
    assert main(["evaluate", str(est_file), str(run_file), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["method"] == "triangulate" and out["n_truth"] == 20
    assert 0 < out["mpe_m"] < 1.0
    assert out["checkpoints"]["t"] == [10, 20, 30, 40, 50, 60]
    assert main(["evaluate", str(est_file), str(run_file)]) == 0
    assert "landmark MPE" in capsys.readouterr().out


def test_methods_lists_the_registry(capsys: pytest.CaptureFixture) -> None:
    assert main(["methods"]) == 0
    out = capsys.readouterr().out
    assert "triangulate" in out and "stmds-smacof" in out and "oracle" in out


def test_user_errors_print_one_line_and_exit_2(tmp_path: Path) -> None:
    bad = tmp_path / "bad.jsonl"
    bad.write_text('{"format": "bomgraph-stream", "version": 1, "bearing_sigma_rad": 0.05, '
                   '"odometry_sigma": [0.03, 0, 0.05]}\n{"t": 0, "bearings": [[1, "x"]]}\n')
    proc = subprocess.run([sys.executable, "-m", "bomgraph.cli", "run", str(bad), "--method",
                           "triangulate", "--out", str(tmp_path / "e.json")],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr
    assert "line 2" in lines[0] and "bearings[0]" in lines[0] and str(bad) in lines[0]
    proc = subprocess.run([sys.executable, "-m", "bomgraph.cli", "run", str(bad), "--method",
                           "nope", "--out", "x"], capture_output=True, text=True)
    assert proc.returncode == 2 and "unknown method" in proc.stderr


def test_option_errors_are_user_errors(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """--option goes through bomgraph.jsonio.parse_options: inf is a number (refused here by
    the method's own range check), a pair without '=' is refused; both exit 2, one line."""
    run_file = tmp_path / "run.jsonl"
    assert main(["simulate", "--steps", "20", "--out", str(run_file)]) == 0
    capsys.readouterr()
    for opt, msg in (("min_parallax_rad=inf", "min_parallax_rad"), ("foo", "key=value")):
        assert main(["run", str(run_file), "--method", "triangulate", "--option", opt,
                     "--out", str(tmp_path / "e.json")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and msg in err[0]
    assert main(["compare", "--quick", "--experiments", "exp9", "--out",
                 str(tmp_path / "c")]) == 2
    assert "unknown experiment" in capsys.readouterr().err


def test_run_json_summary_counts_the_checkpoints_written(tmp_path: Path,
                                                         capsys: pytest.CaptureFixture) -> None:
    """``run --json`` reports the checkpoints in the estimate file (run() keeps only the last
    one in memory when it writes the file as it goes)."""
    from bomgraph.estimate_file import read_estimate

    run_file, est_file = tmp_path / "run.jsonl", tmp_path / "est.json"
    assert main(["simulate", "--seed", "1", "--steps", "45", "--landmarks", "20",
                 "--out", str(run_file)]) == 0
    capsys.readouterr()
    assert main(["run", str(run_file), "--method", "triangulate", "--out", str(est_file),
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["t"] == 45
    assert summary["checkpoints"] == len(read_estimate(est_file).checkpoints) == 5


def test_run_summary_counts_one_landmark_in_the_singular(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture) -> None:
    """h152: the stream format's own two-step example maps one landmark with triangulate;
    the summary said "1 landmarks mapped"."""
    stream = tmp_path / "ex.jsonl"
    stream.write_text(
        '{"format": "bomgraph-stream", "version": 1, "bearing_sigma_rad": 0.0524, '
        '"odometry_sigma": [0.03, 0.0, 0.0524], "sensor_range_m": 1.0}\n'
        '{"t": 0, "bearings": [[0, 1.93]]}\n'
        '{"t": 1, "odom": [0.15, 0.0, 0.2], "bearings": [[0, 1.84], [1, -1.02]]}\n')
    capsys.readouterr()
    assert main(["run", str(stream), "--method", "triangulate",
                 "--out", str(tmp_path / "e.est")]) == 0
    assert capsys.readouterr().out.startswith("triangulate: 1 landmark mapped at t = 1 in ")
    # h154: and so did export's summary, evaluate's truth-free line and the g2o note (landmark
    # 1, seen once, is not mapped)
    est = str(tmp_path / "e.est")
    assert main(["export", est, "--format", "csv", "--out", str(tmp_path / "e.csv")]) == 0
    assert capsys.readouterr().out.rstrip().endswith("(csv): 2 poses, 1 landmark")
    assert main(["evaluate", est, str(stream)]) == 0
    assert "  final map: 1 landmark\n" in capsys.readouterr().out
    assert main(["export", est, "--stream", str(stream), "--format", "g2o",
                 "--out", str(tmp_path / "e.g2o")]) == 0
    out, err = capsys.readouterr()
    assert out.rstrip().endswith("(g2o): 2 poses, 1 landmark")
    assert err == ("bomgraph: note: 1 observed landmark without an estimate has no VERTEX_XY "
                   "(id 1): g2o drops its 1 bearing edge when it loads the file\n"), err
    assert main(["-q", "export", est, "--stream", str(stream), "--format", "g2o",
                 "--out", str(tmp_path / "q.g2o")]) == 0
    assert capsys.readouterr().err == ""


def test_compare_shows_its_bar_on_a_terminal_only(tmp_path: Path) -> None:
    """Like ``run``: no progress bar when stderr is a file or a pipe (it filled logs with
    carriage returns, and began with an empty "0run" bar), ``--progress`` forces it."""
    run_file = tmp_path / "s.jsonl"
    assert main(["simulate", "--steps", "20", "--landmarks", "10", "--out", str(run_file)]) == 0
    base = [sys.executable, "-m", "bomgraph", "compare", "--streams", str(run_file),
            "--methods", "triangulate", "--jobs", "1", "--no-figures"]
    quiet = subprocess.run([*base, "--out", str(tmp_path / "a")], capture_output=True,
                           text=True)
    assert quiet.returncode == 0 and "run/s" not in quiet.stderr and "%|" not in quiet.stderr
    forced = subprocess.run([*base, "--progress", "--out", str(tmp_path / "b")],
                            capture_output=True, text=True)
    assert forced.returncode == 0 and "1/1" in forced.stderr
    assert "compare: 0run" not in forced.stderr  # the empty bar before the total was known
