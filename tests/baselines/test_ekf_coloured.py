"""The coloured bearing-error model of the EKFs (baselines/ekf/coloured.py, option
``correlated_fraction``).

What is proved here: the filter's Gauss-Markov step equals ``F P F^T + Q`` with ``F`` the
identity but ``a`` on the decayed states; repeated sightings from one viewing geometry add
(almost) only the white part's information, while the white-noise filter believes every one of
them; new geometry decorrelates the error; the options are validated; off (the default) the
filter is the white-noise one bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from baselines.ekf import EkfConfig, InverseDepthEkfMapper
from baselines.ekf.coloured import ColouredBearingError, ray_directions
from baselines.ekf.filter import BearingEkf
from bomgraph.errors import ConfigError
from bomgraph.mapper import run
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream import Step, StreamHeader


def test_decay_is_the_linear_gauss_markov_step() -> None:
    rng = np.random.default_rng(3)
    f = BearingEkf(np.zeros(3), np.eye(3) * 0.01, 0.02)
    a = rng.normal(size=(6, 6))
    f.augment(rng.normal(size=6), np.arange(3), rng.normal(size=(6, 3)), a @ a.T,
              np.zeros(6, bool))
    x0, p0 = f.x.copy(), f.P.copy()
    idx = np.array([4, 7])
    factor, q = np.array([0.3, 0.8]), np.array([0.5, 0.1])
    f.decay(idx, factor, q)
    big_f = np.eye(9)
    big_f[idx, idx] = factor
    want = big_f @ p0 @ big_f.T
    want[idx, idx] += q
    np.testing.assert_allclose(f.P, want, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(f.x, big_f @ x0, rtol=1e-14)


def test_factors_follow_the_viewing_geometry() -> None:
    col = ColouredBearingError(0.02, 0.6, 0.05)
    assert col.enabled and math.isclose(col.white_sigma_rad ** 2 + col.bias_var_rad2, 0.02 ** 2)
    assert col.factors([1], np.array([0.3]), 0.0)[0] == 1.0          # first sighting
    assert col.factors([1], np.array([0.3]), 0.0)[0] == 1.0          # same geometry
    a = col.factors([1], np.array([0.35]), 0.05)[0]                  # 0.05 + 0.05 rad
    assert math.isclose(a, math.exp(-2.0))
    x = np.array([0.0, 0.0, 0.3, 1.0, 1.0, 2.0, 0.0, math.pi / 2, 0.5])
    d = ray_directions(x, np.array([2, 4]), np.array([3, 5]))
    np.testing.assert_allclose(d, [math.pi / 4, math.atan2(1.0, 0.5 * 2.0)])


def _stare(fraction: float, n: int) -> float:
    """Std. dev. of the bearing direction of a landmark seen ``n`` times from one pose (the
    robot slides once at the start for parallax, then stands still)."""
    header = StreamHeader(bearing_sigma_rad=0.02, odometry_sigma=(1e-4, 1e-4, 1e-4),
                          sensor_range_m=4.0)
    steps = [Step(t=0, odom=None, landmark_ids=[3], bearings_rad=[math.atan2(2.0, 2.0)])]
    steps.append(Step(t=1, odom=[0.0, 1.0, 0.0], landmark_ids=[3],
                      bearings_rad=[math.atan2(1.0, 2.0)]))
    for t in range(2, n + 2):
        steps.append(Step(t=t, odom=[0.0, 0.0, 0.0], landmark_ids=[3],
                          bearings_rad=[math.atan2(1.0, 2.0)]))
    m = InverseDepthEkfMapper(header, correlated_fraction=fraction, max_bearing_nonlinearity=1e9)
    est = run(m, steps).final
    assert est.landmark_ids.tolist() == [3]
    c = est.landmark_cov[0]
    u = np.array([-1.0, 2.0]) / math.sqrt(5.0)          # across the current ray
    return float(np.sqrt(u @ c @ u))


def test_sightings_from_one_geometry_add_only_the_white_information() -> None:
    white_10, white_100 = _stare(0.0, 10), _stare(0.0, 100)
    col_10, col_100 = _stare(0.6, 10), _stare(0.6, 100)
    # the white filter believes every look: 10x the looks, about sqrt(10) x smaller
    assert white_100 < 0.45 * white_10
    # with the coloured part the cross-ray std. dev. cannot fall below its share
    # (sqrt(0.6) * 0.02 rad at about 2.24 m)
    floor = math.sqrt(0.6) * 0.02 * math.sqrt(5.0)
    assert col_100 > 0.9 * floor and col_100 > 0.8 * col_10
    assert col_100 > 2.0 * white_100


def test_options_are_validated_and_off_is_the_white_filter() -> None:
    with pytest.raises(ConfigError, match="correlated_fraction"):
        EkfConfig(correlated_fraction=1.0, candidates="inverse-depth")
    with pytest.raises(ConfigError, match="correlation_length_rad"):
        EkfConfig(correlation_length_rad=0.0)
    with pytest.raises(ConfigError, match="inverse-depth"):
        EkfConfig(correlated_fraction=0.5)                    # clone candidates
    s = simulate(SimConfig(n_landmarks=10, n_steps=40), np.random.default_rng(2))
    a = run(InverseDepthEkfMapper(s.header), s.steps).final
    b = run(InverseDepthEkfMapper(s.header, correlated_fraction=0.0), s.steps).final
    np.testing.assert_array_equal(a.landmarks_xy, b.landmarks_xy)
    c = run(InverseDepthEkfMapper(s.header, correlated_fraction=0.5), s.steps).final
    assert c.info["state_dim"] > a.info["state_dim"]          # one state per landmark
