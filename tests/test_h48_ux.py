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
