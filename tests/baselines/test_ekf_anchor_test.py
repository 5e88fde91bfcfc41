"""``ekf``'s ``anchor_test`` (baselines/ekf/anchor.py): an inverse-depth candidate's first
bearing, which no gate can test, is tested once its later sightings constrain it, and a
failing one is taken out of the filter (``BearingEkf.retract``, the inverse of an update).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from baselines.ekf import BearingEkf, EkfConfig, EkfMapper
from baselines.ekf.filter import FilterNumericalError, rows_from_dense
from baselines.ekf.slam import BLOCK_IDP, BLOCK_LM
from bomgraph.errors import ConfigError
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream import Step, Stream

_DEG = math.pi / 180
#: a world whose odometry the filter knows well (3 mm and 0.3 deg a step), bearings 1 deg
_ACCURATE = dict(n_steps=80, n_landmarks=20, sigma_l_m=0.003, sigma_phi_rad=0.3 * _DEG,
                 sigma_theta_rad=1 * _DEG)


def _anchors(m: EkfMapper) -> list[int]:
    """The features whose anchor error is still in the state."""
    from baselines.ekf.slam import BLOCK_ANCHOR     # (here: the file's other tests run on main)
    return [k[1] for k in m._sizes if k[0] == BLOCK_ANCHOR]


def _stream(noise_scale: float = 0.0) -> Stream:
    return simulate(SimConfig(noise_scale=noise_scale, **_ACCURATE), np.random.default_rng(3))


def _run(stream: Stream, steps: list[Step], **options) -> EkfMapper:
    m = EkfMapper(stream.header, start_pose=tuple(stream.truth.poses[0]), preset="real",
                  **options)
    for st in steps:
        m.step(st)
    return m


def _with_first_bearing_off(stream: Stream, landmark: int, k_sigma: float) -> list[Step]:
    """The stream's steps with the first bearing to ``landmark`` moved by ``k_sigma``."""
    steps = list(stream.steps)
    n = next(n for n, st in enumerate(steps) if landmark in st.landmark_ids.tolist())
    st = steps[n]
    z = st.bearings_rad.copy()
    z[st.landmark_ids.tolist().index(landmark)] += k_sigma * stream.header.bearing_sigma_rad
    steps[n] = Step(t=st.t, odom=st.odom, landmark_ids=st.landmark_ids, bearings_rad=z,
                    odom_sigma=st.odom_sigma)
    return steps


def _error_m(m: EkfMapper, stream: Stream, landmark: int) -> float:
    est = m.estimate()
    xy = est.landmarks_xy[est.landmark_ids.tolist().index(landmark)]
    return float(np.linalg.norm(xy - stream.truth.landmarks_xy[
        stream.truth.landmark_ids.tolist().index(landmark)]))


def test_retract_is_the_inverse_of_the_update_of_direct_measurements() -> None:
    rng = np.random.default_rng(0)
    a = rng.normal(size=(6, 6))
    f = BearingEkf(np.zeros(3), np.zeros((3, 3)), 0.05)
    f.augment(rng.normal(size=3), np.arange(3), np.eye(3), np.diag([0.2, 0.3, 0.4]),
              np.zeros(3, bool))
    f.kf.P[:] = a @ a.T + np.eye(6)
    x0, p0 = f.x.copy(), f.P.copy()
    idx, var = np.array([3, 5]), 0.7
    h = np.zeros((2, 6))
    h[[0, 1], idx] = 1.0
    f.update(np.zeros(2), lambda x: (h @ x, rows_from_dense(h)), np.full(2, var))
    assert not np.allclose(f.x, x0)
    f.retract(idx, var)
    np.testing.assert_allclose(f.x, x0, atol=1e-12)
    np.testing.assert_allclose(f.P, p0, atol=1e-12)
    before = f.P.copy()                    # no measurement there to take out: refused, unchanged
    with pytest.raises(FilterNumericalError, match="does not know"):
        f.retract(np.array([4]), 0.5 * float(f.P[4, 4]))
    np.testing.assert_array_equal(f.P, before)


@pytest.mark.parametrize("correlated_fraction", [0.0, 0.5])
def test_without_noise_the_map_is_the_same_and_no_anchor_is_dropped(
        correlated_fraction: float) -> None:
    stream = _stream()
    off = _run(stream, stream.steps, correlated_fraction=correlated_fraction).estimate()
    m = _run(stream, stream.steps, correlated_fraction=correlated_fraction, anchor_test=True)
    on = m.estimate()
    assert on.info["anchors_dropped"] == 0 and "anchors_dropped" not in off.info
    np.testing.assert_array_equal(on.landmark_ids, off.landmark_ids)
    np.testing.assert_allclose(on.landmarks_xy, off.landmarks_xy, atol=1e-9)
    np.testing.assert_allclose(on.landmark_cov, off.landmark_cov, atol=1e-12)
    np.testing.assert_allclose(on.poses, off.poses, atol=1e-9)
    # every anchor the rest came to know was tested and its error marginalised; none is
    # left behind by a feature that is gone
    left = _anchors(m)
    assert on.info["anchors_untested"] == len(left) < len(on.landmark_ids)
    assert all((BLOCK_IDP, i) in m._sizes or (BLOCK_LM, i) in m._sizes for i in left)


def test_a_gross_first_bearing_is_caught_and_taken_out() -> None:
    stream = _stream()
    steps = _with_first_bearing_off(stream, 5, 8.0)          # 8 sigma, at the first step
    off = _run(stream, steps)
    on = _run(stream, steps, anchor_test=True)
    assert on.estimate().info["anchors_dropped_ids"] == [5]
    assert _error_m(off, stream, 5) > 0.015                  # 2.1 cm without the test
    assert _error_m(on, stream, 5) < 0.25 * _error_m(off, stream, 5)     # 0.25 cm with it


def test_a_restarted_feature_gets_a_new_anchor_error() -> None:
    stream = _stream()
    m = _run(stream, _with_first_bearing_off(stream, 6, 8.0), anchor_test=True)
    assert m.n_restarted >= 1                    # gated three times: started again
    anchors = _anchors(m)
    assert len(anchors) == len(set(anchors))
    assert all((BLOCK_IDP, i) in m._sizes or (BLOCK_LM, i) in m._sizes for i in anchors)


def test_the_option_is_checked_and_off_in_every_preset() -> None:
    assert all(EkfConfig.preset(p).anchor_test is False for p in EkfConfig.PRESETS)
    with pytest.raises(ConfigError, match="anchor_test='yes': must be true or false"):
        EkfConfig.preset("real", anchor_test="yes")
    with pytest.raises(ConfigError, match="anchor_test must be true or false"):
        EkfConfig(candidates="inverse-depth", anchor_test=1)
    with pytest.raises(ConfigError, match="anchor_test=true needs candidates='inverse-depth'"):
        EkfConfig.preset("paper", anchor_test=True)
    # h154: `bomgraph methods ekf` shows a doc's first sentence only, which left the need out
    from bomgraph.config import describe_options
    doc = next(o.doc for o in describe_options(EkfConfig) if o.name == "anchor_test")
    assert 'candidates="inverse-depth"' in doc and "False in every preset" in doc, doc


def test_the_state_limit_counts_the_anchor_errors_before_anything_is_added() -> None:
    """h154: the limit was checked for the features' 4 states each, then the anchor errors
    refused as "new landmark or pose blocks", after the features had been added."""
    from baselines.ekf.filter import StateLimitError

    stream = _stream()
    first = stream.steps[0]
    n = first.landmark_ids.size
    m = EkfMapper(stream.header, start_pose=tuple(stream.truth.poses[0]), preset="real",
                  anchor_test=True, max_state=3 + 4 * n)     # room for the features alone
    with pytest.raises(StateLimitError, match=f"with {n} new landmark features to {3 + 5 * n} "):
        m.step(first)
    assert m.filter.dim == 3 and not m._sizes
