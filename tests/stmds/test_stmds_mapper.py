"""BOM-STMDS end to end (paper III, Algorithm 1): exact recovery, localisation, robustness."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bomgraph.angles import angle_residual
from bomgraph.errors import ConfigError
from bomgraph.evaluate import score_estimate
from bomgraph.mapper import MapEstimate, create_mapper, run
from bomgraph.sim import SimConfig, paper_design, simulate, simulate_run
from bomgraph.stmds.mapper import StmdsConfig, StmdsMapper
from bomgraph.stream import Prior, Step, Stream, StreamHeader, Truth

METHODS = ["stmds-cs", "stmds-smacof", "stmds-cs-loc", "stmds-smacof-loc"]
# Every pair of landmarks is seen together (range 5 m in a 2.5 m arena): DMC-SPL completes
# nothing, so Method 1 is exact too.
ALL_IN_VIEW = SimConfig(noise_scale=0.0, n_landmarks=15, n_steps=60, sensor_range_m=5.0)


@pytest.fixture(scope="module")
def all_in_view() -> Stream:
    return simulate(ALL_IN_VIEW, np.random.default_rng(3))


@pytest.fixture(scope="module")
def paper_noise_free() -> Stream:
    return simulate(SimConfig(noise_scale=0.0, n_landmarks=30, n_steps=120),
                    np.random.default_rng(5))


@pytest.fixture(scope="module")
def noisy() -> Stream:
    return simulate(SimConfig(n_landmarks=25, n_steps=100), np.random.default_rng(6))


@pytest.mark.parametrize("name", METHODS)
def test_noise_free_map_and_poses_are_exact(name: str, all_in_view: Stream) -> None:
    est = run(create_mapper(name, all_in_view.header, smacof_from_t=20),
              all_in_view.steps).final
    score = score_estimate(est, all_in_view.truth)
    assert score.n_common == 15
    assert score.mpe_m < 1e-9
    if name.endswith("-loc"):
        assert est.poses is not None and len(est.poses) == 6
        np.testing.assert_array_equal(est.pose_t, np.arange(55, 61))
        assert score.robot_mean_m < 1e-9
        # headings: the MDS frame may be mirrored, the returned poses are not
        assert not score.alignment.reflected
        aligned = score.alignment.apply_poses(est.poses)
        err = angle_residual(aligned[:, 2], all_in_view.truth.poses[est.pose_t, 2])
        assert np.abs(err).max() < 1e-9
    else:
        assert est.poses is None


@pytest.mark.parametrize("name", ["stmds-smacof", "stmds-smacof-loc"])
def test_noise_free_smacof_is_exact_with_the_papers_sensor_range(
        name: str, paper_noise_free: Stream) -> None:
    est = run(create_mapper(name, paper_noise_free.header), paper_noise_free.steps).final
    score = score_estimate(est, paper_noise_free.truth)
    assert score.n_common >= 27
    assert score.mpe_m < 1e-9
    if est.poses is not None:
        assert score.robot_mean_m < 1e-9


def test_method_1_is_approximate_when_pairs_are_missing(paper_noise_free: Stream) -> None:
    # DMC-SPL overestimates the missing distances (paths are longer than chords)
    est = run(create_mapper("stmds-cs", paper_noise_free.header), paper_noise_free.steps).final
    assert 1e-6 < score_estimate(est, paper_noise_free.truth).mpe_m < 0.05


def _relabel(stream: Stream, perm: np.ndarray) -> Stream:
    steps = tuple(Step(s.t, s.odom, perm[s.landmark_ids], s.bearings_rad) for s in stream.steps)
    truth = Truth(perm[stream.truth.landmark_ids], stream.truth.landmarks_xy,
                  stream.truth.poses)
    return Stream(stream.header, steps, truth)


@pytest.mark.parametrize("name", ["stmds-cs", "stmds-smacof", "stmds-smacof-loc"])
def test_map_is_invariant_under_relabelling(name: str, noisy: Stream) -> None:
    perm = np.random.default_rng(9).permutation(1000)[:25] * 3 + 11
    a = run(create_mapper(name, noisy.header), noisy.steps).final
    b = run(create_mapper(name, noisy.header), _relabel(noisy, perm).steps).final
    np.testing.assert_array_equal(np.sort(perm[a.landmark_ids]), b.landmark_ids)
    xa = a.landmarks_xy[np.argsort(perm[a.landmark_ids])]
    al = score_estimate(MapEstimate(np.arange(len(xa)), xa),
                        Truth(np.arange(len(xa)), b.landmarks_xy)).alignment
    np.testing.assert_allclose(al.apply(xa), b.landmarks_xy, atol=1e-9)
    if a.poses is not None:
        np.testing.assert_allclose(al.apply(a.poses[:, :2]), b.poses[:, :2], atol=1e-9)


def test_estimate_never_raises_before_data_or_with_degenerate_input() -> None:
    header = StreamHeader(bearing_sigma_rad=0.05, odometry_sigma=(0.03, 0.0, 0.05),
                          sensor_range_m=1.0)
    for name in METHODS:
        m = create_mapper(name, header)
        est = m.estimate()
        assert len(est) == 0 and "reason" in est.info
        # a single landmark, seen twice
        m.step(Step(0, None, [7], [0.3]))
        m.step(Step(1, [0.1, 0.0, 0.0], [7], [0.5]))
        one = m.estimate()
        # no pair to fuse; localising jointly, the landmark and two poses make a triangle
        assert len(one) == (1 if name == "stmds-smacof-loc" else 0)
        # a step with no parallax at all: moving straight at landmarks dead ahead
        m.step(Step(2, [0.1, 0.0, 0.0], [7, 8, 9], [0.0, 0.0, math.pi]))
        m.step(Step(3, [0.1, 0.0, 0.0], [7, 8, 9], [0.0, 0.0, math.pi]))
        assert isinstance(m.estimate(), MapEstimate)
        # no odometry in the middle (a gap), an empty step
        m.step(Step(4, None, [7, 8], [0.1, 0.2]))
        m.step(Step(5, [0.1, 0.0, 0.0], [], []))
        assert isinstance(m.estimate(), MapEstimate)


def _two_clusters() -> Stream:
    """Two groups of landmarks 20 m apart, visited one after the other: two components."""
    rng = np.random.default_rng(11)
    a = rng.uniform(0, 2.0, size=(6, 2))
    b = rng.uniform(0, 2.0, size=(4, 2)) + [20.0, 0.0]
    lms = np.vstack([a, b])
    poses = []
    for centre in ([1.0, 1.0], [21.0, 1.0]):
        ang = np.linspace(0, 2 * np.pi, 16, endpoint=False)
        poses += [[centre[0] + 1.6 * np.cos(t), centre[1] + 1.6 * np.sin(t), t + np.pi / 2]
                  for t in ang]
    poses = np.array(poses)
    from bomgraph.geometry import between, bearings_to
    steps = []
    for t, p in enumerate(poses):
        d = np.linalg.norm(lms - p[:2], axis=1)
        seen = np.flatnonzero(d < 3.0)
        odom = None if t == 0 else between(poses[t - 1], p)
        steps.append(Step(t, odom, seen, bearings_to(p, lms[seen])))
    header = StreamHeader(bearing_sigma_rad=0.01, odometry_sigma=(0.01, 0.01, 0.01))
    return Stream(header, tuple(steps), Truth(np.arange(10), lms, poses))


@pytest.mark.parametrize("name", METHODS)
def test_a_disconnected_graph_maps_its_largest_component(name: str) -> None:
    stream = _two_clusters()
    est = run(create_mapper(name, stream.header, smacof_from_t=5), stream.steps).final
    np.testing.assert_array_equal(est.landmark_ids, np.arange(6))
    assert est.info["left_out"] == [6, 7, 8, 9]
    assert est.info["n_components"] >= 2
    assert score_estimate(est, stream.truth).mpe_m < 1e-9


def test_priors_from_the_header_are_used(noisy: Stream) -> None:
    truth = noisy.truth
    i, j = np.triu_indices(25, 1)
    d = np.linalg.norm(truth.landmarks_xy[i] - truth.landmarks_xy[j], axis=1)
    priors = tuple(Prior(int(a), int(b), float(c), 1e-4) for a, b, c in zip(i, j, d))
    header = StreamHeader(noisy.header.bearing_sigma_rad, noisy.header.odometry_sigma,
                          noisy.header.sensor_range_m, priors)
    with_p = Stream(header, noisy.steps, truth)
    # exact priors on every pair pin the map down (up to the prior sigma)
    for name in ("stmds-cs", "stmds-smacof"):
        est = run(create_mapper(name, with_p.header), with_p.steps).final
        assert score_estimate(est, truth).mpe_m < 1e-3
    m = create_mapper("stmds-smacof", header)
    assert m.estimate().info["n_known_pairs"] == 300   # priors count before any step


def test_priors_of_the_paper_experiment_run_end_to_end() -> None:
    cfg = SimConfig(n_steps=60)
    stream = simulate_run(paper_design(0)[3], cfg, prior_fraction=0.1)
    est = run(create_mapper("stmds-smacof", stream.header), stream.steps).final
    assert score_estimate(est, stream.truth).mpe_m < 0.3


def test_config_is_validated_and_options_are_checked() -> None:
    header = StreamHeader(bearing_sigma_rad=0.05, odometry_sigma=(0.03, 0.0, 0.05))
    with pytest.raises(ConfigError, match="fusion"):
        StmdsConfig(fusion="nope")
    with pytest.raises(ConfigError, match="unknown option"):
        create_mapper("stmds-smacof", header, not_an_option=1)
    m = create_mapper("stmds-cs", header, fusion="paper", n_robot_poses=4)
    assert isinstance(m, StmdsMapper)
    assert (m.config.method, m.config.fusion, m.config.localise) == ("cs", "paper", False)
    assert StmdsConfig().smacof_from_t == 50 and StmdsConfig().n_robot_poses == 6


@pytest.mark.parametrize("options", [
    {"fusion": "paper"}, {"fusion": "relative"},
    {"preset": "improved"},
    {"landmark_mds_above": 10, "n_pivots": 6},          # SMACOF started from landmark MDS
    {"weights": "inverse-variance", "smacof_init": "classical", "smacof_relaxation": 1.0,
     "smacof_max_iter": 3000},
])
def test_every_variant_is_exact_without_noise(options: dict, paper_noise_free: Stream) -> None:
    est = run(create_mapper("stmds-smacof", paper_noise_free.header, **options),
              paper_noise_free.steps).final
    assert score_estimate(est, paper_noise_free.truth).mpe_m < 1e-9


def test_window_triangulated_robot_ranges_are_exact_without_noise(all_in_view: Stream) -> None:
    est = run(create_mapper("stmds-cs-loc", all_in_view.header, robot_ranges="all-poses"),
              all_in_view.steps).final
    score = score_estimate(est, all_in_view.truth)
    assert score.mpe_m < 1e-9 and score.robot_mean_m < 1e-9


def test_presets_and_the_improved_config() -> None:
    header = StreamHeader(bearing_sigma_rad=0.05, odometry_sigma=(0.03, 0.0, 0.05))
    m = create_mapper("stmds-smacof", header, preset="improved", n_robot_poses=5)
    assert m.config == StmdsConfig.preset("improved", n_robot_poses=5)
    assert m.config.baseline_steps == (4,) and m.config.fusion == "relative"
    with pytest.raises(ConfigError, match="preset"):
        create_mapper("stmds-smacof", header, preset="fast")
    with pytest.raises(ConfigError, match="baseline_steps"):
        StmdsConfig(baseline_steps=(0,))


def test_landmarks_held_only_by_priors_are_left_out_unless_asked(noisy: Stream) -> None:
    xy = {int(i): p for i, p in zip(noisy.truth.landmark_ids, noisy.truth.landmarks_xy)}
    ghost = np.array([1.2, 1.3])                      # never observed
    priors = tuple(Prior(999, i, float(np.linalg.norm(ghost - xy[i])), 0.01) for i in (0, 1, 2, 3))
    header = StreamHeader(noisy.header.bearing_sigma_rad, noisy.header.odometry_sigma,
                          noisy.header.sensor_range_m, priors)
    default = run(create_mapper("stmds-smacof", header), noisy.steps).final
    assert 999 not in default.landmark_ids
    both = run(create_mapper("stmds-smacof", header, map_unobserved=True), noisy.steps).final
    assert 999 in both.landmark_ids
