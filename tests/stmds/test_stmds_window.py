"""BOM-STMDS windowed triangulation (issue 8): exactness, Jacobians, the window-2 case, and
the fused variance against a Monte Carlo of the estimator."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bomgraph.geometry import bearings_to, dead_reckon, to_local
from bomgraph.stmds.triangulation import pair_squared_distances, triangulate_rays
from bomgraph.stmds.window import (WindowTriangulation, triangulate_window,
                                   triangulate_window_lsq, triangulate_windows_lsq,
                                   window_lsq_points, window_pair_squared_distances)
from test_stmds_triangulation import _numeric_jacobian  # the central-difference helper


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


def _assert_exact_pair_distances(tri, pts: np.ndarray, w: int) -> None:
    """Noise-free window: every pair's squared distance exact, every variance positive."""
    pe = window_pair_squared_distances(tri, np.full((w - 1, 3), 0.01), 0.02)
    true = np.sum((pts[pe.first] - pts[pe.second]) ** 2, axis=1)
    np.testing.assert_allclose(pe.squared_distance_m2, true, rtol=0, atol=1e-12)
    assert np.all(pe.variance_m4 > 0)


@pytest.mark.parametrize("w", [2, 3, 6, 12])
def test_noise_free_window_gives_exact_points_and_distances(w: int) -> None:
    rng = np.random.default_rng(w)
    odoms, poses, pts, brg = _window_scene(rng, w=w)
    tri, n_gated = triangulate_window(odoms, brg)
    assert n_gated == 0 and len(tri) == len(pts)
    np.testing.assert_allclose(tri.points_xy, to_local(poses[0], pts), atol=1e-12)
    _assert_exact_pair_distances(tri, pts, w)


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


# ------------------------------------------------------------- least squares over all rays
@pytest.mark.parametrize("w", [2, 3, 6, 12])
def test_lsq_window_is_exact_on_noise_free_rays(w: int) -> None:
    rng = np.random.default_rng(w)
    odoms, poses, pts, brg = _window_scene(rng, w=w)
    tri, n_gated = triangulate_window_lsq(odoms, brg)
    assert n_gated == 0 and len(tri) == len(pts)
    np.testing.assert_allclose(tri.points_xy, to_local(poses[0], pts), rtol=0, atol=1e-12)
    assert tri.jacobian_bearing.shape == (len(pts), w)
    assert np.all((tri.jacobian_bearing != 0) == np.isfinite(brg[:, tri.column].T))
    _assert_exact_pair_distances(tri, pts, w)


def test_lsq_windows_at_once_are_each_window_alone_bit_for_bit() -> None:
    """The batched kernel (windows padded to one bearing matrix, landmarks dropped from the
    Gauss-Newton loop as they converge) gives each window's numbers exactly: noisy windows of
    different landmark counts, one with no landmark seen twice, one with gated landmarks."""
    rng = np.random.default_rng(21)
    w = 6
    odoms_list, brg_list = [], []
    for n in (7, 3, 9, 2, 5):
        odoms, _, _, brg = _window_scene(rng, w=w, n=n)
        brg = brg + rng.normal(0.0, 0.02, brg.shape)
        odoms_list.append(odoms + rng.normal(0.0, 0.005, odoms.shape))
        brg_list.append(brg)
    brg_list[3][:, :] = np.nan
    brg_list[3][0, 0] = brg_list[3][2, 1] = 0.3            # every landmark seen once
    brg_list[1][:, 0] = brg_list[1][0, 0]                  # parallel rays: gated
    batch = triangulate_windows_lsq(odoms_list, brg_list, max_range_m=5.0)
    assert len(batch) == len(brg_list)
    for odoms, brg, (tri, n_gated) in zip(odoms_list, brg_list, batch):
        alone, n_alone = triangulate_window_lsq(odoms, brg, max_range_m=5.0)
        assert n_gated == n_alone
        for name in WindowTriangulation.__dataclass_fields__:
            a, b = getattr(tri, name), getattr(alone, name)
            assert a.shape == b.shape and a.tobytes() == b.tobytes(), name
    assert len(batch[3][0]) == 0 and batch[1][1] >= 1
    for odoms, brg, (tri, _) in zip(odoms_list, brg_list, batch):   # the bundle's start
        column, points = window_lsq_points(odoms, brg, max_range_m=5.0)
        assert column.tobytes() == tri.column.tobytes()
        assert points.tobytes() == tri.points_xy.tobytes()
    assert sum(len(t) for t, _ in batch) > 10


def test_lsq_window_of_two_rays_is_the_pair_rule() -> None:
    # two rays: the least-squares point is their intersection, with the same Jacobians
    rng = np.random.default_rng(3)
    odoms, _, _, brg = _window_scene(rng, w=2)
    brg = brg + rng.normal(0.0, 0.03, brg.shape)
    pair, _ = triangulate_window(odoms, brg)
    lsq, _ = triangulate_window_lsq(odoms, brg)
    np.testing.assert_array_equal(lsq.column, pair.column)
    np.testing.assert_allclose(lsq.points_xy, pair.points_xy, rtol=0, atol=1e-12)
    np.testing.assert_allclose(lsq.jacobian_odometry, pair.jacobian_odometry, rtol=1e-8,
                               atol=1e-9)
    np.testing.assert_allclose(lsq.jacobian_bearing, pair.jacobian_bearing, rtol=1e-8,
                               atol=1e-9)


def test_lsq_window_jacobians_match_numeric_on_noisy_rays() -> None:
    # noisy rays: nonzero residuals, so the implicit-function Jacobian needs the full Hessian
    rng = np.random.default_rng(5)
    w = 6
    odoms, _, _, brg = _window_scene(rng, w=w)
    brg[:, 1] = np.nan                            # two close rays: at the edge of a gate
    brg = brg + rng.normal(0.0, 0.03, brg.shape)
    tri, _ = triangulate_window_lsq(odoms, brg)
    seen = np.isfinite(brg)
    c = 3 * (w - 1)
    k = len(tri)
    assert k == 6

    def points(z: np.ndarray) -> np.ndarray:
        bb = brg.copy()
        bb[seen] = z[c:]
        t, _ = triangulate_window_lsq(z[:c].reshape(-1, 3), bb)
        assert np.array_equal(t.column, tri.column)
        return t.points_xy

    z0 = np.concatenate([odoms.reshape(-1), brg[seen]])
    num = _numeric_jacobian(lambda z: points(z).reshape(-1), z0)       # (2k, c + n_seen)
    ana_odo = tri.jacobian_odometry.reshape(k, -1)
    np.testing.assert_allclose(ana_odo.real, num[0::2, :c], atol=1e-7)
    np.testing.assert_allclose(ana_odo.imag, num[1::2, :c], atol=1e-7)
    # bearings, in the row-major order of brg[seen]
    row_of = np.full(brg.shape[1], -1)
    row_of[tri.column] = np.arange(k)
    pose_s, col_s = np.nonzero(seen)
    ana_b = np.zeros((2 * k, len(pose_s)))
    used = row_of[col_s] >= 0
    cols = np.flatnonzero(used)
    jb = tri.jacobian_bearing[row_of[col_s[used]], pose_s[used]]
    ana_b[2 * row_of[col_s[used]], cols] = jb.real
    ana_b[2 * row_of[col_s[used]] + 1, cols] = jb.imag
    np.testing.assert_allclose(ana_b, num[:, c:], atol=1e-7)
    # the pair gradient: d|p_i - p_j|^2 through all increments and every bearing used
    pe = window_pair_squared_distances(tri, np.full((w - 1, 3), 0.02), 0.01, with_jacobian=True)
    for p in range(0, len(pe), 4):
        i, j = pe.first[p], pe.second[p]
        g = _numeric_jacobian(lambda z, i=i, j=j: np.array(np.sum(
            (points(z)[i] - points(z)[j]) ** 2)), z0)
        bi = pose_s[col_s == tri.column[i]], np.flatnonzero(col_s == tri.column[i])
        bj = pose_s[col_s == tri.column[j]], np.flatnonzero(col_s == tri.column[j])
        np.testing.assert_allclose(pe.jacobian[p, :c], g[:c], rtol=1e-6, atol=1e-8)
        np.testing.assert_allclose(pe.jacobian[p, c + bi[0]], g[c + bi[1]], rtol=1e-6,
                                   atol=1e-8)
        np.testing.assert_allclose(pe.jacobian[p, c + w + bj[0]], g[c + bj[1]], rtol=1e-6,
                                   atol=1e-8)
        unseen = np.setdiff1d(np.arange(w), bi[0])
        assert np.all(pe.jacobian[p, c + unseen] == 0)


def test_lsq_window_gates_parallax_and_rays_behind() -> None:
    rng = np.random.default_rng(1)
    odoms, poses, pts, brg = _window_scene(rng, w=6)
    par = brg.copy()
    par[:, 0] = np.where(np.isfinite(par[:, 0]), par[0, 0] - poses[:, 2] + poses[0, 2],
                         np.nan)                  # landmark 0: all its rays parallel
    tri, n_gated = triangulate_window_lsq(odoms, par, min_parallax_rad=math.radians(1.0))
    assert 0 not in tri.column and n_gated == 1
    near, _ = triangulate_window_lsq(odoms, brg, max_range_m=0.1)
    assert len(near) == 0


def _fused_distance_monte_carlo(stride: int, n_mc: int = 1500, kernel=triangulate_window):
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
            tri, _ = kernel(u[s0:s0 + w - 1], b[s0:s0 + w])
            pe = window_pair_squared_distances(tri, np.tile(sig_odo, (w - 1, 1)), sig_b)
            store.add(pe.first, pe.second, pe.squared_distance_m2, pe.variance_m4 * inflation)
        d, v = store.fused()
        fused.append(d)
        reported.append(v)
    return np.var(np.array(fused), axis=0), np.mean(np.array(reported), axis=0)


def test_fused_variance_of_disjoint_windows_matches_monte_carlo() -> None:
    mc_var, first_order = _fused_distance_monte_carlo(stride=5)
    np.testing.assert_allclose(first_order, mc_var, rtol=0.10)


def test_fused_lsq_variance_of_disjoint_windows_matches_monte_carlo() -> None:
    mc_var, first_order = _fused_distance_monte_carlo(stride=5, n_mc=1000,
                                                      kernel=triangulate_window_lsq)
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
                                     {"preset": "window"}, {"preset": "real"},
                                     {"preset": "real-keyframes"},
                                     {"preset": "window", "tri_method": "lsq"},
                                     {"tri_window": 8, "tri_method": "ba"},
                                     {"tri_window": 9, "tri_stride": 3, "tri_method": "ba",
                                      "tri_grow": 2}])
@pytest.mark.parametrize("name", ["stmds-cs", "stmds-smacof", "stmds-smacof-loc"])
def test_noise_free_windowed_maps_are_exact(name: str, options: dict) -> None:
    # the "real" preset's windows are 60 steps long: the run must hold a few of them
    n_steps = 130 if str(options.get("preset")).startswith("real") else 70
    s = simulate(SimConfig(noise_scale=0.0, n_landmarks=20, n_steps=n_steps,
                           sensor_range_m=5.0), np.random.default_rng(3))
    if name.endswith("-loc") and "preset" not in options:
        options = {**options, "robot_ranges": "all-poses"}
    mapper = create_mapper(name, s.header, smacof_from_t=20, **options)
    est = run(mapper, s.steps).final
    score = score_estimate(est, s.truth)
    # every fused distance is exact ...
    known = mapper._store.known()
    ids = mapper._ids.ids
    order = np.argsort(s.truth.landmark_ids)
    xy = s.truth.landmarks_xy[order]
    a = np.searchsorted(s.truth.landmark_ids[order], ids[known.first])
    b = np.searchsorted(s.truth.landmark_ids[order], ids[known.second])
    np.testing.assert_allclose(known.distance_m, np.linalg.norm(xy[a] - xy[b], axis=1),
                               rtol=0, atol=1e-9)
    # ... and so is the map, except Method 1 with missing pairs: its shortest paths
    # overestimate them (the paper's DMC-SPL), so it is only close
    complete = len(known) == 20 * 19 // 2
    assert score.n_common == 20
    assert score.mpe_m < (1e-9 if complete or name != "stmds-cs" else 1e-2)


def test_window_options_are_validated_and_presets_named() -> None:
    header = simulate(SimConfig(n_steps=3), np.random.default_rng(0)).header
    m = create_mapper("stmds-smacof", header, preset="real-keyframes", min_count=2)
    assert m.config.tri_window == 60 and m.config.tri_stride == 10 and m.config.min_count == 2
    assert m.config.tri_method == "ba"
    real = create_mapper("stmds-smacof", header, preset="real").config
    assert real.tri_window is None and real.geometric_windows and real.tri_method == "ba"
    assert create_mapper("stmds-smacof-loc", header, preset="window").config.robot_ranges \
        == "all-poses"
    for bad in ({"tri_window": 1}, {"tri_window": 2.5}, {"tri_stride": 2},
                {"tri_window": 4, "tri_stride": 5}, {"tri_window": 4, "baseline_steps": (4,)},
                {"tri_window": 4, "max_relative_range_sigma": 0.5},
                {"tri_window": 4, "localise": True}, {"tri_method": "lsq"},
                {"tri_window": 4, "tri_method": "all"}):
        with pytest.raises(ConfigError):
            StmdsConfig(**bad)
