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


def _fused_distance_monte_carlo(stride: int, n_mc: int = 1500):
    """A fixed geometry: 17 poses along an arc, 3 landmarks seen from every pose; windows of
    5 poses every ``stride`` steps, fused with the "relative" rule (the mapper's inflation for
    overlapping windows). Returns the MC spread of the fused distances and their reported
    first-order variances, shape (3,) each."""
    from bomgraph.stmds.distances import DistanceStore

    w, n_steps = 5, 16
    odom = np.tile([0.15, 0.0, 0.06], (n_steps, 1))
    poses = dead_reckon(odom)
    pts = np.array([[0.9, 0.8], [1.4, 0.5], [0.7, 1.3]])
    brg = np.stack([bearings_to(p, pts) for p in poses])
    sig_odo = np.array([0.002, 0.001, 0.002])      # small: the first-order regime
    sig_b = math.radians(0.15)
    inflation = max(1, math.ceil((w - 1) / stride))
    starts = range(0, n_steps - (w - 1), stride)
    rng = np.random.default_rng(7)
    fused, reported = [], []
    for _ in range(n_mc):
        u = odom + rng.normal(0.0, 1.0, odom.shape) * sig_odo
        b = brg + rng.normal(0.0, sig_b, brg.shape)
        store = DistanceStore("relative", 1)
        for s0 in starts:
            tri, _ = triangulate_window(u[s0:s0 + w - 1], b[s0:s0 + w])
            pe = window_pair_squared_distances(tri, np.tile(sig_odo, (w - 1, 1)), sig_b)
            store.add(pe.first, pe.second, pe.squared_distance_m2, pe.variance_m4 * inflation)
        d, v = store.fused()
        fused.append(d)
        reported.append(v)
    return np.var(np.array(fused), axis=0), np.mean(np.array(reported), axis=0)


def test_fused_variance_of_disjoint_windows_matches_monte_carlo() -> None:
    mc_var, first_order = _fused_distance_monte_carlo(stride=5)
    np.testing.assert_allclose(first_order, mc_var, rtol=0.10)


def test_windows_sharing_their_end_pose_give_a_conservative_variance() -> None:
    # the shared bearings enter consecutive parallaxes with opposite signs
    mc_var, first_order = _fused_distance_monte_carlo(stride=4, n_mc=600)
    ratio = first_order / mc_var
    assert np.all(ratio > 0.9) and np.all(ratio < 2.0), ratio


def test_overlap_inflation_keeps_the_fused_variance_honest() -> None:
    # windows every step share most of their measurements; without the inflation (x4 here)
    # the fused variance would be too small by up to 4x; with it, it is conservative
    # (measured 1.5-2.4x the actual spread on this geometry: the repeats are not fully
    # correlated)
    mc_var, first_order = _fused_distance_monte_carlo(stride=1, n_mc=600)
    ratio = first_order / mc_var
    assert np.all(ratio > 0.9) and np.all(ratio < 3.0), ratio


# ------------------------------------------------------------------------------- the mapper
from bomgraph.errors import ConfigError  # noqa: E402
from bomgraph.evaluate import score_estimate  # noqa: E402
from bomgraph.mapper import create_mapper, run  # noqa: E402
from bomgraph.sim import SimConfig, simulate  # noqa: E402
from bomgraph.stmds.mapper import StmdsConfig  # noqa: E402


def test_mapper_with_window_two_equals_the_paper_rule() -> None:
    s = simulate(SimConfig(n_landmarks=25, n_steps=100), np.random.default_rng(6))
    paper = create_mapper("stmds-smacof", s.header)
    win = create_mapper("stmds-smacof", s.header, tri_window=2)
    est_p, est_w = run(paper, s.steps).final, run(win, s.steps).final
    dp, vp = paper._store.fused()
    dw, vw = win._store.fused()
    assert len(dp) == len(dw) > 100
    np.testing.assert_allclose(dw, dp, rtol=1e-12, atol=0)
    np.testing.assert_allclose(vw, vp, rtol=1e-12, atol=0)
    np.testing.assert_array_equal(est_w.landmark_ids, est_p.landmark_ids)
    np.testing.assert_allclose(est_w.landmarks_xy, est_p.landmarks_xy, atol=1e-9)


@pytest.mark.parametrize("options", [{"tri_window": 3}, {"tri_window": 7, "tri_stride": 7},
                                     {"preset": "window"}, {"preset": "real"}])
@pytest.mark.parametrize("name", ["stmds-cs", "stmds-smacof", "stmds-smacof-loc"])
def test_noise_free_windowed_maps_are_exact(name: str, options: dict) -> None:
    s = simulate(SimConfig(noise_scale=0.0, n_landmarks=20, n_steps=70, sensor_range_m=5.0),
                 np.random.default_rng(3))
    est = run(create_mapper(name, s.header, smacof_from_t=20, **options), s.steps).final
    score = score_estimate(est, s.truth)
    assert score.n_common == 20 and score.mpe_m < 1e-9


def test_window_options_are_validated_and_presets_named() -> None:
    header = simulate(SimConfig(n_steps=3), np.random.default_rng(0)).header
    m = create_mapper("stmds-smacof", header, preset="real", min_count=2)
    assert m.config.tri_window == 16 and m.config.tri_stride == 1 and m.config.min_count == 2
    assert create_mapper("stmds-smacof-loc", header, preset="window").config.robot_ranges \
        == "window"
    for bad in ({"tri_window": 1}, {"tri_window": 2.5}, {"tri_stride": 2},
                {"tri_window": 4, "tri_stride": 5}, {"tri_window": 4, "baselines": (4,)},
                {"tri_window": 4, "max_relative_range_sigma": 0.5},
                {"tri_window": 4, "localise": True}):
        with pytest.raises(ConfigError):
            StmdsConfig(**bad)
