"""Pose errors and alignment choices (issue 17 point 4, issue 13 item 9): a trajectory fit
against an independent Umeyama, RPE by hand, collinear landmarks, overflow-safe scaling."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bomgraph.evaluate import align, align_candidates, score_estimate
from bomgraph.mapper import MapEstimate
from bomgraph.stream import Step, Truth
from bomgraph.trajectory import (absolute_pose_errors, bearing_residuals,
                                 relative_pose_errors)


def _umeyama(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Independent: least-squares rotation (reflection allowed) by brute force over angles
    and both handednesses, refined in closed form per handedness."""
    ms, md = src.mean(0), dst.mean(0)
    a, b = src - ms, dst - md
    best = None
    for flip in (np.eye(2), np.diag([1.0, -1.0])):
        af = a @ flip.T
        # minimise sum |R(th) af - b|^2 -> th = atan2(sum cross, sum dot)
        th = math.atan2(float(np.sum(af[:, 0] * b[:, 1] - af[:, 1] * b[:, 0])),
                        float(np.sum(af[:, 0] * b[:, 0] + af[:, 1] * b[:, 1])))
        r = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]]) @ flip
        cost = float(np.sum((a @ r.T - b) ** 2))
        if best is None or cost < best[0]:
            best = (cost, r)
    r = best[1]
    return r, md - r @ ms


def _world(seed: int = 1):
    rng = np.random.default_rng(seed)
    poses = np.column_stack([np.cumsum(rng.uniform(0, 0.2, 30)), np.cumsum(rng.normal(0, .1, 30)),
                             rng.uniform(-3, 3, 30)])
    truth = Truth(np.arange(12), rng.uniform(0, 3, (12, 2)), poses)
    return rng, truth


def test_trajectory_alignment_equals_an_independent_umeyama_on_the_poses() -> None:
    rng, truth = _world()
    est_poses = truth.poses + rng.normal(0, 0.05, truth.poses.shape)
    est = MapEstimate(truth.landmark_ids, truth.landmarks_xy + rng.normal(0, .1, (12, 2)),
                      pose_t=np.arange(30), poses=est_poses * [1, -1, -1] + [1, 2, 0])
    s = score_estimate(est, truth, align_on="trajectory")
    r, t = _umeyama(est.poses[:, :2], truth.poses[:, :2])
    np.testing.assert_allclose(s.alignment.rotation, r, atol=1e-10)
    np.testing.assert_allclose(s.alignment.translation, t, atol=1e-10)
    moved = est.poses[:, :2] @ r.T + t
    err = np.hypot(*(moved - truth.poses[:, :2]).T)
    assert s.ape_trans_rmse_m == pytest.approx(np.sqrt(np.mean(err ** 2)), rel=1e-10)
    assert s.robot_mean_m == pytest.approx(err.mean(), rel=1e-10)
    # a landmark fit differs, and "both" lies between the two in position error
    s_lm = score_estimate(est, truth, align_on="landmarks")
    s_both = score_estimate(est, truth, align_on="both")
    assert s.ape_trans_rmse_m < s_both.ape_trans_rmse_m < s_lm.ape_trans_rmse_m
    assert (s.align_on, s_both.align_on, s_lm.align_on) == ("trajectory", "both", "landmarks")


def test_both_without_poses_is_a_landmark_fit_and_says_so() -> None:
    """An estimate without poses has nothing but its landmarks to fit under ``"both"``: the
    score was labelled "aligned on both" over a landmark fit."""
    rng, truth = _world()
    est = MapEstimate(truth.landmark_ids, truth.landmarks_xy + rng.normal(0, .1, (12, 2)))
    s_both = score_estimate(est, truth, align_on="both")
    s_lm = score_estimate(est, truth, align_on="landmarks")
    assert s_both.align_on == "landmarks"
    np.testing.assert_array_equal(s_both.errors_m, s_lm.errors_m)


def test_rpe_equals_a_hand_computation_on_five_poses() -> None:
    truth = np.array([[0, 0, 0], [1, 0, 0], [1, 1, np.pi / 2], [0, 1, np.pi], [0, 0, 0]], float)
    est = truth.copy()
    est[2] = [1.1, 1.0, np.pi / 2 + 0.1]   # pose 2 off by 0.1 m in x and 0.1 rad
    t = np.arange(5)
    r = relative_pose_errors(t, est, truth, delta=1)
    # pair 0-1: exact. pair 1-2: true motion (0, 1, pi/2) from (1,0,0); estimated
    # (0.1, 1, pi/2 + 0.1): E = between(true, est) = R(-pi/2) (0.1, 0) , 0.1 = (0, -0.1, 0.1)
    # pair 2-3: true motion from (1,1,pi/2) to (0,1,pi): (0, 1, pi/2); estimated from
    # (1.1,1,pi/2+.1) to (0,1,pi): local = R(-(pi/2+.1)) (-1.1, 0) ,  pi/2 - 0.1
    c, s_ = math.cos(np.pi / 2 + 0.1), math.sin(np.pi / 2 + 0.1)
    loc = np.array([c * -1.1, -s_ * -1.1])
    e23 = np.array([loc[0] - 0.0, loc[1] - 1.0])    # between((0,1,pi/2), (loc, pi/2-.1)) rotated
    e23 = np.array([e23[1], -e23[0]])               # R(-pi/2) e
    np.testing.assert_array_equal(r.t, [0, 1, 2, 3])
    np.testing.assert_allclose(r.translation_m, [0, 0.1, np.hypot(*e23), 0], atol=1e-12)
    np.testing.assert_allclose(r.heading_rad, [0, 0.1, 0.1, 0], atol=1e-12)
    r2 = relative_pose_errors(t, est, truth, delta=2)
    np.testing.assert_array_equal(r2.t, [0, 1, 2])
    assert r2.translation_m[0] == pytest.approx(0.1) and r2.heading_rad[2] == pytest.approx(0.1)
    assert r2.translation_m[1] == pytest.approx(0.0, abs=1e-12)   # pose 2 skipped by 1-3
    # sparse steps: only pairs both present
    assert len(relative_pose_errors(np.array([0, 1, 3, 4, 6]), est, truth, 1)) == 2



@pytest.mark.parametrize("delta", [5, 2**63 - 1, 10**30])
def test_rpe_with_a_delta_beyond_the_run_has_no_pairs_and_no_overflow(delta: int) -> None:
    # `evaluate --delta 1000000000000000000000000000000` raised OverflowError (int64)
    poses = np.zeros((5, 3))
    r = relative_pose_errors(np.arange(5), poses, poses, delta=delta)
    assert len(r) == 0 and r.t.dtype == np.int64
    assert len(relative_pose_errors(np.zeros(0, int), poses[:0], poses[:0], delta=1)) == 0

@pytest.mark.parametrize("with_poses", [True, False])
def test_collinear_landmarks_pick_the_unmirrored_fit_with_poses(with_poses: bool) -> None:
    rng = np.random.default_rng(3)
    xs = np.linspace(0, 2, 8)
    lm = np.column_stack([xs, 0.5 * xs + 0.2])              # on a line
    poses = np.column_stack([rng.uniform(0, 2, 20), rng.uniform(1.5, 2.5, 20),
                             rng.uniform(-3, 3, 20)])       # all on one side of it
    truth = Truth(np.arange(8), lm, poses if with_poses else None)
    th = 0.7
    r = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    est = MapEstimate(np.arange(8), lm @ r.T + rng.normal(0, 0.01, lm.shape),
                      pose_t=np.arange(20),
                      poses=np.column_stack([poses[:, :2] @ r.T + rng.normal(0, .01, (20, 2)),
                                             poses[:, 2] + th]))
    cands = align_candidates(est.landmarks_xy, lm)
    assert len(cands) == 2 and cands[0].rank == 1
    assert cands[0].reflected != cands[1].reflected
    s = score_estimate(est, truth)
    assert s.mpe_m < 0.03
    if with_poses:
        assert not s.ambiguous and not s.alignment.reflected
        assert s.robot_mean_m < 0.05 and s.ape_heading_rmse_rad < 0.05
    else:
        assert math.isnan(s.robot_mean_m)


def test_collinear_tie_nothing_breaks_is_undefined_not_a_mirror() -> None:
    lm = np.column_stack([np.linspace(0, 2, 6), np.zeros(6)])
    poses = np.column_stack([np.linspace(0, 2, 5), np.zeros(5), np.zeros(5)])  # on the line, along it
    truth = Truth(np.arange(6), lm, poses)
    est = MapEstimate(np.arange(6), lm, pose_t=np.arange(5), poses=poses)
    s = score_estimate(est, truth)
    # the headings break it (the mirror across the x axis keeps heading 0 too): a tie
    assert s.ambiguous and math.isnan(s.robot_last_m) and s.mpe_m < 1e-12


@pytest.mark.parametrize("scale", [1e150, 1e154, 1e200, 1e250, 1e300])
def test_huge_coordinates_give_the_unscaled_alignment(scale: float) -> None:
    rng, truth = _world(5)
    est_xy = truth.landmarks_xy @ np.array([[0, -1], [1, 0.0]]).T + rng.normal(0, .05, (12, 2))
    a1 = align(est_xy, truth.landmarks_xy)
    a2 = align(est_xy * scale, truth.landmarks_xy * scale)
    np.testing.assert_allclose(a2.rotation, a1.rotation, atol=1e-12)
    np.testing.assert_allclose(a2.translation / scale, a1.translation, atol=1e-12)
    s1 = score_estimate(MapEstimate(truth.landmark_ids, est_xy), truth)
    s2 = score_estimate(MapEstimate(truth.landmark_ids, est_xy * scale),
                        Truth(truth.landmark_ids, truth.landmarks_xy * scale))
    assert np.isfinite(s2.mpe_m) and np.isfinite(s2.rmse_m)
    assert s2.mpe_m / scale == pytest.approx(s1.mpe_m, rel=1e-9)
    assert s2.rmse_m / scale == pytest.approx(s1.rmse_m, rel=1e-9)


def test_bearing_residuals_vanish_at_the_truth_and_flip_for_a_mirror() -> None:
    pose = np.array([[0.0, 0.0, 0.3], [1.0, 0.0, 1.0]])
    lm = np.array([[1.0, 1.0], [2.0, -1.0]])
    brg = [np.arctan2(lm[:, 1] - p[1], lm[:, 0] - p[0]) - p[2] for p in pose]
    steps = [Step(t, np.zeros(3), np.arange(2), np.angle(np.exp(1j * b))) for t, b in
             enumerate(brg)]
    r = bearing_residuals(np.arange(2), lm, np.arange(2), pose, steps)
    assert r.shape == (4,) and np.max(np.abs(r)) < 1e-12
    mir = bearing_residuals(np.arange(2), lm * [1, -1], np.arange(2), pose * [1, -1, -1], steps,
                            mirrored=True)
    assert np.max(np.abs(mir)) < 1e-12


def test_rpe_heading_error_wraps_across_pi_and_a_delta_of_the_whole_span_is_one_pair() -> None:
    """Reference turn pi - 0.01 between steps 0 and 1, estimated turn -pi + 0.01 (the same
    motion 0.02 rad further): the heading error is 0.02, not 2 pi - 0.02. And a delta equal
    to the span of the steps (0 .. 4, delta 4) is one pair, (0, 4)."""
    ref = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, np.pi - 0.01]])
    est = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, -np.pi + 0.01]])
    r = relative_pose_errors(np.array([0, 1]), est, ref, delta=1)
    np.testing.assert_allclose(r.heading_rad, [0.02], rtol=1e-9)
    np.testing.assert_allclose(r.translation_m, [0.0], atol=1e-12)
    ape = absolute_pose_errors(np.array([0, 1]), est, ref)     # the same wrap, per pose
    np.testing.assert_allclose(ape.heading_rad, [0.0, 0.02], rtol=1e-9, atol=1e-15)
    poses = np.column_stack([np.arange(5.0), np.zeros(5), np.zeros(5)])
    moved = poses.copy()
    moved[4, 1] = 0.3
    whole = relative_pose_errors(np.arange(5), moved, poses, delta=4)
    np.testing.assert_array_equal(whole.t, [0])
    np.testing.assert_allclose(whole.translation_m, [0.3], rtol=1e-12)


def test_rpe_and_bearing_residuals_do_not_depend_on_the_row_order() -> None:
    """Poses given out of step order (MapEstimate allows it) and a map whose ids are not
    sorted give the same RPE and bearing residuals as sorted rows; a bearing of a landmark the
    map lacks, or from a step without a pose, is left out; the residual is measured minus
    predicted (signed), checked on a bearing 0.1 rad off."""
    rng, truth = _world(4)
    est = truth.poses + np.column_stack([rng.normal(0, 0.05, (30, 2)), rng.normal(0, 0.05, 30)])
    t = np.arange(30)
    want = relative_pose_errors(t, est, truth.poses, delta=3)
    perm = rng.permutation(30)
    got = relative_pose_errors(t[perm], est[perm], truth.poses[perm], delta=3)
    np.testing.assert_array_equal(got.t, want.t)
    np.testing.assert_allclose(got.translation_m, want.translation_m, rtol=0, atol=1e-15)
    np.testing.assert_allclose(got.heading_rad, want.heading_rad, rtol=0, atol=1e-15)
    # bearing residuals: steps 0..5 see landmarks 0..11 plus 99 (not mapped); step 5 has
    # no pose in the estimate
    lm, poses = truth.landmarks_xy, truth.poses[:5]
    steps = []
    for k in range(6):
        p = truth.poses[k]
        b = np.arctan2(lm[:, 1] - p[1], lm[:, 0] - p[0]) - p[2] + (0.1 if k == 2 else 0.0)
        steps.append(Step(k, np.zeros(3), np.r_[np.arange(12), 99],
                          np.angle(np.exp(1j * np.r_[b, 0.5]))))
    ids_perm = rng.permutation(12)
    pose_perm = np.array([3, 0, 4, 2, 1])
    r = bearing_residuals(np.arange(12)[ids_perm], lm[ids_perm], np.arange(5)[pose_perm],
                          poses[pose_perm], steps)
    assert r.shape == (5 * 12,)
    np.testing.assert_allclose(r, np.repeat([0.0, 0.0, 0.1, 0.0, 0.0], 12), atol=1e-12)
