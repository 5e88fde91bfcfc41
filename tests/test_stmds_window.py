"""BOM-STMDS windowed triangulation (issue 8): exactness, Jacobians, the window-2 case, and
the fused variance against a Monte Carlo of the estimator."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bomgraph.geometry import bearings_to, dead_reckon, to_local
from bomgraph.stmds.triangulation import (pair_squared_distances, triangulate_rays,
                                          triangulate_window, window_pair_squared_distances)


def _window_scene(rng: np.random.Generator, w: int = 6, n: int = 7):
    """A curved path of ``w`` poses and ``n`` landmarks ahead, each seen from a random subset
    of at least two poses (NaN bearings elsewhere)."""
    odoms = np.column_stack([rng.uniform(0.1, 0.2, w - 1), rng.uniform(-0.02, 0.02, w - 1),
                             rng.uniform(-0.3, 0.3, w - 1)])
    start = np.array([0.2, -0.1, 0.3])
    poses = dead_reckon(odoms, start)
    pts = start[:2] + rng.uniform([0.5, -1.0], [2.0, 1.5], size=(n, 2))
    brg = np.stack([bearings_to(p, pts) for p in poses])
    seen = rng.random((w, n)) < 0.6
    seen[0, 0] = seen[-1, 0] = True
    seen[:, 1] = False
    seen[w - 2, 1] = seen[w - 1, 1] = True        # landmark 1: only two rays
    for j in range(n):
        if seen[:, j].sum() < 2:
            seen[rng.choice(w, 2, replace=False), j] = True
    return odoms, poses, pts, np.where(seen, brg, np.nan)


@pytest.mark.parametrize("w", [2, 3, 6, 12])
def test_noise_free_window_gives_exact_points_and_distances(w: int) -> None:
    rng = np.random.default_rng(w)
    odoms, poses, pts, brg = _window_scene(rng, w=w)
    tri, n_gated = triangulate_window(odoms, brg)
    assert n_gated == 0 and len(tri) == len(pts)
    np.testing.assert_allclose(tri.points_xy, to_local(poses[0], pts), atol=1e-12)
    pe = window_pair_squared_distances(tri, np.full((w - 1, 3), 0.01), 0.02)
    true = np.sum((pts[pe.first] - pts[pe.second]) ** 2, axis=1)
    np.testing.assert_allclose(pe.squared_distance_m2, true, rtol=0, atol=1e-12)
    assert np.all(pe.variance_m4 > 0)


def test_the_passing_pair_furthest_apart_is_used() -> None:
    rng = np.random.default_rng(1)
    odoms, poses, pts, brg = _window_scene(rng, w=6)
    tri, _ = triangulate_window(odoms, brg)
    for k, j in enumerate(tri.column):
        views = np.flatnonzero(np.isfinite(brg[:, j]))
        assert (tri.pose_first[k], tri.pose_second[k]) == (views[0], views[-1])
    # a gate refusing that pair refuses the landmark (no fall-back: it would select on noise)
    far = brg.copy()
    far[-1, 0] = far[0, 0] - poses[-1, 2] + poses[0, 2]   # parallel rays from poses 0, W-1
    tri2, n_gated = triangulate_window(odoms, far, min_parallax_rad=math.radians(1.0))
    assert 0 not in tri2.column and n_gated == 1


def _numeric_jacobian(f, z: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    cols = []
    for k in range(len(z)):
        dz = np.zeros_like(z)
        dz[k] = eps
        cols.append((f(z + dz) - f(z - dz)) / (2 * eps))
    return np.stack(cols, axis=-1)


def test_window_point_and_pair_jacobians_match_numeric() -> None:
    rng = np.random.default_rng(2)
    w = 5
    odoms, _, _, brg = _window_scene(rng, w=w, n=6)
    tri, _ = triangulate_window(odoms, brg)
    a, b, col = tri.pose_first, tri.pose_second, tri.column
    sig = np.tile([0.03, 0.01, 0.04], (w - 1, 1))
    sb = 0.02
    pe = window_pair_squared_distances(tri, sig, sb, with_jacobian=True)

    def points(z: np.ndarray) -> np.ndarray:
        """All points with the increments and the used bearings of landmarks set from z."""
        bb = brg.copy()
        bb[a, col] = z[3 * (w - 1):3 * (w - 1) + len(col)]
        bb[b, col] = z[3 * (w - 1) + len(col):]
        t, _ = triangulate_window(z[:3 * (w - 1)].reshape(-1, 3), bb)
        assert np.array_equal(t.column, col)          # the same pairs of rays are chosen
        return t.points_xy

    z0 = np.concatenate([odoms.reshape(-1), brg[a, col], brg[b, col]])
    num = _numeric_jacobian(lambda z: points(z).reshape(-1), z0)        # (2k, 3(w-1) + 2k)
    k = len(col)
    ana_odo = tri.jacobian_odometry.reshape(k, -1)
    np.testing.assert_allclose(ana_odo.real, num[0::2, :3 * (w - 1)], atol=1e-7)
    np.testing.assert_allclose(ana_odo.imag, num[1::2, :3 * (w - 1)], atol=1e-7)
    nb = num[:, 3 * (w - 1):]
    idx = np.arange(k)
    np.testing.assert_allclose(tri.jacobian_bearing[:, 0].real, nb[2 * idx, idx], atol=1e-7)
    np.testing.assert_allclose(tri.jacobian_bearing[:, 1].imag, nb[2 * idx + 1, k + idx],
                               atol=1e-7)
    # the pair gradient and the variance J Sigma J^T
    for p in range(len(pe)):
        i, j = pe.first[p], pe.second[p]

        def d2(zz: np.ndarray, i=i, j=j) -> np.ndarray:
            q = points(zz)
            return np.array(np.sum((q[i] - q[j]) ** 2))

        g = _numeric_jacobian(d2, z0)
        expect = np.concatenate([g[:3 * (w - 1)], g[3 * (w - 1) + np.array([i, k + i])],
                                 g[3 * (w - 1) + np.array([j, k + j])]])
        np.testing.assert_allclose(pe.jacobian[p], expect, rtol=1e-6, atol=1e-8)
        sigma = np.concatenate([sig.reshape(-1), [sb] * 4])
        assert pe.variance_m4[p] == pytest.approx(float(np.sum((expect * sigma) ** 2)),
                                                  rel=1e-6)


def test_window_of_two_is_the_sequential_rule() -> None:
    rng = np.random.default_rng(3)
    odom = np.array([0.12, -0.03, -0.2])
    pts = rng.uniform([0.3, -1.0], [2.0, 1.0], size=(8, 2))
    a = bearings_to(np.zeros(3), pts) + rng.normal(0.0, 0.05, 8)
    b = bearings_to(dead_reckon(odom[None, :])[1], pts) + rng.normal(0.0, 0.05, 8)
    sig = np.array([0.03, 0.01, 0.05])
    win, n_gated = triangulate_window(odom[None, :], np.stack([a, b]))
    assert len(win) + n_gated == 8 and len(win) >= 6
    seq = triangulate_rays(odom, a, b).subset(win.column)
    pe_seq = pair_squared_distances(seq, sig, 0.04, with_jacobian=True)
    np.testing.assert_allclose(win.points_xy, seq.points_xy, rtol=0, atol=1e-12)
    np.testing.assert_allclose(win.jacobian_odometry[:, 0, :], seq.jacobian_complex[:, :3],
                               rtol=0, atol=1e-12)
    pe_win = window_pair_squared_distances(win, sig[None, :], 0.04, with_jacobian=True)
    np.testing.assert_array_equal(pe_win.first, pe_seq.first)
    np.testing.assert_allclose(pe_win.squared_distance_m2, pe_seq.squared_distance_m2,
                               rtol=1e-12, atol=0)
    np.testing.assert_allclose(pe_win.variance_m4, pe_seq.variance_m4, rtol=1e-12, atol=0)
    np.testing.assert_allclose(pe_win.jacobian, pe_seq.jacobian, rtol=1e-12, atol=1e-15)
