"""The inverse-depth prior of the EKF baselines (``rho_prior``, baselines/ekf/range_prior.py).

What is checked here: ``"range"`` is the default of every preset and derives the prior from
the header's range as before (the maps bit for bit: scripts/check_identical.py); on a
simulated stream its maps change with the stated range, while ``"empirical"`` gives the same
map bit for bit whatever range the header states (None, true, x2, x0.5) and maps as many
landmarks (not as well on this 1 m world); its prior is the median of the converted features' inverse depths; its
pseudo-measurement turns a fresh feature's prior into the new one exactly; bad values are
refused.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from baselines.ekf import EkfConfig, InverseDepthConfig
from baselines.ekf.range_prior import EMPIRICAL_MIN
from bomgraph.errors import ConfigError
from bomgraph.evaluate import score_estimate
from bomgraph.mapper import create_mapper, run
from bomgraph.sim import SimConfig, simulate

METHODS = ("ekf", "ekf-invdepth")


@pytest.fixture(scope="module")
def stream():
    return simulate(SimConfig(n_steps=120), np.random.default_rng(3))


def _final(stream, method, factor, **options):
    rng = stream.header.sensor_range_m
    header = dataclasses.replace(stream.header,
                                 sensor_range_m=None if factor is None else rng * factor)
    mapper = create_mapper(method, header, preset="real", **options)
    return mapper, run(mapper, stream.steps, checkpoint_every=10).final


def _same(a, b) -> bool:
    return (np.array_equal(a.landmark_ids, b.landmark_ids)
            and np.array_equal(a.landmarks_xy, b.landmarks_xy)
            and np.array_equal(a.poses, b.poses)
            and np.array_equal(a.landmark_cov, b.landmark_cov))


@pytest.mark.parametrize("cls", [EkfConfig, InverseDepthConfig])
def test_range_is_every_presets_default(cls):
    for name in cls.PRESETS:
        assert cls.preset(name).rho_prior == "range"


@pytest.mark.parametrize("method", METHODS)
def test_default_is_the_range_prior(stream, method):
    m0, default = _final(stream, method, 1.0)
    m1, explicit = _final(stream, method, 1.0, rho_prior="range")
    assert _same(default, explicit)
    rng = stream.header.sensor_range_m
    assert (m0.rho_init, m0.rho_sigma) == (2.0 / rng, 1.0 / rng)
    m2, _ = _final(stream, method, None)
    assert (m2.rho_init, m2.rho_sigma) == (0.1, 0.5)


@pytest.mark.parametrize("method", METHODS)
def test_range_prior_follows_the_stated_range(stream, method):
    finals = [_final(stream, method, f)[1] for f in (1.0, None, 2.0, 0.5)]
    assert not all(_same(finals[0], f) for f in finals[1:])


@pytest.mark.parametrize("method", METHODS)
def test_empirical_map_ignores_the_stated_range(stream, method):
    m, first = _final(stream, method, 1.0, rho_prior="empirical")
    for f in (None, 2.0, 0.5):
        assert _same(first, _final(stream, method, f, rho_prior="empirical")[1])
    st = m._rho_state
    assert len(st["converted"]) >= EMPIRICAL_MIN
    mean, sd = st["prior"]
    assert mean == pytest.approx(float(np.median(st["converted"])))
    assert sd >= 0.5 * mean
    # it maps as many landmarks as the prior from the true range, within 2 (its MPE on this
    # 1 m world is worse: the range-free start, 10 m, is far off; docs/measurements.md)
    _, ranged = _final(stream, method, 1.0)
    assert len(first) >= len(ranged) - 2
    assert np.isfinite(score_estimate(first, stream.truth).mpe_m)


def test_pseudo_measurement_sets_the_new_prior(stream):
    mapper = create_mapper("ekf-invdepth", stream.header, preset="real", rho_prior="empirical")
    mapper._add_inverse_depth(np.array([7]), np.array([0.3]))
    st = mapper._rho_state
    off = mapper._offset[("idp", 7)] + 3
    assert mapper.filter.x[off] == 0.1 and mapper.filter.P[off, off] == pytest.approx(0.25)
    st["prior"] = (0.8, 0.2)
    mapper._tighten(st)
    assert mapper.filter.x[off] == pytest.approx(0.8)
    assert mapper.filter.P[off, off] == pytest.approx(0.04)
    assert st["feature"][7] == (0.8, 0.2) and st["tightened"] == 1
    mapper._tighten(st)                  # already at that prior: nothing more
    assert st["tightened"] == 1 and mapper.filter.P[off, off] == pytest.approx(0.04)


@pytest.mark.parametrize("cls", [EkfConfig, InverseDepthConfig])
def test_bad_rho_prior_refused(cls):
    with pytest.raises(ConfigError, match="rho_prior"):
        cls(rho_prior="guess")
