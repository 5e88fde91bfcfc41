"""Tests of the public GTSAM helpers (baselines/gtsam_tools.py): the same objects as the
baselines', the graph of a stream, map alignment and seeding, the diagnosis that names what
is unconstrained, and the checked solve."""

from __future__ import annotations

import math
import tracemalloc

import gtsam
import numpy as np
import pytest

from baselines import (bearing_graph, factor_graph, gtsam_tools as gt, hybrid, resection,
                       seeding)
from bomgraph.errors import ConfigError, TooFewLandmarksError
from bomgraph.geometry import dead_reckon
from bomgraph.evaluate import score_estimate
from bomgraph.mapper import MapEstimate, create_mapper, run
from bomgraph.sim import SimConfig, paper_design, simulate, simulate_run
from bomgraph.stream import Stream


@pytest.fixture(scope="module")
def noise_free() -> Stream:
    return simulate(SimConfig(n_steps=60, n_landmarks=20, noise_scale=0.0),
                    np.random.default_rng(3))


@pytest.fixture(scope="module")
def noisy() -> Stream:
    return simulate(SimConfig(n_steps=60, n_landmarks=25), np.random.default_rng(4))


def _mirrored(stream: Stream) -> MapEstimate:
    """The true map mirrored, turned by 2 rad and shifted (as an MDS map may come)."""
    c, s = math.cos(2.0), math.sin(2.0)
    xy = (stream.truth.landmarks_xy * [1.0, -1.0]) @ np.array([[c, -s], [s, c]]).T + [3, 1]
    return MapEstimate(stream.truth.landmark_ids, xy)


def test_the_helpers_are_the_baselines_own_objects() -> None:
    assert gt.solve_lm is factor_graph.solve_lm and gt.SolveReport is factor_graph.SolveReport
    assert gt.BatchState is factor_graph.BatchState
    assert gt.BearingGraph is bearing_graph.BearingGraph
    assert gt.resect_trajectory is resection.resect_trajectory
    assert gt.resect_pose is resection.resect_pose
    assert gt.odometry_factors is bearing_graph.odometry_factors
    assert gt.trimmed_align is hybrid.trimmed_align
    assert gt.seed_start is hybrid.seed_start is seeding.seed_start   # the hybrid's own
    assert set(gt.__all__) <= set(dir(gt))


def test_build_graph_holds_every_factor(noisy: Stream) -> None:
    state = gt.build_graph(noisy.header, noisy.steps)
    p = state.problem
    n_steps = len(noisy.steps)
    assert p.n_steps == n_steps and p.landmark_ids
    assert state.graph.size() == 1 + 2 * (n_steps - 1) + p.n_bearing_factors
    assert state.values.size() == 2 * n_steps - 1 + len(p.landmark_ids)
    held = gt.build_graph(noisy.header, noisy.steps, admit=False)
    assert held.problem.landmark_ids == [] and held.problem.pending()


def test_align_map_undoes_a_mirror_exactly(noise_free: Stream) -> None:
    ids, xy = noise_free.truth.landmark_ids, noise_free.truth.landmarks_xy
    aligned = gt.align_map(_mirrored(noise_free), ids[:5], xy[:5])
    assert aligned.alignment.reflected and aligned.n_common == 5
    np.testing.assert_allclose(aligned.landmarks_xy, xy, atol=1e-12)
    with pytest.raises(TooFewLandmarksError, match="3 are needed"):
        gt.align_map(_mirrored(noise_free), ids[:2], xy[:2])


def test_seeding_from_a_mirrored_map_recovers_the_truth(noise_free: Stream) -> None:
    state = gt.build_graph(noise_free.header, noise_free.steps,
                           start_pose=noise_free.truth.poses[0])
    before = len(state.problem.landmark_ids)
    seed = gt.seed_landmarks(state, _mirrored(noise_free))
    assert seed.alignment.reflected and len(state.problem.landmark_ids) >= before
    values, report = gt.checked_solve(state.graph, state.values, state.config)
    assert report.converged
    score = score_estimate(state.to_estimate(values, report.as_info()), noise_free.truth)
    assert score.max_m < 1e-6


def test_seeding_a_graph_without_landmarks_says_what_to_do(noise_free: Stream) -> None:
    """On MRCLAM6 robot 3 the dead-reckoned rays of the whole run admit no landmark, and the
    README's recipe (build_graph, seed_landmarks) raised "admit more landmarks to the graph
    first", which build_graph(admit=True) had tried (h20): the message now counts the graph's
    and the pending landmarks and names the hybrid, which aligns and resects for you."""
    state = gt.build_graph(noise_free.header, noise_free.steps, admit=False)
    with pytest.raises(TooFewLandmarksError) as err:
        gt.seed_landmarks(state, _mirrored(noise_free))
    text = str(err.value)
    assert text.startswith("seed_landmarks: the graph holds 0 landmarks, 0 of them in the map")
    assert f"{len(state.problem.pending())} landmarks are pending" in text
    assert "state.values.update(seed_start(state, map).values()); state.absorb()" in text


def test_seeding_says_whether_letting_landmarks_in_would_help(noise_free: Stream) -> None:
    """h89: the message told to "build the graph with admit=True" also to a graph built so
    (build_graph's default), whose rays on the dead-reckoned poses intersect nowhere, as on
    MRCLAM6 robot 3 with the README's recipe. It now says which of the two it is."""
    drifting = simulate(SimConfig(n_steps=60, n_landmarks=20, noise_scale=10.0),
                        np.random.default_rng(3))
    state = gt.build_graph(drifting.header, drifting.steps)
    assert state.problem.landmark_ids == [] and state.problem.pending()
    with pytest.raises(TooFewLandmarksError) as err:
        gt.seed_landmarks(state, _mirrored(drifting))
    text = str(err.value)
    assert "admit=True" not in text and "let them in first" not in text
    assert "their rays on the graph's poses do not intersect" in text
    # h118, h122: a hybrid of one's own needs the public route too (11 of the 25 paper runs)
    assert "state.values.update(seed_start(state, map).values()); state.absorb()" in text
    held = gt.build_graph(noise_free.header, noise_free.steps, admit=False)
    n_in = len(gt.build_graph(noise_free.header, noise_free.steps).problem.landmark_ids)
    with pytest.raises(TooFewLandmarksError) as err:
        gt.seed_landmarks(held, _mirrored(noise_free))
    assert f"{n_in} of them intersect on the graph's poses: let them in first" in str(err.value)


def test_seeding_with_a_map_of_other_landmarks_says_so(noise_free: Stream) -> None:
    """h94: a graph holding the stream's landmarks and a map of other ones (its ids not the
    stream's) was told its pending rays "do not intersect (as on a drifting recording's
    dead-reckoned poses)" and sent to the hybrid, on a noise-free stream; it is the map."""
    state = gt.build_graph(noise_free.header, noise_free.steps)
    n_in = len(state.problem.landmark_ids)
    assert n_in >= 3
    other = _mirrored(noise_free)
    other = MapEstimate(np.asarray(other.landmark_ids) + 1000, other.landmarks_xy)
    with pytest.raises(TooFewLandmarksError) as err:
        gt.seed_landmarks(state, other)
    text = str(err.value)
    assert f"the graph holds {n_in} landmarks, 0 of them in the map ({len(other)})" in text
    assert "the map's landmark ids are not the stream's" in text
    assert "drifting" not in text and "HybridMapper" not in text


def test_diagnose_a_good_graph(noisy: Stream) -> None:
    state = gt.build_graph(noisy.header, noisy.steps[:30])
    d = gt.diagnose(state.graph, state.values)
    assert d.ok and d.rank == d.n_columns and "graph determined" in d.summary()


def test_diagnose_names_a_landmark_seen_once(noisy: Stream) -> None:
    state = gt.build_graph(noisy.header, noisy.steps[:10])
    state.values.insert(gt.landmark_key(999), gtsam.Point2(0.5, 0.5))
    state.graph.add(gtsam.BearingFactor2D(gt.pose_key(3), gt.landmark_key(999),
                                          gtsam.Rot2(0.2),
                                          gtsam.noiseModel.Isotropic.Sigma(1, 0.05)))
    d = gt.diagnose(state.graph, state.values)
    assert not d.ok
    assert d.weak_landmarks["l999"] == "1 bearing" and d.null_variables == ["l999"]
    assert d.rank == d.n_columns - 1 and "l999" in d.elimination_error
    with pytest.raises(gt.UnconstrainedGraphError, match="l999 \\(1 bearing\\)") as exc:
        gt.checked_solve(state.graph, state.values, state.config)
    assert exc.value.diagnosis.weak_landmarks == d.weak_landmarks


def test_diagnose_names_parallel_rays_poses_without_prior_and_missing_values(
        noisy: Stream) -> None:
    state = gt.build_graph(noisy.header, noisy.steps[:10])
    noise = gtsam.noiseModel.Isotropic.Sigma(1, 0.05)
    state.values.insert(gt.landmark_key(998), gtsam.Point2(1.0, 0.0))
    for t in (1, 2):   # two rays from near-by poses at the same bearing: nearly parallel
        state.graph.add(gtsam.BearingFactor2D(gt.pose_key(t), gt.landmark_key(998),
                                              gtsam.Rot2(0.0), noise))
    d = gt.diagnose(state.graph, state.values)
    assert d.weak_landmarks["l998"].startswith("rays span")
    # a graph without its prior on x0 can slide: every pose is named
    floating = gtsam.NonlinearFactorGraph()
    for i in range(1, state.graph.size()):
        floating.add(state.graph.at(i))
    d2 = gt.diagnose(floating, state.values)
    assert "x0" in d2.unanchored and "x9" in d2.unanchored and not d2.ok
    # a factor on a key without a value
    state.graph.add(gtsam.BearingFactor2D(gt.pose_key(4), gt.landmark_key(997),
                                          gtsam.Rot2(0.0), noise))
    d3 = gt.diagnose(state.graph, state.values)
    assert d3.missing_values == ["l997"] and "no initial value for l997" in d3.summary()


def test_diagnose_holds_no_rows_by_rows_matrix() -> None:
    """The rank check needs the right singular vectors only: a full SVD of a tall Jacobian
    (a row per bearing) also made the rows x rows U, 250 MB and 10 s CPU at 200 steps of a
    paper run seeded with its EKF map (5583 x 1297; h118), 30 times the LM solve."""
    stream = simulate(SimConfig(n_steps=20, n_landmarks=200, noise_scale=0.0),
                      np.random.default_rng(0))
    state = gt.build_graph(stream.header, stream.steps)
    a = state.graph.linearize(state.values).jacobian()[0]
    rows, cols = a.shape
    assert rows > 4 * cols

    def peak_of(f) -> int:
        tracemalloc.start()
        try:
            f()
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    # against a full SVD of the same matrix in the same process, not a fixed bound: numpy's
    # LAPACK workspace differs between versions (the thin SVD alone, 1646 x 400: 6.6 MB
    # traced with numpy 2.4, 23.5 MB with 2.5; the full one 23.0 and 56.4 MB)
    full = peak_of(lambda: np.linalg.svd(a, full_matrices=True))
    diagnosis: list = []
    peak = peak_of(lambda: diagnosis.append(gt.diagnose(state.graph, state.values)))
    [d] = diagnosis
    assert d.ok and d.rank == d.n_columns == cols
    assert peak < full, (peak, full)


def test_diagnose_a_wide_jacobian_names_its_free_variables() -> None:
    """Fewer rows than columns (one odometry factor, no prior): the null space is the
    complement of the row space, which only the full V holds."""
    graph = gtsam.NonlinearFactorGraph()
    graph.add(gtsam.BetweenFactorPose2(gt.pose_key(0), gt.pose_key(1), gtsam.Pose2(1, 0, 0),
                                       gtsam.noiseModel.Isotropic.Sigma(3, 0.1)))
    values = gtsam.Values()
    gt.insert_pose(values, 0, np.zeros(3), None)
    values.insert(gt.pose_key(1), gtsam.Pose2(1.0, 0.0, 0.0))
    d = gt.diagnose(graph, values)
    assert (d.rank, d.n_columns) == (3, 6)
    assert d.null_variables == ["x0", "x1"] and d.unanchored == ["x0", "x1"] and not d.ok


def test_the_array_helpers_say_which_convention_they_want(noisy: Stream) -> None:
    """h118: dead_reckon takes the T-1 increments, resect_trajectory one odometry row per step
    (row 0 unused); given the former it said "resect_poses: owner indices must lie in 0 ..
    n_poses-1", a function the caller never called. A map as columns (2, n) and bearings of
    steps beyond the poses given to triangulate_landmarks were IndexErrors."""
    state = gt.build_graph(noisy.header, noisy.steps)
    owner, lid, brg = state.bearings()
    odoms = np.array([np.zeros(3) if s.odom is None else s.odom for s in noisy.steps])
    sig = np.array([s.odometry_sigma(noisy.header) for s in noisy.steps])
    truth = noisy.truth
    args = (owner, lid, brg, noisy.header.bearing_sigma_rad, truth.landmark_ids)
    n = len(noisy.steps)
    with pytest.raises(ConfigError, match=f"step {n - 1} but odoms has {n - 1} rows: give one "
                                          f"row per step 0 .. T-1, row 0 unused .*prepend"):
        gt.resect_trajectory(*args, truth.landmarks_xy, odoms[1:], sig[1:])
    with pytest.raises(ConfigError, match=r"map_xy must have shape \(n, 2\), got \(2, 25\); "
                                          r"transpose it"):
        gt.resect_trajectory(*args, truth.landmarks_xy.T, odoms, sig)
    with pytest.raises(ConfigError, match="odometry_sigma must have the shape of odoms"):
        gt.resect_trajectory(*args, truth.landmarks_xy, odoms, sig[1:])
    poses = gt.resect_trajectory(*args, truth.landmarks_xy, odoms, sig)
    assert poses.shape == (n, 3)
    dr = dead_reckon(odoms[1:])
    with pytest.raises(ConfigError, match=rf"bearings of steps 0 .. {n - 1} but poses has 30 "
                                          r"rows \(steps 0 .. 29\)"):
        gt.triangulate_landmarks(dr[:30], owner, lid, brg, truth.landmark_ids, 0.3)
    j = owner < 30
    ids, xy = gt.triangulate_landmarks(dr[:30], owner[j], lid[j], brg[j], truth.landmark_ids,
                                       0.3)
    assert ids.size and xy.shape == (ids.size, 2)


def test_seed_start_recovers_the_true_poses_from_a_mirrored_map(noise_free: Stream) -> None:
    """h122: on a noise-free stream, a map mirrored, turned and shifted gives the true poses
    (the graph's frame is the truth's when its start pose is the true first pose)."""
    truth = noise_free.truth
    state = gt.build_graph(noise_free.header, noise_free.steps, start_pose=truth.poses[0])
    start = gt.seed_start(state, _mirrored(noise_free))
    assert start.reflected and start.poses.shape == (len(noise_free.steps), 3)
    np.testing.assert_allclose(start.poses[:, :2], truth.poses[:, :2], atol=1e-6)
    np.testing.assert_allclose(np.angle(np.exp(1j * (start.poses[:, 2] - truth.poses[:, 2]))),
                               0.0, atol=1e-6)
    _, i_s, i_t = np.intersect1d(start.landmark_ids, truth.landmark_ids, return_indices=True)
    np.testing.assert_allclose(start.landmarks_xy[i_s], truth.landmarks_xy[i_t], atol=1e-6)
    assert start.values().size() == 2 * len(noise_free.steps) - 1


def test_the_recipe_with_seed_start_maps_a_paper_run_seed_landmarks_alone_cannot() -> None:
    """h122: on run 0 of paper_design(0) (300 steps) the dead-reckoned rays admit fewer than 3
    landmarks and seed_landmarks raises; the README's one call, seed_start (the hybrid's
    seeding), starts the poses so that the recipe maps the run."""
    stream = simulate_run(paper_design(0)[0])
    stmds_map = run(create_mapper("stmds-smacof", stream.header), stream.steps).final
    state = gt.build_graph(stream.header, stream.steps)
    with pytest.raises(TooFewLandmarksError):
        gt.seed_landmarks(state, stmds_map)
    state.values.update(gt.seed_start(state, stmds_map).values())
    state.absorb()
    gt.seed_landmarks(state, stmds_map)
    values, report = gt.checked_solve(state.graph, state.values, state.config)
    estimate = state.to_estimate(values, report.as_info())
    assert report.converged and len(estimate) >= 3
    assert score_estimate(estimate, stream.truth).mpe_m < 0.1


def test_on_a_recording_the_map_s_own_poses_start_the_graph_seed_start_cannot() -> None:
    """h163: on MRCLAM6 robot 3 no 3 of the 15 landmarks intersect on the dead-reckoned poses
    of all 160 steps, so seed_start (the README's remedy) raises too; its message told to give
    "a map holding more of the landmarks" though the ekf map holds all 15. It now names the
    parallax threshold and the remedy that works: the poses of a map in the graph's frame."""
    from tests._cadence_streams import mrclam6_robot3

    stream = mrclam6_robot3()
    ekf = run(create_mapper("ekf", stream.header, preset="real"), stream.steps).final
    state = gt.build_graph(stream.header, stream.steps)
    with pytest.raises(TooFewLandmarksError) as err:
        gt.seed_start(state, ekf)
    message = str(err.value)
    assert "(15 of them seen in the stream)" in message and "min_parallax_rad = 0.3" in message
    assert "a map holding more" not in message and "insert_pose(state.values, t," in message
    previous = None
    for t, pose in zip(ekf.pose_t, ekf.poses):
        gt.insert_pose(state.values, int(t), pose, previous)
        previous = pose
    state.absorb()
    assert gt.seed_landmarks(state, ekf).n_common >= 3
    values, report = gt.checked_solve(state.graph, state.values, state.config)
    assert report.converged
    assert score_estimate(state.to_estimate(values, report.as_info()), stream.truth).mpe_m < 0.1


def test_isam2_params_are_the_ones_gtsam_isam2_runs_with(noisy: Stream) -> None:
    """h163: with plain ``gtsam.ISAM2Params()`` an incremental hybrid mapped sim7 at 8.3 m;
    the mapper's settings were private (``Isam2Mapper._new_isam``)."""
    from baselines.isam2 import Isam2Config, Isam2Mapper

    for cfg in (gt.FactorGraphConfig(), gt.FactorGraphConfig.preset("robust"), Isam2Config(),
                Isam2Config.preset("real"), Isam2Config(isam2_optimizer="gauss-newton")):
        mapper = Isam2Mapper(noisy.header, config=cfg)
        for step in noisy.steps[:12]:
            mapper.step(step)
        mine = gt.isam2_params(cfg)
        assert str(mine) == str(mapper._isam.params())    # every field GTSAM prints
        assert mine.getFactorization() == mapper._isam.params().getFactorization()
        assert f"relinearizeThreshold:              {mapper.config.relinearize_threshold:g}" \
            in str(mine)
        mapper._long = True                                # long mode's solver
        assert str(gt.isam2_params(cfg, long=True)) == str(mapper._new_isam().params())
    assert "ISAM2DoglegParams" in str(gt.isam2_params(gt.FactorGraphConfig()))
    assert str(gt.isam2_params()) == str(gt.isam2_params(Isam2Config()))   # paper
    assert str(gt.isam2_params()) != str(gtsam.ISAM2Params())
    with pytest.raises(ConfigError, match="config= must be a Isam2Config, got dict"):
        gt.isam2_params({"relinearize_threshold": 0.1})   # type: ignore[arg-type]


def test_a_bearing_graph_gives_its_bearings_as_batch_state_does(noisy: Stream) -> None:
    """An incremental method holds a BearingGraph, not a BatchState: the same arrays."""
    graph = gt.BearingGraph(noisy.header, gt.FactorGraphConfig(), np.zeros(3))
    owner, ids, brg = graph.bearings()
    assert owner.shape == ids.shape == brg.shape == (0,)
    for step in noisy.steps:
        graph.add_step(step)
    state = gt.build_graph(noisy.header, noisy.steps)
    mine, theirs = graph.bearings(), state.bearings()
    assert [a.dtype for a in mine] == [np.int64, np.int64, np.float64]
    for a, b in zip(mine, theirs):
        assert a.shape == b.shape and np.array_equal(a, b)
    every = [(s.t, i, b) for s in noisy.steps
             for i, b in zip(s.landmark_ids.tolist(), s.bearings_rad.tolist())]
    assert list(zip(*(a.tolist() for a in mine))) == every
    assert graph.pending() and graph.landmark_ids == []   # pending ones' bearings too


def test_estimate_from_values_names_its_two_graphs(noisy: Stream) -> None:
    """``graph`` was the BearingGraph and ``solved`` the factor graph: named for what they are."""
    import inspect

    names = list(inspect.signature(gt.estimate_from_values).parameters)
    assert names == ["bearing_graph", "values", "factors", "info", "covariances"]
    state = gt.build_graph(noisy.header, noisy.steps)
    est = gt.estimate_from_values(bearing_graph=state.problem, values=state.values,
                                  factors=state.graph)
    assert est.info["n_factors"] == state.graph.size()
    assert len(est) == len(state.problem.landmark_ids)
    assert est.landmark_cov is None
