"""A folder compare writes into that cannot be written (h119): ``OUT/cache`` made immutable
ran every task and only then stopped, on the first cache file, with the work lost. Every
folder compare writes into (the cache, ``estimates/``, the figures' folder) is now checked
before anything runs, by ``--dry-run`` too."""

from __future__ import annotations

from pathlib import Path

import pytest

from _not_writable import not_writable  # tests/_not_writable.py

from bomgraph.cli import main


@pytest.fixture()
def stream(tmp_path: Path) -> Path:
    s = tmp_path / "s.jsonl"
    assert main(["simulate", "--seed", "3", "--steps", "30", "--landmarks", "10", "--out",
                 str(s), "-q"]) == 0
    return s


def _compare(stream: Path, out: Path, *extra: str) -> list[str]:
    """compare with its progress bar on stderr: a bar there means the tasks started."""
    return ["compare", "--streams", str(stream), "--methods", "triangulate", "--jobs", "1",
            "--progress", "--out", str(out), *extra]


@pytest.mark.parametrize("folder, extra", [
    ("cache", ("--no-figures",)), ("estimates", ("--no-figures", "--estimates")),
    ("estimates/streams/triangulate", ("--no-figures", "--estimates"))])
def test_an_unwritable_folder_is_refused_before_any_task_runs(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture[str], folder: str,
        extra: tuple[str, ...]) -> None:
    out = tmp_path / "out"
    (out / folder).mkdir(parents=True)
    for dry in ((), ("--dry-run",)):
        with not_writable(out / folder):
            status = main(_compare(stream, out, *extra, *dry))
        std = capsys.readouterr()
        assert status == 2, (std.out, std.err)
        [line] = std.err.strip().splitlines()  # no progress bar: no task started
        assert line.startswith("bomgraph: error: --out ") and "Traceback" not in std.err
        assert f"{out / folder} is not writable" in line, line
        assert "runs in" not in std.out and "to run" not in std.out, std.out
        assert list((out / folder).iterdir()) == []


def test_a_cache_holding_every_run_is_only_read(tmp_path: Path, stream: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """Not writable, a cache is refused only when a run would be added to it: an archived
    compare's cache, read-only, still gives its tables again."""
    out = tmp_path / "out"
    (out / "cache").mkdir(parents=True)
    assert main(_compare(stream, out, "--no-figures", "--estimates")) == 0
    assert "1 run in" in capsys.readouterr().out
    assert len(list((out / "cache").iterdir())) == 1
    with not_writable(out / "cache"):
        assert main(_compare(stream, out, "--no-figures", "--estimates", "--dry-run")) == 0
        assert "1 run: 0 to run, 1 in" in capsys.readouterr().out
        assert main(_compare(stream, out, "--no-figures", "--estimates")) == 0
        assert "(1 from the cache)" in capsys.readouterr().out
        assert main(_compare(stream, out, "--no-figures")) == 2  # a run without estimates
        assert f"the folder {out / 'cache'} is not writable" in capsys.readouterr().err
