"""Independent checks of the online bearing variance scale (baselines/ekf/variance_scale.py).

The existing tests run the EKF end to end (halved sigma -> scale near 4); these check the
covariance-matching step itself: one step is the closed form when ``H P H^T`` is zero, it
recovers a true scale within its Monte Carlo error, and its fixed-point steps converge to the
root of ``median(y^2 / (a + lambda sigma^2)) = chi2_1 median`` found by a bracketing solver.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq
from scipy.stats import chi2

from baselines.ekf.variance_scale import NIS_MEDIAN, InnovationVarianceScale


def test_nis_median_is_the_chi2_median() -> None:
    rng = np.random.default_rng(81)
    assert abs(NIS_MEDIAN - np.median(rng.standard_normal(400_000) ** 2)) < 0.005
    assert NIS_MEDIAN == chi2.ppf(0.5, 1)


def test_one_step_recovers_a_true_scale_within_its_monte_carlo_error() -> None:
    """Innovations of variance ``4 sigma^2`` with ``H P H^T = 0``: one step gives
    ``median(y^2) / (sigma^2 NIS_MEDIAN)``, whose s.e. is that of a sample median,
    ``1 / (2 f(m) sqrt(n))`` relative to the chi-square density at its median."""
    rng = np.random.default_rng(82)
    sigma, n, true = 0.01, 20_000, 4.0
    y = rng.normal(0, math.sqrt(true) * sigma, n)
    sc = InnovationVarianceScale(sigma)
    out = sc.scaled(y, np.zeros(n), np.full(n, sigma ** 2), np.ones(n, bool))
    assert abs(sc.value - np.median(y * y) / sigma ** 2 / NIS_MEDIAN) < 1e-12 * sc.value
    np.testing.assert_allclose(out, sigma ** 2 + (sc.value - 1) * sigma ** 2, rtol=1e-15)
    se = true / (2 * chi2.pdf(NIS_MEDIAN, 1) * NIS_MEDIAN * math.sqrt(n))
    assert abs(sc.value - true) < 4 * se, (sc.value, se)


def test_fixed_point_steps_converge_to_the_median_root() -> None:
    rng = np.random.default_rng(83)
    sigma, n = 0.01, 5000
    hph = rng.uniform(0.2, 3.0, n) * sigma ** 2          # the parts the scale leaves alone
    y = rng.normal(0, 1, n) * np.sqrt(hph + 3.0 * sigma ** 2)
    sc = InnovationVarianceScale(sigma)
    sc.scaled(y, hph, np.full(n, sigma ** 2), np.ones(n, bool))
    none = np.zeros(0)
    for _ in range(200):                                  # steps on the same bearings
        sc.scaled(none, none, none, np.zeros(0, bool))
    root = brentq(lambda lam: np.median(y * y / (hph + lam * sigma ** 2)) - NIS_MEDIAN,
                  1.0, 100.0, xtol=1e-12)
    assert abs(sc.value - root) < 1e-6 * root, (sc.value, root)
    assert 2.5 < root < 3.5
