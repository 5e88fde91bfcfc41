"""The robust start of window bundles (``tri_robust_start``, issue 15): a ray that points away
from where a landmark's other rays put it (a misidentified detection) no longer refuses its
landmark from every window that holds it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bomgraph.geometry import bearings_to, dead_reckon
from bomgraph.stmds.bundle import _start_without_outlier, bundle_adjust_window
from bomgraph.stmds.config import StmdsConfig

DEG = math.pi / 180.0
ODOM = np.tile([0.25, 0.0, 0.05], (7, 1))
POINTS = np.array([[0.5, 1.3], [1.2, -1.1], [1.8, 1.6], [0.9, 2.4], [2.0, -1.8]])
SIGMA_ODO = np.array([0.01, 0.005, 0.01])
SIGMA_B = 1.0 * DEG


def _window(seed: int = 3):
    rng = np.random.default_rng(seed)
    poses = dead_reckon(ODOM)
    brg = np.stack([bearings_to(p, POINTS) for p in poses])
    u = ODOM + rng.standard_normal(ODOM.shape) * SIGMA_ODO
    return (u, np.tile(SIGMA_ODO, (len(ODOM), 1)),
            brg + rng.normal(0.0, SIGMA_B, brg.shape))


@pytest.mark.parametrize("pose", [0, 3])
def test_a_ray_pointing_away_is_dropped_not_its_landmark(pose: int) -> None:
    u, sig, brg = _window()
    bad = brg.copy()
    bad[pose, 1] += math.pi                          # the landmark behind the robot
    without = brg.copy()
    without[pose, 1] = np.nan
    plain, _ = bundle_adjust_window(u, sig, bad, SIGMA_B, tol=1e-10)
    assert 1 not in plain.column                     # the start refuses landmark 1
    robust, n_gated = bundle_adjust_window(u, sig, bad, SIGMA_B, tol=1e-10, robust_start=True)
    ref, _ = bundle_adjust_window(u, sig, without, SIGMA_B, tol=1e-10)
    assert n_gated == 0 and robust.n_outliers == 1
    np.testing.assert_array_equal(robust.column, np.arange(5))
    np.testing.assert_array_equal(robust.n_rays, [8, 7, 8, 8, 8])
    np.testing.assert_allclose(robust.points_xy, ref.points_xy, rtol=0, atol=1e-7)


def test_a_clean_window_is_unchanged_bit_for_bit() -> None:
    u, sig, brg = _window()
    a, _ = bundle_adjust_window(u, sig, brg, SIGMA_B)
    b, _ = bundle_adjust_window(u, sig, brg, SIGMA_B, robust_start=True)
    assert np.array_equal(a.points_xy, b.points_xy) and np.array_equal(a.poses, b.poses)
    assert np.array_equal(a.covariance_m2, b.covariance_m2)


def test_a_ray_from_beside_the_point_is_not_called_an_outlier() -> None:
    # three rays from far (2-3 m) agree on the point; the fourth, from a pose 0.1 m beside
    # it, points the other way: seen from that close a small pose error turns a bearing
    # through any angle, so the ray is kept (the landmark stays refused)
    point = np.array([3.0, 0.0])
    poses = np.array([[0.0, 0.0, 0.0], [0.2, 0.8, 0.0], [0.5, -0.7, 0.0], [2.9, 0.0, 0.0]])
    brg = np.array([[bearings_to(p, point[None])[0]] for p in poses])
    brg[3, 0] += math.pi
    k, c, _ = _start_without_outlier(poses, brg, np.array([0]), 0.0, np.inf, 10)
    assert c.size == 0
    # the same ray from 2 m away is one
    poses[3] = [1.0, 0.0, 0.0]
    brg[3, 0] = bearings_to(poses[3], point[None])[0] + math.pi
    k, c, xy = _start_without_outlier(poses, brg, np.array([0]), 0.0, np.inf, 10)
    assert c.tolist() == [0] and k.tolist() == [3]
    np.testing.assert_allclose(xy[0], point, atol=1e-9)


def test_the_real_preset_uses_it_and_the_paper_does_not() -> None:
    assert StmdsConfig.preset("real").tri_robust_start
    assert not StmdsConfig().tri_robust_start
