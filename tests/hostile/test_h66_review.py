"""Review of h65 (steps stating their own turn sigma above pi/sqrt(3) warned of): the count's
warning hid the odometry-scale check's other warnings, and named the first step stating any
sigma of its own, not one stating the large turn sigma."""

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


def _stating(sim: Stream, path: Path, sigma_of_t) -> Path:
    """``sim`` with each odometry step ``t`` stating ``sigma_of_t(t)`` (None: none)."""
    steps = tuple(replace(st, odom_sigma=None if (s := sigma_of_t(st.t)) is None
                          else np.array(s, dtype=float)) if st.odom is not None else st
                  for st in sim.steps)
    write_stream(Stream(sim.header, steps, None), path)
    return path


def test_sigmas_in_centimetres_and_degrees_on_every_step_are_both_warned_of(
        tmp_path: Path, sim: Stream, caplog: pytest.LogCaptureFixture) -> None:
    """Every step stating (3, 0, 5): centimetres and degrees. Before h65 the reader warned of
    the centimetres; since h65 only of the degrees (its count returned first), so fixing
    the turn sigma alone left the translation's in centimetres to the next run."""
    warned = _warned(_stating(sim, tmp_path / "s.jsonl", lambda t: (3.0, 0.0, 5.0)), caplog)
    assert len(warned) == 2, warned
    assert any("centimetres?" in w for w in warned), warned
    assert any("60 of the 60 steps state a turn sigma above pi/sqrt(3)" in w
               for w in warned), warned


def test_the_count_and_the_turn_check_are_one_warning(
        tmp_path: Path, sim: Stream, caplog: pytest.LogCaptureFixture) -> None:
    """Turns of +-0.01 rad under a stated 5 (degrees): both the count and the turns' scale
    say degrees; one warning, not two."""
    steps = tuple(replace(st, odom=np.array([st.odom[0], st.odom[1], 0.01 * (-1) ** st.t]),
                          odom_sigma=np.array([0.03, 0.0, 5.0])) if st.odom is not None
                  else st for st in sim.steps)
    write_stream(Stream(sim.header, steps, None), tmp_path / "s.jsonl")
    warned = _warned(tmp_path / "s.jsonl", caplog)
    assert len(warned) == 1 and "turn sigma above pi/sqrt(3)" in warned[0], warned


def test_the_count_warning_names_the_first_step_stating_a_large_turn_sigma(
        tmp_path: Path, sim: Stream, caplog: pytest.LogCaptureFixture) -> None:
    """Steps 1 to 5 state plausible sigmas of their own, the rest 5 (degrees): the warning
    named line 3 (step 1, stating 0.0524), not line 8 (step 6, the first stating 5)."""
    path = _stating(sim, tmp_path / "s.jsonl",
                    lambda t: (0.03, 0.0, 0.0524) if t <= 5 else (0.03, 0.0, 5.0))
    warned = _warned(path, caplog)
    assert len(warned) == 1, warned
    assert "line 8: 'odom_sigma': 55 of the 60 steps" in warned[0], warned


def test_the_centimetre_warning_still_names_the_first_step_stating_its_own(
        tmp_path: Path, sim: Stream, caplog: pytest.LogCaptureFixture) -> None:
    """Steps from 4 on state sigmas in centimetres: the line of step 4 (line 6), as before."""
    path = _stating(sim, tmp_path / "s.jsonl", lambda t: None if t < 4 else (5.0, 5.0, 0.0524))
    warned = _warned(path, caplog)
    assert len(warned) == 1 and "line 6: 'odom_sigma'" in warned[0] \
        and "centimetres?" in warned[0], warned


def test_a_sigma_on_the_step_without_odometry_is_not_the_line_named(
        tmp_path: Path, sim: Stream, caplog: pytest.LogCaptureFixture) -> None:
    """The header's sigmas in centimetres and the step t = 0 stating an odom_sigma (it has no
    odometry: not judged): the warning named line 2 with the header's key
    'odometry_sigma', which is on line 1."""
    head = replace(sim.header, odometry_sigma=(5.0, 5.0, sim.header.odometry_sigma[2]))
    first = replace(sim.steps[0], odom_sigma=np.array([0.03, 0.0, 0.0524]))
    write_stream(Stream(head, (first, *sim.steps[1:]), None), tmp_path / "s.jsonl")
    warned = _warned(tmp_path / "s.jsonl", caplog)
    assert len(warned) == 1 and "line 1: 'odometry_sigma'" in warned[0] \
        and "centimetres?" in warned[0], warned


def test_translation_and_turn_sigmas_both_off_are_both_warned_of(
        tmp_path: Path, sim: Stream, caplog: pytest.LogCaptureFixture) -> None:
    """Every step stating (3, 0, 1.5) (centimetres, and degrees below pi/sqrt(3): not
    counted) on a robot turning +-0.01 rad: the translations' warning hid the turns'."""
    steps = tuple(replace(st, odom=np.array([st.odom[0], st.odom[1], 0.01 * (-1) ** st.t]),
                          odom_sigma=np.array([3.0, 0.0, 1.5])) if st.odom is not None
                  else st for st in sim.steps)
    write_stream(Stream(sim.header, steps, None), tmp_path / "s.jsonl")
    warned = _warned(tmp_path / "s.jsonl", caplog)
    assert len(warned) == 2, warned
    assert "centimetres?" in warned[0] and "the 60 steps turn" in warned[1] \
        and "degrees?" in warned[1], warned
