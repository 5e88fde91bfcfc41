"""The naive baseline: dead reckoning plus least-squares ray intersection."""

from __future__ import annotations

import math

import numpy as np
import pytest

from baselines.triangulate import TriangulateMapper
from bomgraph.evaluate import score_estimate
from bomgraph.geometry import intersect_rays
from bomgraph.mapper import run
from bomgraph.sim import SimConfig, paper_design, simulate, simulate_run
from bomgraph.stream import Step, StreamHeader


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
