"""BOM-STMDS sequential triangulation (paper III-B, eq. 1-2) and its gates."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bomgraph.errors import ConfigError
from bomgraph.geometry import between, bearings_to, to_local
from bomgraph.stmds.triangulation import (gate_points, pair_squared_distances,
                                          point_covariance, range_jacobians, range_variances,
                                          triangulate_rays)


def _two_poses_and_points(rng: np.random.Generator, k: int = 6):
    pose_a = np.array([0.3, -0.2, 0.4])
    pose_b = np.array([0.45, -0.05, 0.7])
    pts = rng.uniform(-1.0, 1.5, size=(k, 2)) + np.array([0.5, 1.0])
    return pose_a, pose_b, pts


def test_general_odometry_recovers_noise_free_points_in_frame_of_first_pose() -> None:
    pose_a, pose_b, pts = _two_poses_and_points(np.random.default_rng(0))
    odom = between(pose_a, pose_b)
    tri = triangulate_rays(odom, bearings_to(pose_a, pts), bearings_to(pose_b, pts))
    np.testing.assert_allclose(tri.points_xy, to_local(pose_a, pts), atol=1e-12)
    np.testing.assert_allclose(tri.range_prev_m, np.linalg.norm(pts - pose_a[:2], axis=1),
                               atol=1e-12)
    np.testing.assert_allclose(tri.range_now_m, np.linalg.norm(pts - pose_b[:2], axis=1),
                               atol=1e-12)


def test_move_then_turn_is_eq_1_of_the_paper() -> None:
    rng = np.random.default_rng(1)
    l, phi = 0.17, 0.31
    th_prev = rng.uniform(-2.5, 2.5, 20)
    th_now = rng.uniform(-2.5, 2.5, 20)
    tri = triangulate_rays([l, 0.0, phi], th_prev, th_now)
    r = np.sin(phi + th_now) * l / np.sin(phi + th_now - th_prev)
    eq1 = r[:, None] * np.column_stack([np.cos(th_prev), np.sin(th_prev)])
    np.testing.assert_allclose(tri.points_xy, eq1, rtol=0, atol=1e-12)


def _numeric_jacobian(f, z: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    cols = []
    for k in range(len(z)):
        dz = np.zeros_like(z)
        dz[k] = eps
        cols.append((f(z + dz) - f(z - dz)) / (2 * eps))
    return np.stack(cols, axis=-1)


def test_point_and_range_jacobians_match_numeric() -> None:
    rng = np.random.default_rng(2)
    odom = np.array([0.15, 0.04, 0.25])
    a = rng.uniform(-1.2, 1.2, 5)
    b = rng.uniform(-1.2, 1.2, 5)
    tri = triangulate_rays(odom, a, b)
    j1, j2 = range_jacobians(tri)
    for i in range(5):
        def point(z, i=i):
            aa, bb = a.copy(), b.copy()
            aa[i], bb[i] = z[3], z[4]
            t = triangulate_rays(z[:3], aa, bb)
            return np.concatenate([t.points_xy[i], [t.range_prev_m[i], t.range_now_m[i]]])
        num = _numeric_jacobian(point, np.r_[odom, a[i], b[i]])
        np.testing.assert_allclose(tri.jacobian[i], num[:2], rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(j1[i], num[2], rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(j2[i], num[3], rtol=1e-6, atol=1e-6)


def test_pair_jacobian_and_variance_match_numeric() -> None:
    rng = np.random.default_rng(3)
    odom = np.array([0.12, -0.03, -0.2])
    a = rng.uniform(-1.0, 1.0, 4)
    b = a + rng.uniform(0.1, 0.4, 4)
    sig_odo = np.array([0.03, 0.01, 0.05])
    sig_b = 0.04
    tri = triangulate_rays(odom, a, b)
    pe = pair_squared_distances(tri, sig_odo, sig_b, with_jacobian=True)
    assert len(pe) == 6
    for p in range(len(pe)):
        i, j = pe.first[p], pe.second[p]

        def d2(z, i=i, j=j):
            aa, bb = a.copy(), b.copy()
            aa[i], bb[i], aa[j], bb[j] = z[3], z[4], z[5], z[6]
            q = triangulate_rays(z[:3], aa, bb).points_xy
            return np.array(np.sum((q[i] - q[j]) ** 2))

        num = _numeric_jacobian(d2, np.r_[odom, a[i], b[i], a[j], b[j]])
        np.testing.assert_allclose(pe.jacobian[p], num, rtol=1e-6, atol=1e-8)
        sigma = np.r_[sig_odo, [sig_b] * 4]
        assert pe.variance_m4[p] == pytest.approx(float(np.sum((num * sigma) ** 2)), rel=1e-6)


def test_point_covariance_and_range_variances_are_j_sigma_jt() -> None:
    tri = triangulate_rays([0.2, 0.0, 0.1], [0.5, 1.0], [0.7, 1.3])
    sig = np.array([0.03, 0.0, 0.05, 0.05, 0.05])
    cov = point_covariance(tri, sig[:3], 0.05)
    j = tri.jacobian * sig
    np.testing.assert_allclose(cov, j @ j.transpose(0, 2, 1))
    v1, v2 = range_variances(tri, sig[:3], 0.05)
    j1, j2 = range_jacobians(tri)
    np.testing.assert_allclose(v1, (j1 * sig) ** 2 @ np.ones(5))
    np.testing.assert_allclose(v2, (j2 * sig) ** 2 @ np.ones(5))


def test_gates_refuse_no_parallax_behind_and_far_points() -> None:
    # 0: fine; 1: zero parallax (parallel rays); 2: antiparallel; 3: behind both rays;
    # 4: far away (tiny parallax, depth ~ 20 m); 5: fine but relatively uncertain
    l = 0.2
    pts_local = np.array([[0.5, 0.6], [np.nan, np.nan], [np.nan, np.nan], [-0.6, -0.4],
                          [20.0, 0.5], [1.2, 0.5]])
    a = np.arctan2(pts_local[:, 1], pts_local[:, 0])
    b = np.arctan2(pts_local[:, 1], pts_local[:, 0] - l)
    a[1], b[1] = 0.4, 0.4
    a[2], b[2] = 0.4, 0.4 + math.pi
    # point 3 lies behind: flip both bearings so the rays point away from it
    a[3], b[3] = a[3] + math.pi, b[3] + math.pi
    tri = triangulate_rays([l, 0.0, 0.0], a, b)
    with np.errstate(all="raise"):
        var1, _ = range_variances(tri, [0.03, 0.0, 0.05], 0.05)
    ok = gate_points(tri, var1, min_parallax_rad=math.radians(1.0), max_range_m=2.0)
    np.testing.assert_array_equal(ok, [True, False, False, False, False, True])
    ok = gate_points(tri, var1, min_parallax_rad=math.radians(1.0), max_range_m=2.0,
                     max_relative_range_sigma=0.5)
    assert ok[0] and not ok[5]
    assert np.all(np.isfinite(var1[[0, 5]]))
    with pytest.raises(ConfigError):
        gate_points(tri, None, max_relative_range_sigma=0.5)


def test_a_step_with_no_parallax_gives_no_usable_point_and_no_warning() -> None:
    # pure translation along a bearing of 0: every ray pair is parallel
    with np.errstate(all="raise"):
        tri = triangulate_rays([0.1, 0.0, 0.0], np.zeros(3), np.zeros(3))
        assert not gate_points(tri).any()



def test_compose_odometry_chains_increments_with_first_order_covariance() -> None:
    from bomgraph.geometry import between, dead_reckon
    from bomgraph.stmds.triangulation import compose_odometry

    rng = np.random.default_rng(4)
    odoms = np.column_stack([rng.uniform(0.1, 0.2, 5), rng.uniform(-0.02, 0.02, 5),
                             rng.uniform(-0.4, 0.4, 5)])
    sig = np.tile([0.03, 0.01, 0.05], (5, 1))
    u, cov = compose_odometry(odoms, sig)
    poses = dead_reckon(odoms)
    np.testing.assert_allclose(u[:2], between(poses[0], poses[-1])[:2], atol=1e-12)
    assert u[2] == pytest.approx(odoms[:, 2].sum())
    num = _numeric_jacobian(lambda z: compose_odometry(z.reshape(5, 3), sig)[0],
                            odoms.reshape(-1))
    jw = num * sig.reshape(-1)
    np.testing.assert_allclose(cov, jw @ jw.T, rtol=1e-6, atol=1e-12)


def test_pair_variance_with_a_full_odometry_covariance_and_a_selection() -> None:
    rng = np.random.default_rng(5)
    a = rng.uniform(-1.0, 1.0, 6)
    b = a + rng.uniform(0.2, 0.5, 6)
    tri = triangulate_rays([0.3, 0.05, 0.1], a, b)
    sig = np.array([0.03, 0.02, 0.05])
    diag = pair_squared_distances(tri, sig, 0.05)
    full = pair_squared_distances(tri, np.diag(sig ** 2), 0.05)
    np.testing.assert_allclose(full.variance_m4, diag.variance_m4, rtol=1e-12)
    # a correlated covariance: the variance is g^T C g with the numeric gradient
    c = np.array([[9e-4, 2e-4, 1e-4], [2e-4, 4e-4, 0.0], [1e-4, 0.0, 2.5e-3]])
    corr = pair_squared_distances(tri, c, 0.05, with_jacobian=True)
    g = corr.jacobian
    expect = np.einsum("pi,ij,pj->p", g[:, :3], c, g[:, :3]) + 0.05 ** 2 * (g[:, 3:] ** 2).sum(1)
    np.testing.assert_allclose(corr.variance_m4, expect, rtol=1e-12)
    # pairs among a selection index the full set and equal those of the subset
    sel = np.array([0, 2, 5])
    part = pair_squared_distances(tri, sig, 0.05, select=sel)
    sub = pair_squared_distances(tri.subset(sel), sig, 0.05)
    np.testing.assert_array_equal(part.first, sel[sub.first])
    np.testing.assert_array_equal(part.second, sel[sub.second])
    np.testing.assert_allclose(part.variance_m4, sub.variance_m4)
    np.testing.assert_allclose(part.squared_distance_m2, sub.squared_distance_m2)


def test_grouped_pairs_give_the_bits_of_one_call_per_group() -> None:
    """Pairs given as a (2, P) array or a pair of arrays, groups as a list or an array: each
    group's numbers (and Jacobian) are those of one call on its own rays and sigmas."""
    rng = np.random.default_rng(8)
    sizes = [5, 1, 0, 7, 2]
    k = sum(sizes)
    a = rng.uniform(-1.0, 1.0, k)
    tri = triangulate_rays(rng.uniform(0.05, 0.3, (k, 3)), a, a + rng.uniform(0.1, 0.6, k))
    sig = rng.uniform(0.01, 0.05, (len(sizes), 3))
    starts = np.cumsum(sizes) - sizes
    blocks = [np.stack(np.triu_indices(n, 1)) + s for n, s in zip(sizes, starts)]
    idx = np.concatenate(blocks, axis=1)
    counts = [blk.shape[1] for blk in blocks]
    stacked = pair_squared_distances(tri, sig, 0.04, pairs=idx, pair_groups=counts,
                                     with_jacobian=True)
    split = pair_squared_distances(tri, sig, 0.04, pairs=(idx[0], idx[1]),
                                   pair_groups=np.array(counts), with_jacobian=True)
    alone = [pair_squared_distances(tri.subset(np.arange(s, s + n)), sig[g], 0.04,
                                    with_jacobian=True)
             for g, (n, s) in enumerate(zip(sizes, starts))]
    for field in ("first", "second", "squared_distance_m2", "variance_m4", "jacobian"):
        assert getattr(stacked, field).tobytes() == getattr(split, field).tobytes(), field
    for field in ("squared_distance_m2", "variance_m4", "jacobian"):
        one_by_one = np.concatenate([getattr(p, field) for p in alone])
        assert getattr(stacked, field).tobytes() == one_by_one.tobytes(), field
    assert len(stacked) == sum(n * (n - 1) // 2 for n in sizes)
