"""Independent checks of the evaluator's alignment, MPE and NEES (bomgraph/evaluate.py).

The existing tests recover exact transforms and compare one rotation-only case with a search
over angles; these compare the SVD alignment of noisy maps with a brute-force search over
rotations *and* reflections, and check that the scores do not depend on the world frame of the
estimate (rotation, translation, reflection with the covariances turned alike) or on the
order of the landmarks.
"""

from __future__ import annotations

from typing import Callable

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



def _numeric_jacobian(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray,
                      wrap: int | None = None) -> np.ndarray:
    """Central differences of ``f`` at ``x`` (output component ``wrap`` taken as an angle)."""
    h = 1e-6
    cols = []
    for k in range(len(x)):
        d = np.zeros(len(x))
        d[k] = h
        diff = f(x + d) - f(x - d)
        if wrap is not None:
            diff[wrap] = np.angle(np.exp(1j * diff[wrap]))
        cols.append(diff / (2 * h))
    return np.column_stack(cols)


@pytest.mark.parametrize("mirror", [False, True])
def test_nees_under_a_similarity_alignment_carries_the_covariance_with_the_map(
        mirror: bool) -> None:
    """Scored with a similarity alignment, an estimate at twice the truth's scale (turned,
    shifted, maybe mirrored) has the NEES ``e^T (J P J^T)^-1 e`` with ``J`` the numeric
    Jacobian of the alignment applied to its points and poses: the covariances scale with
    the map (before the twenty-first session only the rotation was applied to them, so at
    the fitted scale ``s = 0.5`` the NEES came out ``s^2``, a quarter, of its value)."""
    rng = np.random.default_rng(53)
    n = 10
    truth_xy = rng.uniform(0, 2.5, (n, 2))
    true_pose = np.array([1.0, 0.5, 0.8])
    truth = Truth(np.arange(n), truth_xy, np.array([[0.0, 0.0, 0.0], true_pose]))
    a = rng.normal(size=(n, 2, 2))
    cov = a @ a.transpose(0, 2, 1) * 1e-2 + np.eye(2) * 1e-3
    r = _rot(0.7) @ (np.diag([1.0, -1.0]) if mirror else np.eye(2))
    t = np.array([0.4, -2.0])
    # the estimate in the frame x' = 2 R^T (x - t), with errors
    xy = 2.0 * (truth_xy - t) @ r + rng.normal(0, 0.05, (n, 2))
    h = np.array([np.cos(true_pose[2]), np.sin(true_pose[2])]) @ r
    pose = np.array([*(2.0 * (true_pose[:2] - t) @ r), np.arctan2(h[1], h[0])]) \
        + np.array([0.05, -0.04, 0.03])
    b = rng.normal(size=(3, 3))
    pcov = b @ b.T * 1e-3 + np.eye(3) * 1e-4
    est = MapEstimate(np.arange(n), xy, landmark_cov=cov, pose_t=np.array([1]),
                      poses=pose[None], pose_cov=pcov[None])
    al = score_estimate(est, truth, with_scale=True).alignment
    assert al.scale == pytest.approx(0.5, rel=0.05) and al.reflected == mirror
    want_l = []
    for x, c in zip(xy, cov):
        j = _numeric_jacobian(lambda v: al.apply(v[None])[0], x)
        e = al.apply(x[None])[0] - truth_xy[len(want_l)]
        want_l.append(float(e @ np.linalg.solve(j @ c @ j.T, e)))
    np.testing.assert_allclose(landmark_nees(est, truth, al), want_l, rtol=1e-6)
    j = _numeric_jacobian(lambda v: al.apply_poses(v[None])[0], pose, wrap=2)
    moved = al.apply_poses(pose[None])[0]
    e = np.array([*(moved[:2] - true_pose[:2]), np.angle(np.exp(1j * (moved[2] - true_pose[2])))])
    assert pose_nees(est, truth, al) == pytest.approx(
        float(e @ np.linalg.solve(j @ pcov @ j.T, e)), rel=1e-6)
