"""The Mapper protocol, MapEstimate, the runner and the registry."""

from __future__ import annotations


import numpy as np
import pytest

import bomgraph
from bomgraph.errors import ConfigError, UnknownMethodError
from bomgraph.mapper import MapEstimate, available_methods, checkpoint_times, create_mapper, run
from bomgraph.sim import SimConfig, paper_design, simulate_run
from bomgraph.stream import Step, StreamHeader


class Recorder:
    """A mapper that records what it is given."""

    def __init__(self, header: StreamHeader) -> None:
        self.ts: list[int] = []
        self.estimates = 0

    def step(self, step: Step) -> None:
        self.ts.append(step.t)

    def estimate(self) -> MapEstimate:
        self.estimates += 1
        return MapEstimate.empty(reason="recorder")


def test_run_checkpoints_every_10_and_at_the_end() -> None:
    s = simulate_run(paper_design(0)[0], SimConfig(n_steps=35))
    rec = Recorder(s.header)
    result = run(rec, s.steps, checkpoint_every=10, method="rec")
    assert rec.ts == list(range(36))
    assert [c.t for c in result.checkpoints] == [10, 20, 30, 35] == checkpoint_times(36, 10)
    assert result.step_s.shape == (36,) and result.total_s > 0
    assert result.method == "rec" and result.final.info["reason"] == "recorder"
    with pytest.raises(ConfigError):
        run(rec, s.steps, checkpoint_every=0)
    with pytest.raises(ConfigError, match="checkpoints are"):
        result.at(15)


class Finisher(Recorder):
    """A recorder with ``finish()``, logging the order of the calls."""

    def __init__(self, header: StreamHeader) -> None:
        super().__init__(header)
        self.log: list[str] = []

    def step(self, step: Step) -> None:
        super().step(step)
        self.log.append(f"step {step.t}")

    def finish(self) -> None:
        self.log.append("finish")

    def estimate(self) -> MapEstimate:
        self.log.append("estimate")
        return super().estimate()


@pytest.mark.parametrize("n_steps", [30, 35])
def test_run_calls_finish_once_after_the_last_step_before_its_estimate(n_steps: int) -> None:
    """Whether or not the last step falls on the cadence: ``finish()`` once, right before the
    final estimate, and no checkpoint twice."""
    s = simulate_run(paper_design(0)[0], SimConfig(n_steps=n_steps))
    rec = Finisher(s.header)
    seen: list[int] = []
    result = run(rec, s.steps, checkpoint_every=10, on_checkpoint=lambda c: seen.append(c.t))
    assert rec.log.count("finish") == 1
    assert rec.log[-3:] == [f"step {n_steps}", "finish", "estimate"]
    assert [c.t for c in result.checkpoints] == seen == checkpoint_times(n_steps + 1, 10)
    assert rec.estimates == len(seen)


def test_a_finish_that_takes_arguments_is_refused_before_the_first_step() -> None:
    """``run()`` calls ``finish()`` with no arguments; a plugin whose ``finish`` means
    something else (and needs an argument) gets one ConfigError up front, not a TypeError
    after the whole stream."""
    class OwnFinish(Recorder):
        def finish(self, result: object) -> None: ...

    class DefaultedFinish(Recorder):
        finished = 0

        def finish(self, result: object = None) -> None:
            self.finished += 1

    s = simulate_run(paper_design(0)[0])
    mapper = OwnFinish(s.header)
    with pytest.raises(ConfigError, match=r"OwnFinish\.finish\(result\) takes arguments"):
        run(mapper, s.steps[:30])
    assert mapper.ts == []
    ok = DefaultedFinish(s.header)
    run(ok, s.steps[:30])
    assert ok.finished == 1 and len(ok.ts) == 30


def test_a_bad_step_after_a_checkpoint_step_keeps_that_checkpoint() -> None:
    """``run()`` reads one step ahead; a stream that fails on the step after a checkpoint
    step still delivers that checkpoint (nothing lost), then the error, and no ``finish()``
    (the stream did not end)."""
    s = simulate_run(paper_design(0)[0], SimConfig(n_steps=35))

    def steps():
        yield from s.steps[:21]
        raise ConfigError("line 23: bad step (test)")

    rec = Finisher(s.header)
    seen: list[int] = []
    with pytest.raises(ConfigError, match="line 23"):
        run(rec, steps(), checkpoint_every=10, on_checkpoint=lambda c: seen.append(c.t))
    assert seen == [10, 20] and "finish" not in rec.log


def test_registry_lists_every_method_and_refuses_unknown_names() -> None:
    names = [m.name for m in available_methods()]
    for n in ["triangulate", "stmds-cs", "stmds-smacof", "ekf", "gtsam-batch", "gtsam-isam2",
              "hybrid", "oracle"]:
        assert n in names
    header = StreamHeader(0.05, (0.03, 0.0, 0.05))
    with pytest.raises(UnknownMethodError, match="known methods"):
        create_mapper("no-such-method", header)
    with pytest.raises(ConfigError, match="ground truth"):
        create_mapper("oracle", header)
    assert isinstance(create_mapper("triangulate", header), bomgraph.Mapper)


def test_bomgraph_does_not_import_baselines() -> None:
    import subprocess
    import sys
    code = ("import sys, bomgraph, bomgraph.cli, bomgraph.mapper, bomgraph.sim, "
            "bomgraph.experiments, bomgraph.bench, bomgraph.report, bomgraph.plots, "
            "bomgraph.evaluate, bomgraph.geometry, bomgraph.stmds.mapper; "
            "print(any(m == 'baselines' or m.startswith('baselines.') for m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"


def test_map_estimate_refuses_nan_duplicates_and_float_ids() -> None:
    with pytest.raises(ConfigError, match="finite"):
        MapEstimate(np.array([1, 2]), np.array([[0.0, np.nan], [1.0, 1.0]]))
    with pytest.raises(ConfigError, match="twice"):
        MapEstimate(np.array([1, 1]), np.zeros((2, 2)))
    with pytest.raises(ConfigError, match="integers"):
        MapEstimate(np.array([1.7, 2.0]), np.zeros((2, 2)))
