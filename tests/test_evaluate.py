"""The Procrustes evaluator: exact recovery of known transforms, hand-computed MPE."""

from __future__ import annotations

import numpy as np
import pytest

from bomgraph.errors import EvaluationError
from bomgraph.evaluate import (CheckpointScore, align, error_table, landmark_nees, pose_nees,
                               score_checkpoints, score_estimate)
from bomgraph.mapper import Checkpoint, MapEstimate, RunResult
from bomgraph.stream import Truth


def _rot(a: float) -> np.ndarray:
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


@pytest.fixture()
def truth() -> Truth:
    rng = np.random.default_rng(4)
    poses = np.column_stack([rng.uniform(0, 2.5, (20, 2)), rng.uniform(-3, 3, 20)])
    return Truth(np.arange(10, 30), rng.uniform(0, 2.5, (20, 2)), poses)


@pytest.mark.parametrize("reflect", [False, True])
def test_known_rigid_transform_is_recovered_exactly(truth: Truth, reflect: bool) -> None:
    r = _rot(0.83)
    if reflect:
        r = r @ np.diag([1.0, -1.0])
    t = np.array([3.0, -1.5])
    # the estimate is the truth mapped by the inverse: x_est = R^T (x - t)
    est_xy = (truth.landmarks_xy - t) @ r
    psi = np.arctan2(*(np.column_stack([np.cos(truth.poses[:, 2]),
                                        np.sin(truth.poses[:, 2])]) @ r)[:, ::-1].T)
    est_poses = np.column_stack([(truth.poses[:, :2] - t) @ r, psi])
    est = MapEstimate(truth.landmark_ids[::-1], est_xy[::-1], pose_t=np.arange(20),
                      poses=est_poses)
    s = score_estimate(est, truth)
    assert s.mpe_m < 1e-12 and s.robot_mean_m < 1e-12
    np.testing.assert_allclose(s.alignment.rotation, r, atol=1e-12)
    np.testing.assert_allclose(s.alignment.translation, t, atol=1e-12)
    assert s.alignment.reflected == reflect
    np.testing.assert_allclose(s.alignment.apply_poses(est_poses)[:, 2],
                               np.angle(np.exp(1j * truth.poses[:, 2])), atol=1e-12)


def test_reflection_can_be_forbidden(truth: Truth) -> None:
    est = MapEstimate(truth.landmark_ids, truth.landmarks_xy * [1.0, -1.0])
    assert score_estimate(est, truth).mpe_m < 1e-12
    assert score_estimate(est, truth, allow_reflection=False).mpe_m > 0.1


def test_mpe_equals_an_independent_hand_computation() -> None:
    # Three points; the estimate is the truth with one point pushed by (0, 0.3). The best
    # rigid fit of a symmetric configuration is computed by brute force over angles here.
    true_xy = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    est_xy = true_xy + np.array([[0, 0], [0, 0], [0, 0], [0.0, 0.3]])
    truth = Truth(np.arange(4), true_xy)
    s = score_estimate(MapEstimate(np.arange(4), est_xy), truth)
    best = np.inf
    for a in np.linspace(-0.3, 0.3, 60001):
        moved = (est_xy - est_xy.mean(0)) @ _rot(a).T + true_xy.mean(0)
        best = min(best, float(np.sum((moved - true_xy) ** 2)))
    errs = np.linalg.norm(s.alignment.apply(est_xy) - true_xy, axis=1)
    assert np.sum(errs ** 2) == pytest.approx(best, rel=1e-6)
    assert s.mpe_m == pytest.approx(errs.mean(), rel=1e-12)
    assert s.rmse_m == pytest.approx(np.sqrt(best / 4), rel=1e-5)


def test_similarity_option_fits_scale(truth: Truth) -> None:
    est = MapEstimate(truth.landmark_ids, 0.5 * truth.landmarks_xy @ _rot(0.2).T)
    assert score_estimate(est, truth).mpe_m > 0.1
    s = score_estimate(est, truth, with_scale=True)
    assert s.mpe_m < 1e-12 and s.alignment.scale == pytest.approx(2.0)


def test_inputs_are_not_mutated_and_counts(truth: Truth) -> None:
    xy = truth.landmarks_xy[:12] + 0.01
    est = MapEstimate(np.append(truth.landmark_ids[:12], 999), np.vstack([xy, [[5.0, 5.0]]]))
    before = est.landmarks_xy.copy()
    s = score_estimate(est, truth)
    np.testing.assert_array_equal(est.landmarks_xy, before)
    assert (s.n_mapped, s.n_common, s.n_truth) == (13, 12, 20)


def test_fewer_than_three_common_landmarks_is_a_clear_error(truth: Truth) -> None:
    est = MapEstimate(truth.landmark_ids[:2], truth.landmarks_xy[:2])
    with pytest.raises(EvaluationError, match="at least 3"):
        score_estimate(est, truth)
    with pytest.raises(EvaluationError, match="at least 3"):
        align(np.zeros((2, 2)), np.zeros((2, 2)))


def test_error_table_over_checkpoints(truth: Truth) -> None:
    cps = (Checkpoint(10, MapEstimate.empty(), 0.0),
           Checkpoint(20, MapEstimate(truth.landmark_ids, truth.landmarks_xy + [0.1, 0]), 0.0))
    table = error_table(RunResult("x", cps, np.zeros(21), 0.0), truth)
    assert list(table["t"]) == [10, 20]
    assert np.isnan(table["mpe_m"][0]) and table["mpe_m"][1] < 1e-12
    assert list(table["n_mapped"]) == [0, 20]


def test_landmark_nees_is_chi2_for_consistent_errors() -> None:
    rng = np.random.default_rng(5)
    n = 4000
    true_xy = rng.uniform(0, 10, (n, 2))
    cov = np.array([[0.04, 0.01], [0.01, 0.02]])
    est_xy = true_xy + rng.multivariate_normal([0, 0], cov, n)
    truth = Truth(np.arange(n), true_xy)
    est = MapEstimate(np.arange(n), est_xy, landmark_cov=np.broadcast_to(cov, (n, 2, 2)))
    s = score_estimate(est, truth)
    assert landmark_nees(est, truth, s.alignment).mean() == pytest.approx(2.0, rel=0.06)


def test_score_checkpoints_gives_typed_rows(truth: Truth) -> None:
    cps = (Checkpoint(10, MapEstimate.empty(), 0.5),
           Checkpoint(20, MapEstimate(truth.landmark_ids[:5], truth.landmarks_xy[:5] + [0.1, 0],
                                      pose_t=np.array([3, 7]), poses=truth.poses[[3, 7]]), 0.25))
    rows = score_checkpoints(RunResult("x", cps, np.zeros(21), 0.0), truth)
    assert all(isinstance(r, CheckpointScore) for r in rows)
    first, second = rows
    assert (first.t, first.n_mapped, first.n_common, first.estimate_s) == (10, 0, 0, 0.5)
    assert np.isnan(first.mpe_m) and np.isnan(first.nees_pose)
    assert (second.t, second.n_mapped, second.n_common) == (20, 5, 5)
    # the map is shifted by 0.1 m and the poses are not: after alignment they are 0.1 m off
    assert second.mpe_m < 1e-12 and second.robot_last_m == pytest.approx(0.1)
    assert np.isnan(second.nees_landmark) and np.isnan(second.nees_pose)   # no covariances
    table = error_table(cps, truth)
    assert table["mpe_m"][1] == second.mpe_m and table["n_common"].tolist() == [0, 5]


def test_pose_nees_of_a_hand_computed_error() -> None:
    """A latest-pose error (0.1 m, -0.2 m, 0.05 rad) under diag(0.01, 0.04, 0.0025) gives
    NEES 1 + 1 + 1 = 3, whichever rigid transform (a reflection too) aligns the frames."""
    lm = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 3.0], [1.0, 1.0]])
    truth = Truth(np.arange(4), lm, np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 0.3]]))
    err = np.array([0.1, -0.2, 0.05])
    cov = np.diag([0.01, 0.04, 0.0025])
    for r in (_rot(0.7), _rot(0.7) @ np.diag([1.0, -1.0])):
        t = np.array([0.4, -2.0])
        p = truth.poses[1] + err
        # the estimate in a frame x_est = R^T (x - t); the heading turns (and flips) with R
        h = np.array([np.cos(p[2]), np.sin(p[2])]) @ r
        est_pose = np.array([*((p[:2] - t) @ r), np.arctan2(h[1], h[0])])
        tr = np.eye(3)
        tr[:2, :2], tr[2, 2] = r, np.linalg.det(r)
        est = MapEstimate(np.arange(4), (lm - t) @ r, pose_t=np.array([1]),
                          poses=est_pose[None], pose_cov=(tr.T @ cov @ tr)[None])
        s = score_estimate(est, truth)
        assert pose_nees(est, truth, s.alignment) == pytest.approx(3.0, rel=1e-9)
    no_cov = MapEstimate(np.arange(4), lm, pose_t=np.array([1]), poses=truth.poses[1:])
    assert np.isnan(pose_nees(no_cov, truth, score_estimate(no_cov, truth).alignment))


def _square() -> tuple[MapEstimate, Truth]:
    ids = np.array([1, 2, 3, 4])
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    est = MapEstimate(ids, xy + 0.01, pose_t=[0, 1, 2], poses=np.zeros((3, 3)))
    return est, Truth(ids, xy, poses=np.zeros((3, 3)))


def test_score_estimate_refuses_swapped_or_wrong_arguments() -> None:
    """score_estimate(truth, estimate) used to score the truth against the estimate as if
    nothing were wrong; a RunResult or a missing truth ended in an AttributeError."""
    est, truth = _square()
    with pytest.raises(EvaluationError, match="estimate must be a MapEstimate, got Truth "
                                              r"\(arguments swapped"):
        score_estimate(truth, est)  # type: ignore[arg-type]
    result = RunResult("m", (Checkpoint(2, est, 0.0),), np.zeros(3), 0.0)
    with pytest.raises(EvaluationError, match=r"got RunResult \(result.final"):
        score_estimate(result, truth)  # type: ignore[arg-type]
    with pytest.raises(EvaluationError, match=r"truth must be a Truth .* got NoneType \(the "
                                              r"stream has no truth\)"):
        score_estimate(est, None)  # type: ignore[arg-type]
    with pytest.raises(EvaluationError, match="truth must be a Truth"):
        score_checkpoints(result, None)  # type: ignore[arg-type]
    with pytest.raises(EvaluationError, match=r"got MapEstimate \(score one map with "):
        score_checkpoints(est, truth)  # type: ignore[arg-type]
    with pytest.raises(EvaluationError, match="items must be Checkpoint, got MapEstimate"):
        score_checkpoints([est], truth)  # type: ignore[list-item]
    assert score_checkpoints(result, truth)[0].n_common == 4


@pytest.mark.parametrize("delta", [0, -1, 1.5, "1"])
def test_score_estimate_refuses_a_delta_that_is_not_a_positive_integer(delta: object) -> None:
    """0 and -1 raised trajectory's plain ValueError; 1.5 gave NaN relative errors."""
    est, truth = _square()
    with pytest.raises(EvaluationError, match="delta must be an integer >= 1"):
        score_estimate(est, truth, delta=delta)  # type: ignore[arg-type]


def test_align_refuses_points_given_as_columns() -> None:
    """A (2, n) array was reshaped to (n, 2): a transform of scrambled points."""
    pts = np.array([[0.0, 1.0, 0.0, 2.0], [0.0, 0.0, 1.0, 1.0]])
    with pytest.raises(EvaluationError, match=r"source_xy must have shape \(n, 2\), got "
                                              r"\(2, 4\); transpose"):
        align(pts, pts)
    with pytest.raises(EvaluationError, match="must be numbers"):
        align("ab", "cd")  # type: ignore[arg-type]
    assert np.allclose(align(pts.T, pts.T).apply(pts.T), pts.T)
    with pytest.raises(EvaluationError, match=r"points_xy must have shape \(n, 2\)"):
        align(pts.T, pts.T).apply(pts)


def test_a_score_prints_its_numbers_not_its_arrays(truth: Truth) -> None:
    """``repr(MapScore)`` printed every per-landmark error and the alignment's arrays."""
    est = MapEstimate(truth.landmark_ids, truth.landmarks_xy + 0.01)
    text = repr(score_estimate(est, truth))
    assert text.startswith("MapScore(mpe_m=") and "n_common=20" in text
    assert "array(" not in text and "\n" not in text
