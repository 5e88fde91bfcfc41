"""Independent checks of the localisation distances (paper III-E, bomgraph/stmds/localisation).

``RobotPoses.robot_pairs`` (dead-reckoned robot-robot distances and their first-order
variances) and ``RobotPoses.all_pose_ranges`` (robot-landmark distances from all held rays,
``sigma^2 u^T A_w^-1 u``) had no test of their own. Here the distances are checked exact
without noise, the robot-robot variance against central differences over the odometry and a
Monte Carlo, and the robot-landmark variance against a Monte Carlo of the bearings.
"""

from __future__ import annotations

import math

import numpy as np

from bomgraph.geometry import bearings_to, dead_reckon
from bomgraph.stmds.localisation import RobotPoses


def _held(odoms: np.ndarray, sigmas: np.ndarray, bearings=None, idx=None) -> RobotPoses:
    """A window holding ``len(odoms) + 1`` poses (the first without odometry)."""
    win = RobotPoses(len(odoms) + 1, "scale-free")
    m = len(odoms) + 1
    for k in range(m):
        b = np.zeros(0) if bearings is None else bearings[k]
        i = np.zeros(0, np.int64) if idx is None else idx[k]
        win.push(k, None if k == 0 else odoms[k - 1], None if k == 0 else sigmas[k - 1], i, b)
    return win


def _odoms(rng: np.random.Generator, m: int) -> np.ndarray:
    return np.column_stack([rng.uniform(0.1, 0.2, m), rng.uniform(-0.02, 0.02, m),
                            rng.uniform(-0.5, 0.5, m)])


def test_robot_pair_distances_are_exact_and_their_variance_is_j_sigma_jt() -> None:
    rng = np.random.default_rng(71)
    odoms = _odoms(rng, 5)
    sig = np.tile([0.03, 0.01, 0.05], (5, 1)) * rng.uniform(0.5, 1.5, (5, 3))
    a, b, d, v = _held(odoms, sig).robot_pairs()
    poses = dead_reckon(odoms)
    np.testing.assert_allclose(d, np.linalg.norm(poses[b, :2] - poses[a, :2], axis=1),
                               rtol=1e-12)

    def dists(z: np.ndarray) -> np.ndarray:
        p = dead_reckon(z.reshape(-1, 3))
        return np.linalg.norm(p[b, :2] - p[a, :2], axis=1)

    eps = 1e-6
    z0 = odoms.reshape(-1)
    jac = np.stack([(dists(z0 + e) - dists(z0 - e)) / (2 * eps)
                    for e in np.eye(z0.size) * eps], -1)
    np.testing.assert_allclose(v, (jac ** 2) @ (sig.reshape(-1) ** 2), rtol=1e-6)


def test_robot_pair_variance_matches_a_monte_carlo() -> None:
    rng = np.random.default_rng(72)
    odoms = _odoms(rng, 5)
    odoms[:, 2] = [0.9, 0.8, -0.2, 1.0, 0.7]          # a curved path: the turns move distances
    sig = np.tile([0.001, 0.0005, 0.01], (5, 1))      # and their terms dominate
    a, b, d, v = _held(odoms, sig).robot_pairs()
    n = 40_000
    noisy = odoms[None] + rng.normal(0, 1, (n, 5, 3)) * sig
    xy = np.zeros((n, 6, 2))
    psi = np.zeros(n)
    for k in range(5):                            # dead reckoning, vectorised over draws
        c, s = np.cos(psi), np.sin(psi)
        xy[:, k + 1, 0] = xy[:, k, 0] + c * noisy[:, k, 0] - s * noisy[:, k, 1]
        xy[:, k + 1, 1] = xy[:, k, 1] + s * noisy[:, k, 0] + c * noisy[:, k, 1]
        psi = psi + noisy[:, k, 2]
    dd = np.linalg.norm(xy[:, b] - xy[:, a], axis=2)
    var = dd.var(axis=0, ddof=1)
    se = v * math.sqrt(2.0 / (n - 1))             # 0.7 % of each variance
    assert np.all(np.abs(var - v) <= 4 * se + 0.01 * v), np.c_[var, v]


def _landmark_scene(rng: np.random.Generator):
    odoms = _odoms(rng, 5)
    poses = dead_reckon(odoms)
    lms = poses[2, :2] + rng.uniform(0.5, 1.0, (4, 1)) * np.column_stack(
        [np.cos(t := poses[2, 2] + np.array([1.2, -1.3, 1.9, -2.0])), np.sin(t)])
    brg = [bearings_to(p, lms) for p in poses]
    idx = [np.arange(4, dtype=np.int64) for _ in poses]
    return odoms, poses, lms, brg, idx


def test_all_pose_ranges_are_exact_without_noise() -> None:
    odoms, poses, lms, brg, idx = _landmark_scene(np.random.default_rng(73))
    win = _held(odoms, np.zeros((5, 3)), brg, idx)
    k, lm, d, _ = win.all_pose_ranges(0.01, math.radians(2.0))
    assert len(k) == 24
    np.testing.assert_allclose(d, np.linalg.norm(poses[k, :2] - lms[lm], axis=1), atol=1e-9)


def test_all_pose_range_variance_matches_a_monte_carlo_of_the_bearings() -> None:
    """Odometry exact (zero sigmas: the dead-reckoning term is zero), bearings noisy: the
    sample variance of each robot-landmark distance is ``sigma^2 u^T A_w^-1 u``."""
    rng = np.random.default_rng(74)
    odoms, poses, lms, brg, idx = _landmark_scene(rng)
    sigma = 0.002
    win = _held(odoms, np.zeros((5, 3)), brg, idx)
    k0, lm0, _, v0 = win.all_pose_ranges(sigma, math.radians(2.0))
    n = 3000
    out = np.empty((n, len(k0)))
    for s in range(n):
        noisy = [b + rng.normal(0, sigma, b.size) for b in brg]
        k, lm, d, _ = _held(odoms, np.zeros((5, 3)), noisy, idx).all_pose_ranges(
            sigma, math.radians(2.0))
        assert np.array_equal(k, k0) and np.array_equal(lm, lm0)
        out[s] = d
    var = out.var(axis=0, ddof=1)
    se = v0 * math.sqrt(2.0 / (n - 1))            # 2.6 % of each variance
    assert np.all(np.abs(var - v0) <= 4 * se + 0.02 * v0), np.c_[var, v0]


def _two_views(parallax_rad: float, reversed_rays: bool = False) -> RobotPoses:
    """Two poses 1 m apart along x (no turn) seeing landmark 7 about 5 m away with rays at
    ``parallax_rad`` (the landmark on the perpendicular bisector of the baseline); reversed:
    both bearings turned by pi (the same lines, the point behind both rays)."""
    depth = 0.5 / math.tan(parallax_rad / 2)
    lm = np.array([0.5, depth])
    flip = math.pi if reversed_rays else 0.0
    brg = [np.array([math.atan2(lm[1], lm[0] - x) + flip]) for x in (0.0, 1.0)]
    idx = [np.array([7]), np.array([7])]
    return _held(np.array([[1.0, 0.0, 0.0]]), np.zeros((1, 3)), brg, idx)


def test_all_pose_ranges_parallax_gate_and_rays_in_front_at_range() -> None:
    """The gate compares the ``1 / r^2``-weighted normal matrix's smallest eigenvalue with
    ``1 - cos(min_parallax)`` times the mean weight: with rays 1.2 times the gate apart the
    landmark (~5 m away: weights ~1/25) is kept, at 0.8 times refused; with both rays reversed
    (the point behind them) it is refused."""
    gate = math.radians(11.0)
    k, lm, d, _ = _two_views(1.2 * gate).all_pose_ranges(0.01, gate)
    assert lm.tolist() == [7, 7]
    depth = 0.5 / math.tan(0.6 * gate)
    np.testing.assert_allclose(d, [math.hypot(0.5, depth)] * 2, rtol=1e-9)
    assert _two_views(0.8 * gate).all_pose_ranges(0.01, gate)[0].size == 0
    assert _two_views(1.2 * gate, reversed_rays=True).all_pose_ranges(0.01, gate)[0].size == 0


def test_one_range_estimate_comes_back_with_its_own_variance() -> None:
    """``add_ranges`` folds ``(r, var r)`` as a squared distance of variance ``4 r^2 var r``:
    one estimate fused alone is itself, distance and variance, under every rule."""
    for rule in ("paper", "relative", "scale-free"):
        win = RobotPoses(3, rule)
        win.push(0, None, None, np.zeros(0, np.int64), np.zeros(0))
        win.add_ranges(0, np.array([4, 9]), np.array([2.5, 0.7]), np.array([0.01, 0.0004]))
        lm, d, v = win.ranges(0)
        assert lm.tolist() == [4, 9]
        np.testing.assert_allclose(d, [2.5, 0.7], rtol=1e-12)
        np.testing.assert_allclose(v, [0.01, 0.0004], rtol=1e-12)


def test_headings_of_poses_without_a_mapped_landmark_follow_the_odometry() -> None:
    """``_fill_headings``: a pose's missing heading is its neighbour's plus (or, from the
    next pose, minus) the turn between them, ``odom[k]`` leading from pose ``k-1`` to ``k``:
    turns 0.1, 0.2, 0.3 from a heading 0.5 give 0.6, 0.8, 1.1, forwards and backwards."""
    from bomgraph.stmds.localisation import _fill_headings

    odoms = np.array([[0.1, 0.0, 0.1], [0.1, 0.0, 0.2], [0.1, 0.0, 0.3]])
    win = _held(odoms, np.zeros((3, 3)))
    ks = np.arange(4)
    want = [0.5, 0.6, 0.8, 1.1]
    nan = math.nan
    np.testing.assert_allclose(_fill_headings(win, ks, np.array([0.5, nan, nan, nan])), want,
                               rtol=1e-12)
    np.testing.assert_allclose(_fill_headings(win, ks, np.array([nan, nan, nan, 1.1])), want,
                               rtol=1e-12)
    np.testing.assert_allclose(_fill_headings(win, ks, np.array([nan, 0.6, nan, nan])), want,
                               rtol=1e-12)


def _rot(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def _resection_scene():
    """Four poses (robot nodes 9..12 after 9 landmark slots) in a world of five landmarks
    with ids 2, 3, 5, 6, 8 (slot 8 not mapped); the bearings by ``math.atan2`` per pair, CCW
    from the heading and wrapped by ``math.remainder``: independent of the geometry kernel."""
    poses = np.array([[0.0, 0.0, 0.3], [0.4, 0.1, 0.9], [0.9, 0.5, -2.6], [1.3, 0.2, 3.0]])
    lm_idx = np.array([2, 3, 5, 6], np.int64)
    lms = np.array([[2.0, 1.0], [-1.0, 2.5], [0.5, -2.0], [3.0, -0.5]])
    seen = [np.array([2, 3, 5, 8]), np.array([3, 6]), np.array([2, 5, 6]), np.array([6, 3, 2])]
    where = {2: 0, 3: 1, 5: 2, 6: 3}
    win = RobotPoses(4, "scale-free")
    for k, (x, y, psi) in enumerate(poses):
        b = []
        for i in seen[k]:
            lx, ly = lms[where[int(i)]] if int(i) in where else (7.0, 7.0)
            b.append(math.remainder(math.atan2(ly - y, lx - x) - psi, math.tau))
        win.push(k, None if k == 0 else np.zeros(3), None, seen[k], np.array(b))
    kept = np.concatenate([lm_idx, 9 + np.arange(4)])
    return win, poses, lms, lm_idx, kept


def test_resect_headings_recovers_headings_and_undoes_a_mirror_exactly() -> None:
    """Noise-free: with the map and positions rotated by ``theta`` the headings come back as
    ``psi + theta`` and the frame is kept; with them mirrored (``y -> -y``) and then rotated,
    the mirror image fits better, so the output is reflected back (``lm_xy`` is the truth
    rotated by ``-theta``, the poses likewise with headings ``psi - theta``) and
    ``reflected`` is True (the docstring: reflect the frame when the mirror image fits
    better)."""
    from bomgraph.stmds.localisation import resect_headings

    win, poses, lms, lm_idx, kept = _resection_scene()
    theta = 0.7
    r = _rot(theta)
    pts = np.concatenate([lms, poses[:, :2]])
    xy = pts @ r.T
    lm_xy, pose_t, out, reflected = resect_headings(win, kept, xy, 9, lm_idx, xy[:4])
    assert reflected is False and pose_t.tolist() == [0, 1, 2, 3]
    np.testing.assert_allclose(lm_xy, lms @ r.T, atol=1e-12)
    np.testing.assert_allclose(out[:, :2], poses[:, :2] @ r.T, atol=1e-12)
    np.testing.assert_allclose(np.remainder(out[:, 2] - poses[:, 2] - theta + 1, math.tau),
                               1.0, atol=1e-12)

    mirrored = (pts * [1.0, -1.0]) @ r.T
    lm_xy, pose_t, out, reflected = resect_headings(win, kept, mirrored, 9, lm_idx,
                                                    mirrored[:4])
    back = _rot(-theta)
    assert reflected is True and pose_t.tolist() == [0, 1, 2, 3]
    np.testing.assert_allclose(lm_xy, lms @ back.T, atol=1e-12)
    np.testing.assert_allclose(out[:, :2], poses[:, :2] @ back.T, atol=1e-12)
    np.testing.assert_allclose(np.remainder(out[:, 2] - poses[:, 2] + theta + 1, math.tau),
                               1.0, atol=1e-12)
    assert np.all(np.abs(out[:, 2]) <= math.pi)
