"""``baselines.seeding`` (h123, review of h122): what ``align_seed`` and ``seed_start`` raise
when a map cannot start the poses, and that a ``SeedStart`` hands out new values, never the
graph's."""

from __future__ import annotations

from collections.abc import Callable

import gtsam
import numpy as np
import pytest

from baselines import gtsam_tools as gt
from baselines.bearing_graph import poses_from_values
from baselines.seeding import SeedAlignment
from baselines.triangulate import TriangulateMapper
from bomgraph.errors import ConfigError, TooFewLandmarksError
from bomgraph.mapper import MapEstimate, run
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream import Stream, Truth


@pytest.fixture(scope="module")
def noise_free() -> Stream:
    return simulate(SimConfig(n_steps=60, n_landmarks=20, noise_scale=0.0),
                    np.random.default_rng(3))


def _true_map(stream: Stream, ids_offset: int = 0, n: int | None = None) -> MapEstimate:
    truth = stream.truth
    return MapEstimate(truth.landmark_ids[:n] + ids_offset, truth.landmarks_xy[:n])


def test_a_map_of_two_landmarks_cannot_be_aligned(noise_free: Stream) -> None:
    state = gt.build_graph(noise_free.header, noise_free.steps)
    for call in (gt.align_seed, gt.seed_start):
        with pytest.raises(TooFewLandmarksError) as err:
            call(state, _true_map(noise_free, n=2))
        assert str(err.value) == (
            "align_seed: fewer than 3 of the map's 2 landmarks (2 of them seen in the stream) "
            "intersect with min_parallax_rad = 0.3 on the dead-reckoned poses of the 61 "
            "steps, so the map cannot be "
            "aligned: give more steps or a map holding more of the landmarks the stream sees "
            "(by the stream's landmark ids)")


def test_a_map_the_stream_sees_on_too_short_a_stream_is_told_its_remedies(
        noise_free: Stream) -> None:
    """h166: align_seed's other branch (3 or more of the map's landmarks seen, none
    intersecting): more steps, or the poses of a map in the graph's frame; "1 step" (was
    "1 steps")."""
    state = gt.build_graph(noise_free.header, noise_free.steps[:1])
    with pytest.raises(TooFewLandmarksError) as err:
        gt.align_seed(state, _true_map(noise_free))
    assert str(err.value) == (
        "align_seed: fewer than 3 of the map's 20 landmarks (8 of them seen in the stream) "
        "intersect with min_parallax_rad = 0.3 on the dead-reckoned poses of the 1 step, so "
        "the map cannot be aligned: give more steps, or, where the dead reckoning drifts (a "
        "recording), start the poses from a map that carries them in the graph's frame (pose "
        "0 at the start pose, as ekf's and gtsam-batch's maps do): insert_pose(state.values, "
        "t, pose, previous pose) for every step, state.absorb(), then seed_landmarks")
    assert "a map holding more" not in str(err.value)


def test_a_map_of_other_ids_is_told_so(noise_free: Stream) -> None:
    """The whole true map under other ids: not "more steps", none of them is the stream's."""
    state = gt.build_graph(noise_free.header, noise_free.steps)
    with pytest.raises(TooFewLandmarksError, match=r"^align_seed: fewer than 3 of the map's 20 "
                       r"landmarks \(0 of them seen in the stream\)") as err:
        gt.seed_start(state, _true_map(noise_free, ids_offset=1000))
    assert "\n" not in str(err.value)


def test_no_pose_seeing_three_landmarks_is_refused(noise_free: Stream) -> None:
    state = gt.build_graph(noise_free.header, noise_free.steps)
    al = gt.align_seed(state, _true_map(noise_free))
    assert al.n_reference == 20 and not al.in_solution_frame
    two = SeedAlignment(al.landmark_ids[:2], al.landmarks_xy[:2], al.alignment, False, 20)
    with pytest.raises(TooFewLandmarksError) as err:
        gt.seed_start(state, two)
    assert str(err.value) == (
        "seed_start: no pose sees 3 of the map's 2 landmarks, so none can be resected: give "
        "a map holding more of the landmarks the stream sees")


def test_seed_start_changes_nothing_in_the_graph_and_its_values_are_new(
        noise_free: Stream) -> None:
    state = gt.build_graph(noise_free.header, noise_free.steps)
    n_steps = len(noise_free.steps)
    ts = np.arange(n_steps)
    before_size, before = state.values.size(), poses_from_values(state.values, ts)
    start = gt.seed_start(state, _true_map(noise_free))
    assert state.values.size() == before_size
    np.testing.assert_array_equal(poses_from_values(state.values, ts), before)
    assert start.poses.shape == (n_steps, 3)
    assert start.landmarks_xy.shape == (start.landmark_ids.size, 2)
    np.testing.assert_allclose(start.poses[0], state.problem.start_pose, atol=1e-9)
    values = start.values()
    assert values is not start.values() and values is not state.values
    assert values.size() == 2 * n_steps - 1          # x_0..x_T-1 and m_1..m_T-1, no landmark
    np.testing.assert_allclose(poses_from_values(values, ts), start.poses, atol=1e-12)
    state.values.update(values)                      # the README's recipe
    moved = values.atPose2(gt.pose_key(5)).compose(gtsam.Pose2(1.0, 0.0, 0.0))
    values.update(gt.pose_key(5), moved)             # changing the copy leaves the graph
    np.testing.assert_allclose(poses_from_values(state.values, ts), start.poses, atol=1e-12)


def test_alignment_options_with_an_aligned_map_are_refused(noise_free: Stream) -> None:
    """h125: ``use_solution``, ``align_steps`` and ``trim`` only steer ``align_seed``; given
    with a ``SeedAlignment`` they were silently ignored, now they are refused."""
    state = gt.build_graph(noise_free.header, noise_free.steps)
    al = gt.align_seed(state, _true_map(noise_free))
    for given in ({"trim": 1.5}, {"use_solution": False}, {"align_steps": 10, "trim": 3.0}):
        with pytest.raises(ConfigError) as err:
            gt.seed_start(state, al, **given)
        assert str(err.value) == (
            f"seed_start: {', '.join(given)} given with a SeedAlignment, which is aligned "
            f"already (they apply only when seed_start aligns a MapEstimate itself): pass "
            f"them to the align_seed call that made it, or pass the MapEstimate instead")
    np.testing.assert_array_equal(gt.seed_start(state, al).poses,
                                  gt.seed_start(state, _true_map(noise_free)).poses)


def test_alignment_options_with_a_map_reach_align_seed(noise_free: Stream) -> None:
    """With a ``MapEstimate`` they are ``align_seed``'s: the start is the one from the
    alignment made with them."""
    state = gt.build_graph(noise_free.header, noise_free.steps)
    est = _true_map(noise_free)
    start = gt.seed_start(state, est, align_steps=5, trim=1.0)
    asked = gt.align_seed(state, est, align_steps=5, trim=1.0)
    np.testing.assert_array_equal(start.aligned.landmarks_xy, asked.landmarks_xy)
    assert start.aligned.n_reference == asked.n_reference < gt.align_seed(state, est).n_reference


def _map_calls(state: gt.BatchState) -> dict[str, Callable[[object], object]]:
    """Each helper that takes a map, called with ``state`` (align_map on 3 made-up
    reference landmarks)."""
    return {"seed_start": lambda m: gt.seed_start(state, m),
            "align_seed": lambda m: gt.align_seed(state, m),
            "seed_landmarks": lambda m: gt.seed_landmarks(state, m),
            "align_map": lambda m: gt.align_map(m, np.arange(3), np.zeros((3, 2)))}


def test_a_run_result_for_the_map_is_told_to_give_final(noise_free: Stream) -> None:
    """h125: the README's map is ``run(...).final``; the ``RunResult`` itself, given to any
    helper that takes a map, raised ``AttributeError: 'RunResult' object has no attribute
    'landmark_ids'`` deep inside. Each now refuses it where it enters."""
    result = run(TriangulateMapper(noise_free.header), noise_free.steps)
    state = gt.build_graph(noise_free.header, noise_free.steps)
    for name, call in _map_calls(state).items():
        with pytest.raises(ConfigError) as err:
            call(result)
        assert str(err.value) == (f"{name}(): the map must be a MapEstimate, got RunResult "
                                  f"(result.final or result.at(t))")
    gt.seed_start(state, result.final)                 # what it should have been


def test_a_truth_for_the_map_too_far_off_is_told_so_not_a_type_error(noise_free: Stream) -> None:
    """h129: ``check_map`` admits any map with ``landmark_ids`` and ``landmarks_xy`` (a
    ``Truth`` too), but the refusals counted the map with ``len(map)``: a ``Truth`` of other
    ids raised ``TypeError: object of type 'Truth' has no len()`` instead of saying why."""
    state = gt.build_graph(noise_free.header, noise_free.steps)
    far = Truth(noise_free.truth.landmark_ids + 1000, noise_free.truth.landmarks_xy)
    for name, call in _map_calls(state).items():
        with pytest.raises(TooFewLandmarksError) as err:
            call(far)
        said = "align_seed" if name == "seed_start" else name     # seed_start aligns first
        assert str(err.value).startswith(f"{said}: ") and "20" in str(err.value)
    assert gt.seed_start(state, noise_free.truth).poses.shape == (61, 3)   # a Truth serves
