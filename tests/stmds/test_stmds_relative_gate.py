"""The relative depth gate of window bundles (``max_relative_range_sigma`` with
``tri_method="ba"``): a landmark is mapped once a window's covariance says it triangulated it
well (issue 15: admission by the rays' actual geometry, not by an angle)."""

from __future__ import annotations

import math

import numpy as np

from bomgraph.evaluate import score_estimate
from bomgraph.geometry import bearings_to, dead_reckon, to_local
from bomgraph.mapper import create_mapper, run
from bomgraph.sim import SimConfig, simulate
from bomgraph.stmds.bundle import bundle_adjust_window, relative_range_sigma
from bomgraph.stmds.config import StmdsConfig


def _straight_window(depths_m: tuple[float, ...], w: int = 8, step_m: float = 0.2):
    """``w`` poses along the x axis, one landmark beside the path at each depth (seen from
    every pose), noise free. Returns odoms, bearings, the points in the first pose's frame."""
    odoms = np.tile([step_m, 0.0, 0.0], (w - 1, 1))
    poses = dead_reckon(odoms)
    mid = step_m * (w - 1) / 2
    pts = np.array([[mid + 0.3 * i, d] for i, d in enumerate(depths_m)])
    brg = np.stack([bearings_to(p, pts) for p in poses])
    return odoms, brg, to_local(poses[0], pts)


def test_noise_free_window_is_exact_and_far_landmarks_score_worse() -> None:
    odoms, brg, pts = _straight_window((1.5, 3.0, 6.0, 12.0))
    sig = np.tile([0.01, 0.005, 0.01], (len(odoms), 1))
    bundle, _ = bundle_adjust_window(odoms, sig, brg, 0.01, outlier_sigma=None)
    np.testing.assert_allclose(bundle.points_xy, pts, rtol=0, atol=1e-9)
    rel = relative_range_sigma(bundle, brg)
    # the same baseline: the relative error grows with the depth (about linearly)
    assert np.all(np.diff(rel) > 0)
    assert rel[-1] / rel[0] > 4.0
    # first order: every std. dev. scales with the noise
    half, _ = bundle_adjust_window(odoms, sig / 2, brg, 0.005, outlier_sigma=None)
    np.testing.assert_allclose(relative_range_sigma(half, brg), rel / 2, rtol=1e-6)


def test_relative_sigma_is_the_largest_axis_of_the_ellipse_over_the_mean_range() -> None:
    odoms, brg, _ = _straight_window((2.0, 5.0))
    sig = np.tile([0.01, 0.005, 0.01], (len(odoms), 1))
    bundle, _ = bundle_adjust_window(odoms, sig, brg, 0.01, outlier_sigma=None)
    poses = bundle.poses
    for j in range(len(bundle)):
        block = bundle.covariance_m2[2 * j:2 * j + 2, 2 * j:2 * j + 2]
        rng = np.hypot(*(bundle.points_xy[j] - poses[:, :2]).T).mean()
        assert math.isclose(relative_range_sigma(bundle, brg)[j],
                            math.sqrt(np.linalg.eigvalsh(block)[-1]) / rng, rel_tol=1e-9)


def test_the_gate_maps_a_subset_exactly_without_noise() -> None:
    run_ = simulate(SimConfig(noise_scale=0.0, n_landmarks=30, n_steps=80),
                    np.random.default_rng(5))
    header = run_.header
    kw = {"tri_estimate_sigma": False}
    free = run(create_mapper("stmds-smacof", header, preset="real",
                             max_relative_range_sigma=math.inf, **kw),
               run_.steps).final
    gated = run(create_mapper("stmds-smacof", header, preset="real",
                              max_relative_range_sigma=0.1, **kw), run_.steps).final
    assert 3 <= len(gated) < len(free)
    assert set(gated.landmark_ids) <= set(free.landmark_ids)
    # noise free, every window's estimate is exact: the gated map is the truth up to a motion
    assert score_estimate(gated, run_.truth).mpe_m < 1e-6


def test_real_preset_accepts_the_gate_and_keyframe_windows_without_bundle_refuse_it() -> None:
    StmdsConfig.preset("real", max_relative_range_sigma=0.1)
    try:
        StmdsConfig(tri_window=6, max_relative_range_sigma=0.1)
    except Exception as exc:                                  # ConfigError
        assert "relative depth gate" in str(exc)
    else:
        raise AssertionError("tri_method='pair' windows took the relative depth gate")
