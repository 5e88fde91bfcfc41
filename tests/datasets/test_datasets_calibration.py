"""Calibration against truth: odometry errors, the odometry sigma fit, robust bearing statistics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bomgraph.datasets.calibration import (fit_odometry_sigma, odometry_errors,
                                           odometry_sigma_model, robust_bearing_stats)
from bomgraph.geometry import between


def _odometry_sample(seed: int, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` steps ``u`` (dx, dy, dpsi), a known sigma ``model`` and errors ``e`` drawn from it."""
    rng = np.random.default_rng(seed)
    u = np.column_stack([rng.uniform(0.05, 0.6, n), rng.uniform(-0.02, 0.02, n),
                         rng.uniform(-0.6, 0.6, n)])
    model = np.array([[0.005, 0.08, 0.02], [0.004, 0.03, 0.05], [0.01, 0.1, 0.12]])
    return u, model, rng.standard_normal((n, 3)) * odometry_sigma_model(model, u)


def test_fit_odometry_sigma_recovers_a_known_model():
    u, model, e = _odometry_sample(7, 4000)
    e[:5] += 5.0  # gross errors are excluded, not fitted
    fit, info = fit_odometry_sigma(u, e)
    assert info["n_excluded"] >= 5
    sig_true = odometry_sigma_model(model, u)
    sig_fit = odometry_sigma_model(fit, u)
    np.testing.assert_allclose(np.median(sig_fit / sig_true, axis=0), 1.0, atol=0.05)
    np.testing.assert_allclose(fit[:, 1:], model[:, 1:], rtol=0.2)



def test_a_step_gross_in_one_component_is_left_out_of_the_refit():
    """(h102) The refit keeps the steps within 5 sigmas in *every* component."""
    u, model, e = _odometry_sample(3, 2000)
    e[:20, 0] += 2.0   # dx only: dy and the turn are fine on these steps
    fit, info = fit_odometry_sigma(u, e)
    assert info["n_excluded"] >= 20
    np.testing.assert_allclose(fit[0, 1:], model[0, 1:], rtol=0.25)

def test_robust_bearing_stats_on_known_residuals():
    rng = np.random.default_rng(1)
    r = 0.004 + 0.006 * rng.standard_normal(20000)
    r[:100] += 1.0
    st = robust_bearing_stats(r)
    assert st["bias_rad"] == pytest.approx(0.004, abs=2e-4)
    assert st["spread_rad"] == pytest.approx(0.006, rel=0.03)
    assert st["n_gross"] == 100 and st["n_outliers"] >= 100
    assert st["sigma_rad"] == pytest.approx(math.hypot(0.004, 0.006), rel=0.03)


def test_odometry_errors_wrap_the_heading():
    truth = np.array([[0.0, 0.0, 3.0], [1.0, 0.0, -3.0]])
    inc = between(truth[:-1], truth[1:])
    odoms = inc + np.array([[0.01, -0.02, 2 * math.pi + 0.03]])
    err, true_inc = odometry_errors(odoms, truth)
    np.testing.assert_allclose(true_inc, inc)
    np.testing.assert_allclose(err, [[0.01, -0.02, 0.03]], atol=1e-12)
