"""Helpers of the tests of ``bomgraph run --out`` reading its stream once (tests/test_h71_*,
tests/test_h74_*, tests/test_h76_*): a simulated stream file, and a count of the step lines
the reader parses."""

from __future__ import annotations

from pathlib import Path

import pytest

from bomgraph import stream_file
from bomgraph.cli import main


def simulated(tmp_path_factory: pytest.TempPathFactory, steps: int, landmarks: int) -> Path:
    """A stream file of ``bomgraph simulate --seed 5`` with ``steps`` and ``landmarks``."""
    path = tmp_path_factory.mktemp("sim") / "s.jsonl"
    assert main(["simulate", "--seed", "5", "--steps", str(steps), "--landmarks",
                 str(landmarks), "--out", str(path)]) == 0
    return path


def counted_parses(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The list each parse of a step line appends to (the reader's own parser, counted)."""
    seen: list[int] = []
    parse = stream_file._parse_step

    def counted(*args, **kwargs):
        seen.append(1)
        return parse(*args, **kwargs)

    monkeypatch.setattr(stream_file, "_parse_step", counted)
    return seen
