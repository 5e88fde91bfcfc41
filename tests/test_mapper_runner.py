"""The runner, the registry and the estimate file; the naive triangulate method."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import bomgraph
from bomgraph.errors import ConfigError, StreamFormatError, UnknownMethodError
from bomgraph.evaluate import score_estimate
from bomgraph.mapper import (MapEstimate, available_methods, checkpoint_times, create_mapper,
                             estimate_to_json, read_estimate, run, write_estimate)
from bomgraph.sim import SimConfig, paper_design, simulate, simulate_run
from bomgraph.stream import Step, StreamHeader
from baselines.triangulate import TriangulateMapper
from bomgraph.geometry import intersect_rays


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


def test_estimate_file_round_trip(tmp_path: Path) -> None:
    s = simulate_run(paper_design(0)[1], SimConfig(n_steps=25))
    result = run(TriangulateMapper(s.header), s.steps, method="triangulate")
    write_estimate(result, tmp_path / "e.json")
    back = read_estimate(tmp_path / "e.json")
    assert back.method == "triangulate"
    np.testing.assert_array_equal(back.final.landmark_ids, result.final.landmark_ids)
    np.testing.assert_array_equal(back.final.landmarks_xy, result.final.landmarks_xy)
    np.testing.assert_array_equal(back.final.poses, result.final.poses)
    assert [c.t for c in back.checkpoints] == [10, 20, 25]
    assert estimate_to_json(result)["timing_s"]["total"] == result.total_s
    (tmp_path / "bad.json").write_text('{"format": "bomgraph-estimate", "version": 1, '
                                       '"landmarks": [[1, 2]]}')
    with pytest.raises(StreamFormatError, match="landmarks"):
        read_estimate(tmp_path / "bad.json")


def test_triangulate_recovers_noise_free_landmarks_to_1e6() -> None:
    s = simulate_run(paper_design(0)[0], SimConfig(noise_scale=0))
    est = run(TriangulateMapper(s.header), s.steps).final
    score = score_estimate(est, s.truth)
    assert score.n_common == 50
    assert score.max_m < 1e-6
    assert score.robot_mean_m < 1e-6


def test_triangulate_needs_parallax_and_two_rays() -> None:
    p, ok = intersect_rays(np.array([[0.0, 0.0]]), np.array([0.3]))
    assert not ok and np.all(np.isnan(p))
    # two rays at 1 degree: refused at the default 2 degree gate, accepted at 0.5 degrees
    o = np.array([[0.0, 0.0], [1.0, 0.0]])
    target = np.array([0.5, 0.5 / math.tan(math.radians(0.5))])
    dirs = np.arctan2(target[1] - o[:, 1], target[0] - o[:, 0])
    assert not intersect_rays(o, dirs)[1]
    p, ok = intersect_rays(o, dirs, min_parallax_rad=math.radians(0.5))
    assert ok and np.allclose(p, target, atol=1e-9)
    # behind the rays: refused
    assert not intersect_rays(o, dirs + math.pi, min_parallax_rad=math.radians(0.5))[1]


def test_a_landmark_seen_from_one_place_only_is_not_mapped() -> None:
    header = StreamHeader(0.05, (0.03, 0.0, 0.05))
    m = TriangulateMapper(header)
    m.step(Step(0, None, np.array([3, 4]), np.array([0.5, 1.0])))
    m.step(Step(1, np.array([0.0, 0.0, 0.3]), np.array([3]), np.array([0.2])))  # pure turn
    m.step(Step(2, np.array([0.2, 0.0, 0.0]), np.array([4]), np.array([1.1])))
    est = m.estimate()
    assert 3 not in est.landmark_ids and 3 in est.info["left_out"]
    assert 4 in est.landmark_ids


def test_triangulate_is_deterministic_and_rotation_invariant() -> None:
    cfg = SimConfig(n_steps=80, n_landmarks=20)
    s = simulate(cfg, np.random.default_rng(9))
    a = run(TriangulateMapper(s.header), s.steps).final
    b = run(TriangulateMapper(s.header, start_pose=(4.0, -2.0, 1.0)), s.steps).final
    np.testing.assert_array_equal(a.landmark_ids, b.landmark_ids)
    sa, sb = score_estimate(a, s.truth), score_estimate(b, s.truth)
    assert sa.mpe_m == pytest.approx(sb.mpe_m, abs=1e-9)


@pytest.mark.parametrize("body,key", [
    ('"landmarks": [[0, 1, 2, 3, 4, 5]]', "landmarks[0]"),
    ('"landmarks": [["3", "1.5", "2.5"]]', "landmarks[0]"),
    ('"landmarks": [[true, 1.5, 2.5]]', "landmarks[0]"),
    ('"landmarks": [[1e30, 1.5, 2.5]]', "landmarks[0]"),
    ('"landmarks": [], "poses": [[2.7, 0, 0, 0]]', "poses[0]"),
    ('"landmarks": [], "poses": [[1, 0, 0, 0], [1, 0, 0, 0]]', "poses"),
    ('"landmarks": [], "checkpionts": []', "checkpionts"),
    ('"landmarks": [], "checkpoints": 5', "checkpoints"),
    ('"landmarks": [], "checkpoints": [{"t": true, "landmarks": []}]', "checkpoints[0].t"),
    ('"landmarks": [], "timing_s": [1, 2]', "timing_s"),
    ('"landmarks": [], "landmarks": []', "landmarks"),
])
def test_estimate_reader_is_strict(tmp_path: Path, body: str, key: str) -> None:
    p = tmp_path / "e.json"
    p.write_text('{"format": "bomgraph-estimate", "version": 1, "method": "m", ' + body + "}")
    with pytest.raises(StreamFormatError) as info:
        read_estimate(p)
    assert f"'{key}'" in str(info.value) and str(p) in str(info.value)


def test_map_estimate_refuses_nan_duplicates_and_float_ids() -> None:
    with pytest.raises(ConfigError, match="finite"):
        MapEstimate(np.array([1, 2]), np.array([[0.0, np.nan], [1.0, 1.0]]))
    with pytest.raises(ConfigError, match="twice"):
        MapEstimate(np.array([1, 1]), np.zeros((2, 2)))
    with pytest.raises(ConfigError, match="integers"):
        MapEstimate(np.array([1.7, 2.0]), np.zeros((2, 2)))
