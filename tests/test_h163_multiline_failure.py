"""A method whose exception message has several lines (GTSAM's "Indeterminate linear system"
message, the first failure a hybrid of one's own meets) is reported on one readable line:
its line breaks become spaces, not the literal ``\\n``s of the CLI's one-line net (h163)."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import numpy as np
import pytest

from bomgraph import mapper
from bomgraph.cli import main
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream

SINGULAR = textwrap.dedent('''
    import gtsam

    from bomgraph.mapper import MapEstimate


    class Singular:
        """Gauss-Newton on a landmark seen once: GTSAM's indeterminate system at t = 3"""

        def __init__(self, header) -> None:
            pass

        def step(self, step) -> None:
            if step.t == 3:
                graph = gtsam.NonlinearFactorGraph()
                noise = gtsam.noiseModel.Isotropic.Sigma(3, 0.01)
                graph.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(), noise))
                graph.add(gtsam.BearingFactor2D(0, 1, gtsam.Rot2(0.3),
                                                gtsam.noiseModel.Isotropic.Sigma(1, 0.01)))
                values = gtsam.Values()
                values.insert(0, gtsam.Pose2())
                values.insert(1, gtsam.Point2(2.0, 0.5))
                gtsam.GaussNewtonOptimizer(graph, values).optimize()

        def estimate(self):
            return MapEstimate.empty()
''')


@pytest.fixture()
def singular(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    (tmp_path / "singular_plugin.py").write_text(SINGULAR)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    mapper.register_method("singular", "singular_plugin:Singular", "raises GTSAM's error")
    stream = simulate(SimConfig(n_steps=10, n_landmarks=5), np.random.default_rng(0))
    write_stream(stream, tmp_path / "s.jsonl")
    return tmp_path / "s.jsonl"


def test_run_and_compare_show_a_multiline_method_error_as_one_readable_line(
        singular: Path, tmp_path: Path, capsys) -> None:
    assert main(["run", str(singular), "--method", "singular", "--out",
                 str(tmp_path / "e.est")]) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert "\\n" not in err, err
    assert ("failed: RuntimeError: Indeterminate linear system detected while working near "
            "variable 1") in err, err
    assert "(raised in Singular.step() at t = 3); -v shows the traceback" in err, err
    out = tmp_path / "c"
    assert main(["compare", "--streams", str(singular), "--methods", "singular", "--out",
                 str(out), "--no-figures", "--jobs", "1"]) == 1
    err = capsys.readouterr().err
    assert "\\n" not in err and "RuntimeError: Indeterminate linear system detected" in err, err
    run = json.loads((out / "results.json").read_text())["results"][0]
    assert run["error"].startswith("RuntimeError: Indeterminate linear system detected while "
                                   "working near variable 1"), run["error"]
    assert "\n" not in run["error"] and "Traceback" in run["traceback"]
