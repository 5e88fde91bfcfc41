"""The small stream and the one-method compare command of the compare output-folder tests
(tests/test_compare_out_folder.py, tests/test_h75_compare_leftovers.py), and the linked-folder
tests' compare with estimates and their one-line error (tests/test_h80_linked_estimates.py,
tests/test_h82_linked_review.py, tests/test_h100_lock_review.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from bomgraph.cli import main


@pytest.fixture()
def stream(tmp_path: Path) -> Path:
    """A 30-step, 10-landmark simulated stream file."""
    path = tmp_path / "s.jsonl"
    assert main(["simulate", "--steps", "30", "--landmarks", "10", "--out", str(path)]) == 0
    return path


def compare_cmd(stream: Path, out: Path, *more: str) -> list[str]:
    """``bomgraph compare`` of ``triangulate`` on ``stream`` into ``out``, one job."""
    return ["compare", "--streams", str(stream), "--methods", "triangulate", "--jobs", "1",
            "--no-progress", "--out", str(out), *more]


def linked_cmd(stream: Path, out: Path, methods: str) -> list[str]:
    """``bomgraph compare`` of ``methods`` on ``stream`` into ``out`` with ``--estimates``, no
    figures, one job."""
    return ["compare", "--streams", str(stream), "--methods", methods, "--jobs", "1",
            "--no-progress", "--no-figures", "--estimates", "--out", str(out)]


def one_error(capsys: pytest.CaptureFixture) -> str:
    """The one line on stderr (asserted to be one)."""
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]
