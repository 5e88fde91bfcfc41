"""Independent checks of the evaluator's alignment, MPE and NEES (bomgraph/evaluate.py).

The existing tests recover exact transforms and compare one rotation-only case with a search
over angles; these compare the SVD alignment of noisy maps with a brute-force search over
rotations *and* reflections, and check that the scores do not depend on the world frame of the
estimate (rotation, translation, reflection with the covariances turned alike) or on the
order of the landmarks, and the NEES under a similarity alignment against the truth carried
back into the estimate's frame.
"""

from __future__ import annotations

import numpy as np
import pytest

from bomgraph.evaluate import align, landmark_nees, pose_nees, score_estimate
from bomgraph.mapper import MapEstimate
from bomgraph.stream import Truth


def _rot(a: float) -> np.ndarray:
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


def _brute_sse(src: np.ndarray, dst: np.ndarray, reflect: bool) -> float:
    """Least summed squared error over rotations on a fine grid refined twice, with the
    optimal translation (the centroids') and, if allowed, the mirror image too."""
    best = np.inf
    for m in ([np.eye(2), np.diag([1.0, -1.0])] if reflect else [np.eye(2)]):
        a = (src - src.mean(0)) @ m.T
        b = dst - dst.mean(0)
        lo, hi = -np.pi, np.pi
        for _ in range(3):
            grid = np.linspace(lo, hi, 2001)
            sse = [float(((a @ _rot(t).T - b) ** 2).sum()) for t in grid]
            k = int(np.argmin(sse))
            best = min(best, sse[k])
            step = grid[1] - grid[0]
            lo, hi = grid[k] - step, grid[k] + step
    return best


@pytest.mark.parametrize("mirrored", [False, True])
def test_alignment_of_a_noisy_map_is_the_brute_force_optimum(mirrored: bool) -> None:
    rng = np.random.default_rng(51)
    truth = rng.uniform(0, 2.5, (15, 2))
    est = (truth + rng.normal(0, 0.1, truth.shape) - [1.0, 2.0]) @ _rot(1.1)
    if mirrored:
        est = est * [1.0, -1.0]
    al = align(est, truth)
    sse = float(((al.apply(est) - truth) ** 2).sum())
    assert sse == pytest.approx(_brute_sse(est, truth, True), rel=1e-6)
    assert al.reflected == mirrored
    # reflection forbidden: the brute force over rotations only
    al = align(est, truth, allow_reflection=False)
    sse = float(((al.apply(est) - truth) ** 2).sum())
    assert sse == pytest.approx(_brute_sse(est, truth, False), rel=1e-6)


def test_mpe_and_landmark_nees_do_not_depend_on_the_estimates_frame_or_order() -> None:
    rng = np.random.default_rng(52)
    n = 12
    truth = Truth(np.arange(100, 100 + n), rng.uniform(0, 2.5, (n, 2)))
    a = rng.normal(size=(n, 2, 2))
    cov = a @ a.transpose(0, 2, 1) * 1e-3 + np.eye(2) * 1e-4
    xy = truth.landmarks_xy + rng.normal(0, 0.05, (n, 2))
    base = MapEstimate(truth.landmark_ids, xy, landmark_cov=cov)
    s0 = score_estimate(base, truth)
    nees0 = landmark_nees(base, truth, s0.alignment)
    for ang, mirror in ((0.4, False), (2.5, True), (-1.2, True)):
        r = _rot(ang) @ (np.diag([1.0, -1.0]) if mirror else np.eye(2))
        t = np.array([3.0, -4.0])
        perm = rng.permutation(n)
        moved = MapEstimate(truth.landmark_ids[perm], (xy @ r.T + t)[perm],
                            landmark_cov=(r @ cov @ r.T)[perm])
        s = score_estimate(moved, truth)
        assert s.mpe_m == pytest.approx(s0.mpe_m, rel=1e-9)
        assert s.alignment.reflected == mirror
        got = landmark_nees(moved, truth, s.alignment)
        # landmark_nees follows the common ids in sorted order
        np.testing.assert_allclose(got, nees0, rtol=1e-8)
    # the NEES itself: e^T P^-1 e in the aligned frame, by a solve instead of an inverse
    e = s0.alignment.apply(xy) - truth.landmarks_xy
    rc = s0.alignment.rotation
    ref = [float(ei @ np.linalg.solve(rc @ ci @ rc.T, ei)) for ei, ci in zip(e, cov)]
    np.testing.assert_allclose(nees0, ref, rtol=1e-10)


def test_nees_under_a_similarity_alignment_is_that_of_the_estimates_own_frame() -> None:
    """Under ``with_scale`` (``bomgraph evaluate --similarity``) the aligned estimate is
    ``s R x + t``, whose covariance is ``s^2 R P R^T``. Checked the other way round: the truth
    carried back into the estimate's frame by the inverse of the fitted transform, where the
    estimate's own covariance applies (no covariance is turned). Before the twenty-first
    session the covariance was turned but not scaled, so the NEES columns of ``bomgraph
    evaluate --similarity`` were off by ``s^2`` (on a seeded 60-step ``ekf`` run whose fit had
    ``s`` = 0.968, the final landmark NEES 0.769 instead of 0.820)."""
    rng = np.random.default_rng(61)
    n = 10
    lm = rng.uniform(0, 2.5, (n, 2))
    true_pose = np.array([1.2, 0.7, 0.4])
    truth = Truth(np.arange(n), lm, np.array([[0.0, 0.0, 0.0], true_pose]))
    a = rng.normal(size=(n, 2, 2))
    cov = a @ a.transpose(0, 2, 1) * 1e-3 + np.eye(2) * 1e-4
    b = rng.normal(size=(3, 3))
    pcov = b @ b.T * 1e-3 + np.eye(3) * 1e-4
    for scale, mirror in ((0.5, False), (3.0, True)):
        r = _rot(1.1) @ (np.diag([1.0, -1.0]) if mirror else np.eye(2))
        t = np.array([-2.0, 5.0])
        # the estimate: noisy truth in a frame x_est = R^T (x - t) / scale, heading turned
        noisy = lm + rng.normal(0, 0.05, (n, 2))
        p = true_pose + rng.normal(0, 0.05, 3)
        h = np.array([np.cos(p[2]), np.sin(p[2])]) @ r
        est = MapEstimate(np.arange(n), (noisy - t) @ r / scale, pose_t=np.array([1]),
                          poses=np.array([[*((p[:2] - t) @ r / scale),
                                           np.arctan2(h[1], h[0])]]),
                          landmark_cov=cov, pose_cov=pcov[None])
        al = score_estimate(est, truth, with_scale=True).alignment
        assert al.reflected == mirror and al.scale == pytest.approx(scale, rel=0.1)
        # the truth in the estimate's frame: the inverse of x -> s R x + c
        back = (lm - al.translation) @ al.rotation / al.scale
        e = est.landmarks_xy - back
        want = [float(ei @ np.linalg.solve(ci, ei)) for ei, ci in zip(e, cov)]
        np.testing.assert_allclose(landmark_nees(est, truth, al), want, rtol=1e-9)
        q = np.array([np.cos(true_pose[2]), np.sin(true_pose[2])]) @ al.rotation
        back_pose = np.r_[(true_pose[:2] - al.translation) @ al.rotation / al.scale,
                          np.arctan2(q[1], q[0])]
        ep = est.poses[0] - back_pose
        ep[2] = (ep[2] + np.pi) % (2 * np.pi) - np.pi
        assert pose_nees(est, truth, al) == pytest.approx(float(ep @ np.linalg.solve(pcov, ep)),
                                                          rel=1e-9)


def test_similarity_without_reflection_fits_the_best_scale_for_its_rotation() -> None:
    """A mirrored map aligned with ``with_scale`` and reflection forbidden: the rotation is the
    best proper one, and for it the least-squares scale is ``sum b . (R a) / sum |a|^2``
    (centred points), written out here. The Umeyama scale is ``trace(S D) / var``: dropping
    the ``D = diag(1, -1)`` sign (``sum(sv)``) overstates it."""
    rng = np.random.default_rng(62)
    truth = rng.uniform(0, 3, (12, 2))
    est = ((truth + rng.normal(0, 0.05, truth.shape)) @ _rot(0.8).T * [1.0, -1.0]) / 2.5
    al = align(est, truth, with_scale=True, allow_reflection=False)
    assert not al.reflected
    a, b = est - est.mean(0), truth - truth.mean(0)
    ra = a @ al.rotation.T
    best = float((b * ra).sum() / (a * a).sum())
    assert al.scale == pytest.approx(best, rel=1e-9)
    np.testing.assert_allclose(al.translation, truth.mean(0) - best * al.rotation @ est.mean(0),
                               atol=1e-12)
    # and the fit is the brute-force optimum over proper rotations at their own best scale
    sse = float(((al.apply(est) - truth) ** 2).sum())
    grid = np.linspace(-np.pi, np.pi, 20001)
    costs = []
    for t in grid:
        rt = a @ _rot(t).T
        s = (b * rt).sum() / (a * a).sum()
        costs.append(float(((s * rt - b) ** 2).sum()))
    assert sse <= min(costs) + 1e-9


def test_latest_pose_is_the_latest_step_whatever_the_row_order() -> None:
    """``pose_t`` need not be sorted (MapEstimate refuses repeats only): ``robot_last_m`` and
    :func:`pose_nees` are about the pose with the largest step, not the last row."""
    rng = np.random.default_rng(63)
    lm = rng.uniform(0, 3, (6, 2))
    poses = np.column_stack([rng.uniform(0, 3, (5, 2)), rng.uniform(-3, 3, 5)])
    truth = Truth(np.arange(6), lm, poses)
    err = np.array([[0.3, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.0],
                    [0.0, 0.0, 0.2]])            # per step 0..4
    cov = np.tile(np.diag([0.01, 0.01, 0.01]), (5, 1, 1))
    order = np.array([4, 0, 3, 1, 2])           # step 4 first, step 2 last
    est = MapEstimate(np.arange(6), lm, pose_t=order, poses=(poses + err)[order],
                      pose_cov=cov)
    s = score_estimate(est, truth)
    assert s.robot_last_m == pytest.approx(0.0, abs=1e-12)      # step 4: heading error only
    assert s.robot_mean_m == pytest.approx(0.4 / 5, rel=1e-9)
    assert pose_nees(est, truth, s.alignment) == pytest.approx(0.2 ** 2 / 0.01, rel=1e-9)


def test_pose_nees_heading_error_is_wrapped_across_pi() -> None:
    """A heading of pi - 0.05 against a true -pi + 0.05 is an error of -0.1 rad, not
    2 pi - 0.1: the pose NEES under ``diag(.., 0.01)`` is 1, not ~3.8e3."""
    lm = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 3.0], [1.0, 1.0]])
    truth = Truth(np.arange(4), lm, np.array([[0.0, 0.0, 0.0], [1.0, 1.0, -np.pi + 0.05]]))
    est = MapEstimate(np.arange(4), lm, pose_t=np.array([1]),
                      poses=np.array([[1.0, 1.0, np.pi - 0.05]]),
                      pose_cov=np.diag([0.01, 0.01, 0.01])[None])
    s = score_estimate(est, truth)
    assert pose_nees(est, truth, s.alignment) == pytest.approx(1.0, rel=1e-9)
    assert s.ape_heading_rmse_rad == pytest.approx(0.1, rel=1e-9)


def test_collinear_tie_the_positions_leave_is_broken_by_the_headings() -> None:
    """Landmarks and robot positions all on one line: the mirror across it fits both equally,
    but it turns a heading of +1 rad off the line into -1 rad. The headings pick the proper
    fit; the score is not ambiguous and the pose errors are zero."""
    lm = np.column_stack([np.linspace(0, 2, 6), np.zeros(6)])
    poses = np.column_stack([np.linspace(0, 2, 5), np.zeros(5), np.full(5, 1.0)])
    truth = Truth(np.arange(6), lm, poses)
    r = _rot(0.6)
    est = MapEstimate(np.arange(6), lm @ r.T, pose_t=np.arange(5),
                      poses=np.column_stack([poses[:, :2] @ r.T, poses[:, 2] + 0.6]))
    s = score_estimate(est, truth)
    assert not s.ambiguous and not s.alignment.reflected
    assert s.ape_heading_rmse_rad == pytest.approx(0.0, abs=1e-9)
    assert s.robot_mean_m == pytest.approx(0.0, abs=1e-9)


def test_squared_error_sum_of_a_hand_computed_case() -> None:
    """``_sse`` (the tie-break cost) is the plain sum of squares, scaled only to avoid
    overflow: |(3, 4)|^2 + |(1, 0)|^2 = 26, and the same at 1e200 without overflowing."""
    from bomgraph.evaluate import _sse
    x = np.array([[3.0, 4.0], [1.0, 0.0]])
    assert _sse(x, 0.0) == pytest.approx(26.0, rel=1e-15)
    assert _sse(x * 1e150, 0.0) == pytest.approx(26.0e300, rel=1e-12)
    assert _sse(x, x) == 0.0
