"""``plausibility.OdometryScale`` after h55 judges the mean of each step's motion over its own
sigma's bound: one step stating a tiny sigma (a 'hard' g2o edge of huge information) must
not hide sigmas in centimetres on every other step, as one step stating a huge sigma no
longer makes them look so."""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from bomgraph.stream import Stream
from bomgraph.stream_file import read_stream, write_stream


def _warned(path: Path, caplog: pytest.LogCaptureFixture) -> list[str]:
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        read_stream(path)
    return [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]


def test_one_hard_step_does_not_hide_sigmas_in_centimetres(
        tmp_path: Path, sim: Stream, caplog: pytest.LogCaptureFixture) -> None:
    head = replace(sim.header, odometry_sigma=(5.0, 5.0, sim.header.odometry_sigma[2]))
    write_stream(replace(sim, header=head), tmp_path / "cm.jsonl")
    warned = _warned(tmp_path / "cm.jsonl", caplog)
    assert len(warned) == 1 and "centimetres?" in warned[0], warned
    steps = list(sim.steps)
    steps[30] = replace(steps[30], odom_sigma=np.array([1e-6, 1e-6, 1e-6]))
    write_stream(Stream(head, tuple(steps), sim.truth), tmp_path / "hard.jsonl")
    warned = _warned(tmp_path / "hard.jsonl", caplog)
    assert len(warned) == 1 and "centimetres?" in warned[0], warned
