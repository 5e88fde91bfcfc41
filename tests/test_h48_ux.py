"""Small faults a new user met (helper h46's walkthrough), each fixed with a test here."""

from __future__ import annotations

from pathlib import Path

import pytest

from bomgraph.cli import main


def test_compare_says_how_many_runs_came_from_the_cache(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture) -> None:
    """The last line said "2 runs in 0.0 s" when both came from the cache; only --dry-run
    said what was cached. It (and compare's result) now counts the runs the cache gave."""
    from bomgraph.bench import Executor
    from bomgraph.experiments import compare_experiments
    from bomgraph.report import compare

    run_file = tmp_path / "s.jsonl"
    assert main(["simulate", "--steps", "20", "--landmarks", "10", "--out", str(run_file)]) == 0
    cmd = ["compare", "--streams", str(run_file), "--methods", "triangulate,stmds-cs",
           "--jobs", "1", "--no-figures", "--no-progress", "--out", str(tmp_path / "c")]
    assert main(cmd) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith("2 runs in ") and "from the cache" not in last
    assert main(cmd) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith("2 runs in ") and " s (2 from the cache); wrote " in last
    chosen, _ = compare_experiments(streams=[str(run_file)], methods="triangulate")
    assert compare(chosen, tmp_path / "c", executor=Executor("serial")).n_cached == 1
    assert compare(chosen, tmp_path / "c", executor=Executor("serial"),
                   use_cache=False).n_cached == 0


_HEAD = ('{"format": "bomgraph-stream", "version": %s, "bearing_sigma_rad": 0.05, '
         '"odometry_sigma": [0.03, 0, 0.05]}\n{"t": 0, "bearings": [[1, 0.5]]}\n')


@pytest.mark.parametrize("version, says", [('"1"', 'the integer 1, not the string "1"'),
                                           ("1.0", "the integer 1, not 1.0"),
                                           ("true", "the integer 1, not true"),
                                           ("2", "unknown version 2; this reader knows "
                                                 "version 1")])
def test_a_version_that_is_not_the_integer_1_says_what_to_write(
        tmp_path: Path, capsys: pytest.CaptureFixture, version: str, says: str) -> None:
    """``"version": "1"`` was refused with 'unknown version "1"; this reader knows version
    1', which reads as a contradiction: it now says to write the integer."""
    stream = tmp_path / "s.jsonl"
    stream.write_text(_HEAD % version)
    assert main(["run", str(stream), "--method", "triangulate",
                 "--out", str(tmp_path / "e.est")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(stream) in err[0] and "line 1" in err[0]
    assert "'version'" in err[0] and says in err[0], err[0]


@pytest.mark.parametrize("version, says", [('"2"', 'the integer 1 or 2, not the string "2"'),
                                           ("3", "unknown version 3; this reader knows "
                                                 "versions 1 and 2")])
def test_an_estimate_version_that_is_not_an_integer_says_what_to_write(
        tmp_path: Path, capsys: pytest.CaptureFixture, version: str, says: str) -> None:
    stream, est = tmp_path / "s.jsonl", tmp_path / "e.est"
    assert main(["simulate", "--steps", "20", "--landmarks", "10", "--out", str(stream)]) == 0
    assert main(["run", str(stream), "--method", "triangulate", "--out", str(est)]) == 0
    lines = est.read_text().splitlines(keepends=True)
    assert '"version":2,' in lines[0]
    est.write_text(lines[0].replace('"version":2,', f'"version":{version},', 1)
                   + "".join(lines[1:]))
    capsys.readouterr()
    assert main(["evaluate", str(est), str(stream)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(est) in err[0] and "line 1" in err[0]
    assert "'version'" in err[0] and says in err[0], err[0]
