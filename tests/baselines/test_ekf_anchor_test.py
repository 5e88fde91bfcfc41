"""``ekf``'s ``anchor_test`` (baselines/ekf/anchor.py): an inverse-depth candidate's first
bearing, which no gate can test, is tested once its later sightings constrain it, and a
failing one is taken out of the filter (``BearingEkf.retract``, the inverse of an update).
"""

from __future__ import annotations

import math
from typing import Any

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


def _linear_problem(rng: np.random.Generator, with_e: bool, s2: float
                    ) -> tuple[BearingEkf, list[int], list[int], dict]:
    """A linear-Gaussian stand-in for a run: a pose, a landmark, two features' ``theta`` from
    anchors at pose 0 (``theta = psi + z + w``), the anchor errors as the mixin adds them
    (``e = theta - psi - z``), then 12 linear predicts and updates of rows on the pose, one
    ``theta`` and the landmark (none on ``e``)."""
    T = 12
    p = {"F": np.eye(3) + 0.05 * rng.normal(size=(3, 3)), "u": 0.01 * rng.normal(size=3),
         "Q": np.diag([1e-4, 2e-4, 3e-4]), "m0": np.array([0.0, 0.0, 0.1]),
         "P0": np.diag([1e-6, 1e-6, 1e-4]), "ml": np.array([1.0, 2.0]),
         "Pl": np.diag([0.5, 0.7]), "z": np.array([0.3, -0.2]), "T": T, "rv": 1e-4,
         "H": rng.normal(size=(T, 3, 6)), "y": 0.1 * rng.normal(size=(T, 3))}
    f = BearingEkf(p["m0"], p["P0"], 0.05)
    f.augment(p["ml"], np.zeros(0, np.int64), np.zeros((2, 0)), p["Pl"], np.zeros(2, bool))
    th = [f.augment(np.array([f.x[2] + z]), np.array([2]), np.ones((1, 1)), np.array([s2]),
                    np.zeros(1, bool)) for z in p["z"]]
    eo = [f.augment(np.zeros(1), np.array([2, t]), np.array([[-1.0, 1.0]]), np.zeros(1),
                    np.zeros(1, bool)) for t in th] if with_e else []
    for t in range(T):
        J = np.eye(f.dim)
        J[:3, :3] = p["F"]
        f.kf.x[:3] = p["F"] @ f.kf.x[:3] + p["u"]
        f.kf.P[:] = J @ f.kf.P @ J.T
        f.kf.P[:3, :3] += p["Q"]
        cols = np.array([[0, 1, 2, th[r % 2], 3, 4] for r in range(3)])
        y = p["y"][t] - np.einsum("ks,ks->k", p["H"][t], f.x[cols])
        f.update_rows(cols, p["H"][t], y, np.full(3, p["rv"]))
    return f, th, eo, p


def _batch(p: dict, anchors: list[int], s2: float) -> tuple[np.ndarray, np.ndarray, Any]:
    """The same problem solved at once over every pose, with the anchor factors ``anchors``
    only; the mean and covariance of (last pose, landmark, thetas)."""
    T = p["T"]
    it, il = 3 * (T + 1), 3 * (T + 1) + 2
    A, b = np.zeros((il + 2, il + 2)), np.zeros(il + 2)

    def factor(row: np.ndarray, cols: np.ndarray, r: Any, R: Any) -> None:
        W, row = np.linalg.inv(np.atleast_2d(R)), np.atleast_2d(row)
        A[np.ix_(cols, cols)] += row.T @ W @ row
        b[cols] += row.T @ W @ np.atleast_1d(r)

    factor(np.eye(3), np.arange(3), p["m0"], p["P0"])
    factor(np.eye(2), np.arange(il, il + 2), p["ml"], p["Pl"])
    for t in range(T):
        factor(np.hstack([-p["F"], np.eye(3)]), np.arange(3 * t, 3 * t + 6), p["u"], p["Q"])
        for r in range(3):
            factor(p["H"][t][r], np.r_[3 * t + 3:3 * t + 6, it + r % 2, il, il + 1],
                   p["y"][t][r], p["rv"])
    for j in anchors:
        factor(np.array([1.0, -1.0]), np.array([it + j, 2]), p["z"][j], s2)
    C = np.linalg.inv(A)
    keep = np.r_[3 * T:3 * T + 3, il, il + 1, it, it + 1]
    return (C @ b)[keep], C[np.ix_(keep, keep)], (C @ b, C, it)


def test_retract_is_the_solve_without_the_anchor_and_the_test_its_leave_one_out() -> None:
    """h154, derived apart from the module: on a linear problem with predicts between, the
    anchor errors leave the other states as they were, the retraction of one or both
    anchors is the batch solve without them, and ``e_hat^2 / (sigma^2 - P_e)`` is the
    anchor's statistic against the batch posterior without it."""
    s2 = 0.02 ** 2
    f, th, eo, p = _linear_problem(np.random.default_rng(7), True, s2)
    plain, _, _, _ = _linear_problem(np.random.default_rng(7), False, s2)
    sel = np.r_[0:5, th]
    np.testing.assert_allclose(f.x[sel], plain.x, atol=1e-13)
    np.testing.assert_allclose(f.P[np.ix_(sel, sel)], plain.P, atol=1e-16)
    mean, cov, _ = _batch(p, [0, 1], s2)
    np.testing.assert_allclose(f.x[sel], mean, atol=1e-12)
    _, _, (mu, C, it) = _batch(p, [1], s2)
    d = np.zeros(len(mu))
    d[[it, 2]] = 1.0, -1.0
    loo = (p["z"][0] - d @ mu) ** 2 / (d @ C @ d + s2)
    e_hat, pe = f.x[eo[0]], f.P[eo[0], eo[0]]
    assert loo > 10 and e_hat ** 2 / (s2 - pe) == pytest.approx(loo, rel=1e-9)
    for drop in ([0], [0, 1]):
        g, th, eo, _ = _linear_problem(np.random.default_rng(7), True, s2)
        g.retract(np.array([eo[j] for j in drop]), s2)
        mean, cov, _ = _batch(p, [j for j in (0, 1) if j not in drop], s2)
        assert np.abs(g.x[sel] - f.x[sel]).max() > 1e-3           # the anchor pulled
        np.testing.assert_allclose(g.x[sel], mean, atol=1e-12)
        np.testing.assert_allclose(g.P[np.ix_(sel, sel)], cov, atol=1e-16, rtol=1e-9)
