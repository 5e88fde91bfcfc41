"""A turn sigma in degrees stated by the steps themselves (h65): the header's is judged against
pi/sqrt(3), a step's own only against a full turn (one step's 'turn unknown' is valid), and the
odometry-scale check sees degrees only on a robot that turns little; so steps stating 3 or 5
(degrees) on a turning robot were read silently, as the same value in the header was not."""

from __future__ import annotations

import json
import logging
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from hostile_helpers import bomgraph

from bomgraph.stream import Stream
from bomgraph.stream_file import read_stream, write_stream


def _warned(path: Path, caplog: pytest.LogCaptureFixture) -> list[str]:
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        read_stream(path)
    return [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]


def _per_step(sim: Stream, path: Path, sigma: tuple[float, float, float] | None, *,
              turn: str = "as simulated", header: tuple[float, float, float] | None = None
              ) -> Path:
    """``sim`` with every step stating ``sigma`` (None: none, the header's are used); ``turn``:
    'none' (a straight line: every turn exactly 0), 'little' (+-0.01 rad) or 'in place'
    (every translation exactly 0)."""
    steps = []
    for st in sim.steps:
        if st.odom is not None:
            odom = np.array(st.odom, dtype=float)
            if turn == "none":
                odom[2] = 0.0
            elif turn == "little":
                odom[2] = 0.01 * (-1) ** st.t
            elif turn == "in place":
                odom[:2] = 0.0
            st = replace(st, odom=odom,
                         odom_sigma=None if sigma is None else np.array(sigma, dtype=float))
        steps.append(st)
    head = sim.header if header is None else replace(sim.header, odometry_sigma=header)
    write_stream(Stream(head, tuple(steps), None), path)
    return path


def test_the_simulated_robot_turns() -> None:
    """The cases below are on a turning robot: its turns are not what made them silent."""
    from bomgraph.sim import SimConfig, simulate
    s = simulate(SimConfig(n_steps=60), np.random.default_rng(0))
    turns = np.abs([st.odom[2] for st in s.steps if st.odom is not None])
    assert np.mean(turns) > 0.3 and np.mean(turns > 0.2) > 0.5


@pytest.mark.parametrize("degrees", [2.0, 3.0, 4.0])
def test_per_step_turn_sigmas_in_degrees_on_a_turning_robot_are_warned_of(
        tmp_path: Path, sim: Stream, caplog: pytest.LogCaptureFixture, degrees: float) -> None:
    """Read silently: the 60 steps' turns (0.40 rad on average) average 0.21, 0.15 and 0.12
    of their bound, above the odometry-scale check's tenth."""
    path = _per_step(sim, tmp_path / "deg.jsonl", (0.03, 0.0, degrees))
    warned = _warned(path, caplog)
    assert len(warned) == 1, warned
    assert "line 3: 'odom_sigma'" in warned[0] and "degrees?" in warned[0], warned
    assert "60 of the 60 steps state a turn sigma above pi/sqrt(3)" in warned[0], warned


@pytest.mark.parametrize("turn", ["none", "little", "in place"])
def test_per_step_turn_sigmas_in_degrees_on_a_robot_that_does_not_turn(
        tmp_path: Path, sim: Stream, caplog: pytest.LogCaptureFixture, turn: str) -> None:
    """A straight line (every turn exactly 0: the turns are not judged) read 5 silently; a
    robot turning in place (every translation exactly 0) too."""
    warned = _warned(_per_step(sim, tmp_path / "deg.jsonl", (0.03, 0.0, 5.0), turn=turn),
                     caplog)
    assert len(warned) == 1 and "degrees?" in warned[0], warned


@pytest.mark.parametrize("turn,sigma", [
    (turn, sigma) for turn in ("as simulated", "none", "little", "in place")
    for sigma in (None, (0.03, 0.0, 0.0524), (0.03, 0.03, 0.0524), (0.0, 0.0, 0.0),
                  (0.03, 0.0, 1.8))
    if (turn, sigma and sigma[2]) != ("little", 1.8)])   # +-0.01 rad: a tenth of 1.8's bound
def test_plausible_per_step_sigmas_on_any_motion_are_not_warned_of(
        tmp_path: Path, sim: Stream, caplog: pytest.LogCaptureFixture, turn: str,
        sigma: tuple[float, float, float] | None) -> None:
    """No false warning and no division by zero: a straight line (no turn judged), a robot
    turning in place (no translation judged), sigmas of 0 (nothing judged), a turn sigma just
    below pi/sqrt(3); the header's sigmas (None) alike."""
    assert _warned(_per_step(sim, tmp_path / "ok.jsonl", sigma, turn=turn), caplog) == []


def test_a_minority_of_steps_stating_turn_unknown_is_not_warned_of(
        tmp_path: Path, sim: Stream, caplog: pytest.LogCaptureFixture) -> None:
    """One step's turn unknown (a g2o edge of rotation information below 0.3) is valid, and
    so are several, short of half the steps."""
    steps = list(sim.steps)
    for k in range(1, 30):   # 29 of the 60 odometry steps
        steps[k] = replace(steps[k], odom_sigma=np.array([0.03, 0.0, 3.16]))
    write_stream(replace(sim, steps=tuple(steps)), tmp_path / "s.jsonl")
    assert _warned(tmp_path / "s.jsonl", caplog) == []
    steps[30] = replace(steps[30], odom_sigma=np.array([0.03, 0.0, 3.16]))   # 30 of 60
    write_stream(replace(sim, steps=tuple(steps)), tmp_path / "s.jsonl")
    assert _warned(tmp_path / "s.jsonl", caplog) == []
    steps[31] = replace(steps[31], odom_sigma=np.array([0.03, 0.0, 3.16]))   # 31 of 60
    write_stream(replace(sim, steps=tuple(steps)), tmp_path / "s.jsonl")
    warned = _warned(tmp_path / "s.jsonl", caplog)
    assert len(warned) == 1 and "31 of the 60 steps" in warned[0], warned


def test_per_step_translation_sigmas_in_centimetres_are_warned_of(
        tmp_path: Path, sim: Stream, caplog: pytest.LogCaptureFixture) -> None:
    """The steps' own translation sigma 3 (centimetres) for steps of about 0.15 m; turning or
    not (a guard: this one was warned of before h65)."""
    for turn in ("as simulated", "none"):
        warned = _warned(_per_step(sim, tmp_path / "cm.jsonl", (3.0, 0.0, 0.0524), turn=turn),
                         caplog)
        assert len(warned) == 1 and "centimetres?" in warned[0], warned


def test_the_cli_warns_of_the_per_step_degrees_stream(tmp_path: Path) -> None:
    """The case as found: ``bomgraph simulate`` (300 steps), every step rewritten to state its
    own sigmas with the turn's in degrees (5), run: no warning (the turns average 0.106 of
    their bound)."""
    out = tmp_path / "s.jsonl"
    assert bomgraph("simulate", "--seed", "0", "--out", out).returncode == 0
    head, *steps = out.read_text().splitlines()
    lines = [json.loads(s) for s in steps]
    for st in lines:
        if "odom" in st:
            st["odom_sigma"] = [0.03, 0.0, 5.0]
    out.write_text("\n".join([head, *map(json.dumps, lines)]) + "\n")
    proc = bomgraph("run", out, "--method", "triangulate", "--out", tmp_path / "e.json")
    assert proc.returncode == 0, proc.stderr
    warned = [ln for ln in proc.stderr.decode().splitlines() if "WARNING" in ln]
    assert len(warned) == 1 and "degrees?" in warned[0], warned


def test_no_odometry_step_is_not_judged() -> None:
    """A stream of the step t = 0 alone, or of steps without odometry: nothing judged (and no
    division by the zero steps)."""
    from bomgraph.plausibility import OdometryScale
    from bomgraph.stream import Step
    scale = OdometryScale((0.03, 0.0, 5.0))
    scale.add(Step(0, None, np.zeros(0, np.int64), np.zeros(0)))
    assert scale.n == 0 and scale.problem() is None


@pytest.mark.parametrize("n_steps", [1, 9])
def test_too_few_steps_are_not_judged_by_the_count(tmp_path: Path, n_steps: int,
                                                   caplog: pytest.LogCaptureFixture) -> None:
    """One step (or nine) stating its turn unknown is valid: like the scale checks, the count
    judges MIN_SCALE_STEPS (10) steps or more (it warned '1 of the 1 steps'); ten are judged."""
    from bomgraph.sim import SimConfig, simulate
    for n, warned in ((n_steps, False), (10, True)):
        sim = simulate(SimConfig(n_steps=n), np.random.default_rng(0))
        msgs = _warned(_per_step(sim, tmp_path / f"s{n}.jsonl", (0.03, 0.0, 2.0)), caplog)
        assert any("turn sigma above pi/sqrt(3)" in m for m in msgs) == warned, (n, msgs)
