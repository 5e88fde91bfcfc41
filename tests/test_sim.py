"""The simulator: the paper's defaults, determinism, the sensor model, priors."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from bomgraph.errors import ConfigError
from bomgraph.geometry import between, bearings_to
from bomgraph.sim import (SimConfig, make_priors, n_prior_pairs, paper_design, simulate,
                          simulate_run)


def test_defaults_are_the_papers() -> None:
    c = SimConfig()
    assert (c.arena_m, c.n_landmarks, c.n_steps, c.sensor_range_m) == (2.5, 50, 300, 1.0)
    assert c.sigma_l_m == 0.03
    assert c.sigma_phi_rad == pytest.approx(math.radians(3))
    assert c.sigma_theta_rad == pytest.approx(math.radians(3))


def test_paper_design_is_5_layouts_by_5_starts() -> None:
    design = paper_design(0)
    assert len(design) == 25
    runs = [simulate_run(s, SimConfig(n_steps=5)) for s in design[:6]]
    # the same layout for the 5 starts of a layout, a new one for the next layout
    for r in runs[1:5]:
        np.testing.assert_array_equal(r.truth.landmarks_xy, runs[0].truth.landmarks_xy)
        assert not np.array_equal(r.truth.poses[0], runs[0].truth.poses[0])
    assert not np.array_equal(runs[5].truth.landmarks_xy, runs[0].truth.landmarks_xy)


def test_noise_free_measurements_match_the_truth_and_stay_in_the_arena() -> None:
    s = simulate_run(paper_design(2)[7], SimConfig(noise_scale=0))
    poses = s.truth.poses
    assert np.all(poses[:, :2] >= 0) and np.all(poses[:, :2] <= 2.5)
    odoms = np.array([st.odom for st in s.steps[1:]])
    np.testing.assert_allclose(odoms, between(poses[:-1], poses[1:]), atol=1e-12)
    assert np.all(odoms[:, 1] == 0.0)
    assert np.all((odoms[:, 0] >= 0.1) & (odoms[:, 0] <= 0.2))
    lm = s.truth.landmarks_xy
    for st in s.steps[::17]:
        pose = poses[st.t]
        d = np.hypot(*(lm - pose[:2]).T)
        np.testing.assert_array_equal(np.sort(st.landmark_ids), np.flatnonzero(d <= 1.0))
        np.testing.assert_allclose(st.bearings_rad, bearings_to(pose, lm[st.landmark_ids]),
                                   atol=1e-12)


def test_noise_has_the_stated_spread() -> None:
    s = simulate_run(paper_design(0)[0], SimConfig(n_steps=300))
    poses, lm = s.truth.poses, s.truth.landmarks_xy
    res = np.concatenate([np.asarray(st.bearings_rad) - bearings_to(poses[st.t],
                                                                     lm[st.landmark_ids])
                          for st in s.steps])
    res = np.angle(np.exp(1j * res))  # independent of bomgraph.angles
    assert np.std(res) == pytest.approx(math.radians(3), rel=0.06)
    odoms = np.array([st.odom for st in s.steps[1:]])
    true = between(poses[:-1], poses[1:])
    assert np.std(odoms[:, 0] - true[:, 0]) == pytest.approx(0.03, rel=0.15)


def test_sensor_options_fov_min_range_and_wrong_associations() -> None:
    cfg = SimConfig(n_steps=60, fov_rad=math.radians(70), min_range_m=0.3, noise_scale=0,
                    wrong_association_rate=0.0)
    s = simulate(cfg, np.random.default_rng(3))
    for st in s.steps:
        assert np.all(np.abs(st.bearings_rad) <= math.radians(35) + 1e-12)
        d = np.hypot(*(s.truth.landmarks_xy[st.landmark_ids] - s.truth.poses[st.t, :2]).T)
        assert np.all(d >= 0.3)
    bad = simulate(SimConfig(n_steps=60, noise_scale=0, wrong_association_rate=0.5),
                   np.random.default_rng(3))
    wrong = 0
    for st in bad.steps:
        assert len(np.unique(st.landmark_ids)) == len(st.landmark_ids)
        pred = bearings_to(bad.truth.poses[st.t], bad.truth.landmarks_xy[st.landmark_ids])
        wrong += int(np.sum(np.abs(pred - st.bearings_rad) > 1e-9))
    assert wrong > 50


def test_min_range_and_fov_leave_the_other_bearings_noise_unchanged() -> None:
    # the same generator state with and without a minimum range / field of view: every
    # bearing the restricted stream keeps is, to the bit, the unrestricted stream's bearing
    base = SimConfig(n_steps=80)
    full = simulate(base, np.random.default_rng(5))
    for cfg in (replace(base, min_range_m=0.2), replace(base, fov_rad=math.radians(90)),
                replace(base, min_range_m=0.1, fov_rad=math.radians(120))):
        part = simulate(cfg, np.random.default_rng(5))
        dropped = 0
        for a, b in zip(full.steps, part.steps):
            assert np.array_equal(a.odom, b.odom) if a.odom is not None else b.odom is None
            keep = np.isin(a.landmark_ids, b.landmark_ids)
            assert np.array_equal(np.asarray(a.landmark_ids)[keep], b.landmark_ids)
            assert np.array_equal(np.asarray(a.bearings_rad)[keep], b.bearings_rad)
            dropped += int((~keep).sum())
        assert dropped > 0


def test_priors_exp3() -> None:
    assert n_prior_pairs(50, 0.1) == 123
    s = simulate_run(paper_design(0)[0], SimConfig(n_steps=3), prior_fraction=0.1)
    pri = s.header.priors
    assert len(pri) == 123
    assert len({(p.i, p.j) for p in pri}) == 123
    lm = s.truth.landmarks_xy
    err = np.array([p.distance_m - np.linalg.norm(lm[p.i] - lm[p.j]) for p in pri])
    assert np.all(np.abs(err) < 5 * 0.03 * 1.5)
    assert abs(err.std() - 0.03) < 0.01
    with pytest.raises(ConfigError):
        make_priors(s.truth, 0.0, 0.03, np.random.default_rng(0))


@pytest.mark.parametrize("kwargs", [dict(n_landmarks=0), dict(sensor_range_m=0),
                                    dict(step_min_m=0.3, step_max_m=0.2),
                                    dict(lookahead_m=0.1), dict(wrong_association_rate=2),
                                    # absurd sizes: refused, not allocated (session 12)
                                    dict(n_landmarks=10**9), dict(n_steps=10**9),
                                    dict(n_landmarks=10**400)])
def test_config_refuses_nonsense(kwargs: dict) -> None:
    with pytest.raises(ConfigError):
        SimConfig(**kwargs)


def test_priors_for_too_many_landmarks_are_refused_before_the_pairs_are_listed() -> None:
    # 20,000 landmarks: np.triu_indices would list 2e8 pairs (3 GiB) before drawing
    from bomgraph.stream import Truth

    n = 20_000
    truth = Truth(np.arange(n), np.zeros((n, 2)), None)
    with pytest.raises(ConfigError, match="pairs"):
        make_priors(truth, 0.01, 0.03, np.random.default_rng(0))


@pytest.mark.parametrize("kwargs,match", [
    ({"config": {"n_steps": 3}}, "config must be a SimConfig, got dict"),
    ({"rng": 0}, r"rng must be a numpy.random.Generator \(np.random.default_rng"),
    ({"rng": None}, "rng must be a numpy.random.Generator"),
    ({"landmarks_xy": np.zeros((2, 5))}, r"landmarks_xy must have shape \(n, 2\), got \(2, 5\)"),
    ({"start_pose": (1.0, 1.0)}, r"start_pose must be \(x_m, y_m, psi_rad\)"),
])
def test_simulate_refuses_wrong_arguments_by_name(kwargs: dict, match: str) -> None:
    """A dict config, an int seed for rng or a (2, N) layout ended in AttributeError or was
    reshaped into another layout."""
    args = {"config": SimConfig(n_steps=3), "rng": np.random.default_rng(0), **kwargs}
    config, rng = args.pop("config"), args.pop("rng")
    with pytest.raises(ConfigError, match=match):
        simulate(config, rng, **args)


@pytest.mark.parametrize("field", ["n_steps", "n_landmarks"])
@pytest.mark.parametrize("value", [2.5, 3.0, True])
def test_sim_config_counts_must_be_integers(field: str, value: object) -> None:
    with pytest.raises(ConfigError, match=f"{field} must be an integer"):
        SimConfig(**{field: value})
