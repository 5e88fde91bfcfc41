"""h49's review of the h47/h48/ord/units merges: what it found, each test failing before."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from _depth_mapper import depth_mapper

from bomgraph import mapper
from bomgraph.bench import Executor, execute
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream

TWO_METHODS = depth_mapper("self.DEPTH", "Near", attrs="DEPTH = 1.0") + """
class Far(Near):
    DEPTH = 3.0
"""


@pytest.fixture
def two_targets(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Experiment:
    """A module file with two factories, and a one-run sweep of the run-time method "m"."""
    src = tmp_path / "code" / "bomgraph_h49_two.py"
    src.parent.mkdir()
    src.write_text(TWO_METHODS)
    monkeypatch.syspath_prepend(str(src.parent))
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=40), np.random.default_rng(3)), stream)
    yield Experiment("e", "e", (Arm("m", "m"),), sources=(FileSource(str(stream)),))
    sys.modules.pop(src.stem, None)


def test_a_method_registered_anew_with_another_target_is_not_the_cached_one(
        two_targets: Experiment, tmp_path: Path) -> None:
    """The key held the sources of the target's package, not the target: "m" registered
    again (replace=True) as another factory of the same module took the first one's cached
    result."""
    cache = tmp_path / "cache"
    mapper.register_method("m", "bomgraph_h49_two:Near")
    (near,) = execute(two_targets.tasks(), Executor("serial"), cache_dir=cache)
    mapper.register_method("m", "bomgraph_h49_two:Far", replace=True)
    (far,) = execute(two_targets.tasks(), Executor("serial"), cache_dir=cache)
    (fresh,) = execute(two_targets.tasks(), Executor("serial"))
    assert near["ok"] and far["ok"] and fresh["ok"]
    mpe = [r["checkpoints"][-1]["mpe_m"] for r in (near, far, fresh)]
    assert mpe[1] == mpe[2] != mpe[0], "the other factory's cached result was returned"
    assert far["key"] != near["key"]
    # the same factory given the truth (a bound) is another method too
    mapper.register_method("m", "bomgraph_h49_two:Far", needs_truth=True, replace=True)
    (bound,) = execute(two_targets.tasks(), Executor("serial"), cache_dir=cache)
    assert bound["ok"] and bound["key"] != far["key"]


def test_a_huge_integer_version_is_cut_in_the_message(tmp_path: Path) -> None:
    """version_problem printed an unknown integer version whole: a header's version of 4,000
    digits gave a 4,000-character error line (the reader cut it at 40 before h48)."""
    from bomgraph.errors import StreamFormatError
    from bomgraph.jsonio import version_problem
    from bomgraph.stream_file import read_stream

    assert len(version_problem(10 ** 4000, (1,))) < 120
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=3), np.random.default_rng(3)), stream)
    head, rest = stream.read_text().split("\n", 1)
    stream.write_text(head.replace('"version": 1', '"version": ' + "9" * 4000) + "\n" + rest)
    with pytest.raises(StreamFormatError) as err:
        read_stream(stream)
    assert "unknown version 999" in str(err.value) and len(str(err.value)) < 300


def test_a_noisy_simulated_stream_is_not_taken_for_degrees(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """`bomgraph simulate --noise-scale 55` (accepted: its bearing sigma is below pi) states a
    dpsi sigma of 2.9 rad, so a turn beyond a full turn is a 2-3 sigma draw of its odometry;
    the reader warned "more than a full turn in one step; dpsi_rad is radians (degrees?)"
    at such a step. A turn is now taken for degrees only beyond 5 stated sigmas too (h52: 7;
    and the largest noise scale is now 34.6, where the turn sigma is pi/sqrt(3), so the
    stream is 34's, longer)."""
    import logging

    from bomgraph.stream_file import read_stream

    stream = tmp_path / "n55.jsonl"
    sim = simulate(SimConfig(n_steps=1000, noise_scale=34), np.random.default_rng(2))
    assert max(abs(s.odom[2]) for s in sim.steps if s.odom is not None) > 2 * np.pi
    write_stream(sim, stream)
    with caplog.at_level(logging.WARNING, logger="bomgraph"):
        read_stream(stream)
    assert "full turn" not in caplog.text, caplog.text
    # the paper's noise: a turn of 10 (degrees) is still one
    import json

    paper = tmp_path / "deg.jsonl"
    write_stream(simulate(SimConfig(n_steps=3), np.random.default_rng(0)), paper)
    head, *steps = paper.read_text().splitlines()
    step = json.loads(steps[1])
    step["odom"] = [0.1, 0.0, 10.0]
    paper.write_text("\n".join([head, steps[0], json.dumps(step), *steps[2:]]) + "\n")
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="bomgraph"):
        read_stream(paper)
    assert "turns 10 rad, more than a full turn" in caplog.text


def test_plan_compare_and_is_cached_refuse_a_none_executor_in_one_line(tmp_path: Path) -> None:
    """``executor=None`` (documented as "serial" before h47) raised AttributeError: 'NoneType'
    object has no attribute 'backend'; compare() and execute() refuse it with a ConfigError
    saying what to pass, and so do these now."""
    from bomgraph.bench import is_cached
    from bomgraph.errors import ConfigError
    from bomgraph.report import plan_compare

    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=3), np.random.default_rng(3)), stream)
    exp = Experiment("e", "e", (Arm("triangulate", "triangulate"),),
                     sources=(FileSource(str(stream)),))
    (tmp_path / "out" / "cache").mkdir(parents=True)
    with pytest.raises(ConfigError, match="executor must be an? Executor.*NoneType"):
        plan_compare([exp], tmp_path / "out", executor=None)
    with pytest.raises(ConfigError, match="executor must be an? Executor.*NoneType"):
        is_cached(exp.tasks()[0], tmp_path / "out" / "cache", None)


def test_an_importer_does_not_refuse_a_turn_beyond_a_full_turn() -> None:
    """Importers refuse implausible streams, and for a while that included a turn beyond 2 pi
    (h49 noticed: g2o wraps angles, so an EDGE_SE2 of 7 rad is a valid file). The reader
    still warns of it; an importer makes the stream."""
    from bomgraph.errors import DatasetError
    from bomgraph.plausibility import refuse_implausible, step_problem

    sim = simulate(SimConfig(n_steps=5), np.random.default_rng(1))
    st = sim.steps[2]
    turned = type(st)(t=st.t, odom=np.array([0.1, 0.0, 7.0]), landmark_ids=st.landmark_ids,
                      bearings_rad=st.bearings_rad)
    steps = [*sim.steps[:2], turned, *sim.steps[3:]]
    refuse_implausible(sim.header, steps, DatasetError, "test")      # no raise
    assert step_problem(turned, 0.0)[0] == "odom"                   # the reader's warning
    far = type(st)(t=st.t, odom=np.array([1e6, 0.0, 0.0]), landmark_ids=st.landmark_ids,
                   bearings_rad=st.bearings_rad)
    with pytest.raises(DatasetError, match="more than"):             # other checks stay
        refuse_implausible(sim.header, [*sim.steps[:2], far], DatasetError, "test")
