"""The filter (baselines/ekf/filter.py): filterpy's EKF holds its state, whose arrays grow and
shrink together (also during a run of the mapper); the lean block predict and sparse update
give filterpy's own dense ``predict``/``update`` (Joseph form) to 1e-12; augmenting is the exact
covariance of a linear map; predict propagates the odometry noise through the input Jacobian;
the iterated update reaches the MAP estimate of prior and bearing (against a generic
minimiser); the state limit refuses before allocating."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter
from scipy.optimize import minimize

import baselines.ekf.filter as filter_module
from baselines.ekf import BearingEkf, EkfMapper, InverseDepthEkfMapper
from baselines.ekf.filter import StateLimitError, rows_from_dense
from baselines.ekf.models import bearing_and_jacobian, motion_jacobians
from bomgraph.angles import angle_residual
from bomgraph.errors import ConfigError
from bomgraph.geometry import compose
from bomgraph.mapper import create_mapper, run
from bomgraph.sim import RunSpec, SimConfig, paper_design, simulate, simulate_run

SMALL = SimConfig(n_landmarks=20, n_steps=80)


def sized_arrays(f: BearingEkf) -> dict[str, tuple[int, ...]]:
    return {"x": f.kf.x.shape, "P": f.kf.P.shape, "nullspace": f.nullspace.shape,
            "is_angle": f._is_angle.shape, "dim_x": (f.kf.dim_x,)}


def assert_consistent_sizes(f: BearingEkf) -> None:
    n = f.dim
    assert sized_arrays(f) == {"x": (n,), "P": (n, n), "nullspace": (n, 3), "is_angle": (n,),
                               "dim_x": (n,)}


def test_filter_is_filterpys_and_augment_is_the_exact_covariance_of_a_linear_map() -> None:
    f = BearingEkf(np.array([0.1, 0.2, 0.3]), np.diag([0.01, 0.02, 0.03]), 0.05)
    assert isinstance(f.kf, ExtendedKalmanFilter)
    p0 = f.P.copy()
    g = np.array([[1.0, 0.5, -2.0], [0.0, 2.0, 1.0]])
    w = np.array([[0.3, 0.1], [0.1, 0.2]])
    f.augment(np.array([1.0, 2.0]), np.arange(3), g, w, np.array([False, False]))
    a = np.vstack([np.eye(3), g])                     # [x; G x + w]
    expected = a @ p0 @ a.T
    expected[3:, 3:] += w
    np.testing.assert_allclose(f.P, expected, atol=1e-15)
    assert_consistent_sizes(f)
    f.remove(np.array([3]))
    np.testing.assert_allclose(f.P, expected[np.ix_([0, 1, 2, 4], [0, 1, 2, 4])], atol=1e-15)
    assert_consistent_sizes(f)
    with pytest.raises(ConfigError, match="robot pose"):
        f.remove(np.array([2]))


def test_predict_propagates_the_odometry_covariance_through_the_input_jacobian() -> None:
    f = BearingEkf(np.array([1.0, 2.0, 0.7]), np.zeros((3, 3)), 0.05)
    odom, sig = np.array([0.2, 0.01, 0.1]), np.array([0.03, 0.02, 0.05])
    f.predict(odom, sig)
    np.testing.assert_allclose(f.x, compose([1.0, 2.0, 0.7], odom), atol=1e-15)
    _, g = motion_jacobians(np.array([1.0, 2.0, 0.7]), odom)
    np.testing.assert_allclose(f.P, g @ np.diag(sig ** 2) @ g.T, atol=1e-15)


def test_state_arrays_grow_and_shrink_together_during_a_run() -> None:
    s = simulate(SMALL, np.random.default_rng(5))
    m = EkfMapper(s.header)
    dims = set()
    for st in s.steps[:40]:
        m.step(st)
        assert_consistent_sizes(m.filter)
        n_lm = sum(1 for k in m._sizes if k[0] == "lm")
        n_clone = sum(1 for k in m._sizes if k[0] == "clone")
        assert m.filter.dim == 3 + 2 * n_lm + 3 * n_clone
        assert n_clone <= len({t for sig in m._candidates.values() for t, _ in sig})
        np.testing.assert_allclose(m.filter.P, m.filter.P.T, atol=1e-12)
        assert np.linalg.eigvalsh(m.filter.P).min() > -1e-9
        dims.add(m.filter.dim)
    assert len(dims) > 3                                  # it did grow (and shrink)
    est = m.estimate()
    assert est.landmark_cov.shape == (len(est), 2, 2)
    assert est.pose_cov.shape == (40, 3, 3) and est.poses.shape == (40, 3)
    np.testing.assert_array_equal(est.pose_t, np.arange(40))


def _landmark_filter() -> tuple[BearingEkf, np.ndarray, np.ndarray]:
    """A pose and a poorly known landmark 2-3 m away (a strongly nonlinear bearing)."""
    f = BearingEkf(np.array([0.0, 0.0, 0.3]), np.diag([0.1, 0.1, 0.05]) ** 2, 0.02)
    f.augment(np.array([2.0, 1.0]), np.arange(3), np.zeros((2, 3)), np.diag([0.5, 0.8]) ** 2,
              np.array([False, False]))
    return f, f.x.copy(), f.P.copy()


def _bearing(x: np.ndarray) -> np.ndarray:
    return bearing_and_jacobian(x[None, :3], x[None, 3:5])[0]


def _bearing_jac(x: np.ndarray) -> np.ndarray:
    return bearing_and_jacobian(x[None, :3], x[None, 3:5])[1]


def _model(x: np.ndarray):
    return _bearing(x), rows_from_dense(_bearing_jac(x))


def test_iterated_update_is_the_map_estimate_of_prior_and_bearing() -> None:
    z, var = np.array([0.6]), np.array([0.02 ** 2])
    f, x0, p0 = _landmark_filter()
    info = np.linalg.inv(p0)

    def cost(x: np.ndarray) -> float:
        r = float(angle_residual(z[0], _bearing(x)[0]))
        return 0.5 * (x - x0) @ info @ (x - x0) + 0.5 * r * r / var[0]

    best = minimize(cost, x0, method="BFGS", options={"gtol": 1e-12}).x
    f.update(z, _model, var, iterations=30)
    np.testing.assert_allclose(f.x, best, atol=1e-6)
    # the covariance is (I - K H) P0 with H at the estimate: the inverse of the Gauss-Newton
    # Hessian there
    h = _bearing_jac(f.x)
    np.testing.assert_allclose(f.P, np.linalg.inv(info + h.T @ h / var[0]), atol=1e-12)
    plain, _, _ = _landmark_filter()
    plain.update(z, _model, var)              # one linearisation, at x0
    assert cost(plain.x) > cost(f.x) + 1.0




def _random_filter(rng: np.random.Generator, n_landmarks: int) -> BearingEkf:
    """A pose and ``n_landmarks`` correlated landmarks 1-3 m away, random covariance."""
    f = BearingEkf(np.array([0.2, -0.1, 0.4]), np.zeros((3, 3)), 0.03)
    xy = rng.uniform(-3, 3, (n_landmarks, 2))
    f.augment(xy.ravel(), np.arange(3), np.zeros((2 * n_landmarks, 3)),
              np.zeros((2 * n_landmarks, 2 * n_landmarks)), np.zeros(2 * n_landmarks, bool))
    a = rng.normal(size=(f.dim, f.dim)) * 0.05
    f.kf.P = a @ a.T + 1e-4 * np.eye(f.dim)
    return f


def test_lean_predict_and_update_are_filterpys_dense_ones() -> None:
    """The block predict and the sparse update give what filterpy's own ``predict`` (dense
    ``F P F^T + Q``) and ``update`` (dense Joseph form) give, to 1e-12."""
    rng = np.random.default_rng(3)
    f = _random_filter(rng, 6)
    n = f.dim
    ref = ExtendedKalmanFilter(dim_x=n, dim_z=4)
    ref.x, ref.P = f.x.copy(), f.P.copy()
    odom, sig = np.array([0.3, 0.05, 0.2]), np.array([0.02, 0.01, 0.04])
    f_pose, g = motion_jacobians(f.x[:3], odom)
    ref.F = np.eye(n)
    ref.F[:3, :3] = f_pose
    ref.Q = np.zeros((n, n))
    ref.Q[:3, :3] = g @ np.diag(sig ** 2) @ g.T
    x_before = ref.x.copy()
    ref.predict()                        # P = F P F^T + Q (its linear x = F x is replaced)
    ref.x = x_before
    ref.x[:3] = compose(x_before[:3], odom)
    f.predict(odom, sig)
    np.testing.assert_allclose(f.x, ref.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(f.P, ref.P, rtol=0, atol=1e-12)
    lm = np.array([0, 2, 3, 5])                        # 4 bearings to 4 of the landmarks
    z = rng.uniform(-np.pi, np.pi, 4)

    def dense(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        h, j = bearing_and_jacobian(np.tile(x[:3], (4, 1)), x[3:].reshape(-1, 2)[lm])
        H = np.zeros((4, len(x)))
        H[:, :3] = j[:, :3]
        H[np.arange(4)[:, None], 3 + 2 * lm[:, None] + np.arange(2)] = j[:, 3:]
        return h, H

    def sparse(x: np.ndarray):
        h, j = bearing_and_jacobian(np.tile(x[:3], (4, 1)), x[3:].reshape(-1, 2)[lm])
        cols = np.concatenate([np.tile(np.arange(3), (4, 1)),
                               3 + 2 * lm[:, None] + np.arange(2)], 1)
        return h, [(np.arange(4), cols, j)]

    var = np.array([0.03, 0.02, 0.05, 0.04]) ** 2
    ref.update(z, HJacobian=lambda x: dense(x)[1], Hx=lambda x: dense(x)[0], R=np.diag(var),
               residual=angle_residual)
    f.update(z, sparse, var)
    ref_x = ref.x.copy()
    ref_x[2] = angle_residual(ref_x[2], 0.0)
    np.testing.assert_allclose(f.x, ref_x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(f.P, ref.P, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(f.P, f.P.T)              # exactly symmetric, no fix-up


def test_the_state_limit_refuses_before_allocating() -> None:
    f = BearingEkf(np.zeros(3), np.zeros((3, 3)), 0.03, max_state=7,
                   limit_hint="; raise it with max_landmarks")
    f.augment(np.ones(4), np.arange(3), np.zeros((4, 3)), np.eye(4), np.zeros(4, bool))
    with pytest.raises(StateLimitError, match=r"beyond its limit of 7; raise it with max_landmarks"):
        f.augment(np.ones(2), np.arange(3), np.zeros((2, 3)), np.eye(2), np.zeros(2, bool))
    assert f.dim == 7


@pytest.mark.parametrize("z0", [0.6, np.pi - 0.01], ids=["small-innovation", "near-pi"])
def test_iterated_update_ends_with_filterpys_update_at_the_last_iterate(z0: float) -> None:
    """The last step of the iterated update is filterpy's ``update`` with the model
    linearised at the iterate, ``h_i + H_i (x - x_i)``, its residual wrapped after the linear
    term (the next test has a case where that matters)."""
    z, var = np.array([z0]), np.array([0.02 ** 2])
    f, x0, p0 = _landmark_filter()
    f.update(z, _model, var, iterations=2)
    # the reference: one Gauss-Newton iterate by hand, then filterpy's update
    h0, H0 = _bearing(x0), _bearing_jac(x0)
    s = H0 @ p0 @ H0.T + np.diag(var)
    xi = x0 + p0 @ H0.T @ np.linalg.solve(s, angle_residual(z, h0))
    xi[2] = angle_residual(xi[2], 0.0)
    h_i, H_i = _bearing(xi), _bearing_jac(xi)
    ref = ExtendedKalmanFilter(dim_x=5, dim_z=1)
    ref.x, ref.P = x0.copy(), p0.copy()

    def diff(x: np.ndarray) -> np.ndarray:
        d = x - xi
        d[2] = angle_residual(x[2], xi[2])
        return d

    ref.update(z, HJacobian=lambda x: H_i, Hx=lambda x: h_i + H_i @ diff(x), R=np.diag(var),
               residual=angle_residual)
    ref.x[2] = angle_residual(ref.x[2], 0.0)
    np.testing.assert_allclose(f.x, ref.x, rtol=0, atol=1e-10)
    np.testing.assert_allclose(f.P, ref.P, rtol=0, atol=1e-12)


def _filterpy_iterated(f: BearingEkf, z: np.ndarray, model, var: np.ndarray, plain) -> tuple:
    """The iterated update of two iterations as it was written on filterpy's dense ``update``:
    one Gauss-Newton iterate, then ``update`` with ``h_i + H_i (x - x_i)``."""
    def dense(rows, k: int, n: int) -> np.ndarray:
        H = np.zeros((k, n))
        for r, c, v in rows:
            H[r[:, None], c] = v
        return H

    x0, p0, n, k = f.x.copy(), f.P.copy(), f.dim, len(z)
    h0, rows0 = plain(x0)
    H0 = dense(rows0, k, n)
    s = H0 @ p0 @ H0.T + np.diag(var)
    xi = x0 + p0 @ H0.T @ np.linalg.solve(s, angle_residual(z, h0))
    xi[f._is_angle] = angle_residual(xi[f._is_angle], 0.0)
    h_i, rows_i = model(xi)
    H_i = dense(rows_i, k, n)
    ref = ExtendedKalmanFilter(dim_x=n, dim_z=k)
    ref.x, ref.P = x0, p0
    ref.update(z, HJacobian=lambda x: H_i, Hx=lambda x: h_i + H_i @ f._difference(x, xi),
               R=np.diag(var), residual=angle_residual)
    x = ref.x.copy()
    x[f._is_angle] = angle_residual(x[f._is_angle], 0.0)
    return x, ref.P


def test_iterated_update_of_a_mapper_run_is_filterpys_where_a_residual_passes_pi(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """At step 61 of this simulated run one bearing's linearised residual passes -pi (-8.06
    rad unwrapped): wrapping it only before the linear term moved a feature by 0.09."""
    stream = simulate_run(RunSpec(0, 0, 0), SimConfig())
    m = InverseDepthEkfMapper(stream.header, preset="real")
    seen = []
    lean = filter_module.BearingEkf.update

    def check(self, z, model, var, iterations=1, model_iterate=None, **kw):
        if m._t == 61:
            seen.append(_filterpy_iterated(self, np.asarray(z), model, np.asarray(var),
                                           model_iterate))
        lean(self, z, model, var, iterations, model_iterate, **kw)
        if m._t == 61:
            np.testing.assert_allclose(self.x, seen[-1][0], rtol=0, atol=1e-9)
            np.testing.assert_allclose(self.P, seen[-1][1], rtol=0, atol=1e-12)

    monkeypatch.setattr(filter_module.BearingEkf, "update", check)
    for st in stream.steps[:62]:
        m.step(st)
    assert seen


@pytest.mark.parametrize("method", ["ekf", "ekf-invdepth"])
def test_one_pass_gated_update_is_the_model_path_to_rounding(method: str) -> None:
    """The one-pass gated update of the paper presets (``_plain_gated_update``: the fused
    kernel of baselines/ekf/rows.py and ``BearingEkf.update_rows``) gives the same maps, to
    rounding (1e-9), and the same gate counts as the general path through the bearing model and
    ``BearingEkf.update``."""
    stream = simulate_run(paper_design(0)[1], SimConfig(n_steps=120))
    results = []
    for one_pass in (True, False):
        mapper = create_mapper(method, stream.header, start_pose=tuple(stream.truth.poses[0]))
        calls = []
        if one_pass:
            plain = mapper._plain_gated_update
            mapper._plain_gated_update = lambda *a: calls.append(1) or plain(*a)
        else:
            mapper._plain_gated_update = (
                lambda po, k, o, z: calls.append(1) or mapper._model_gated_update(po, k, o, z,
                                                                                  None))
        est = run(mapper, stream.steps, checkpoint_every=10).final
        assert len(calls) > 100                       # the path under test was taken
        results.append((est, mapper.filter.P.copy(), mapper.n_gated, mapper.n_updates))
    (a, pa, ga, ua), (b, pb, gb, ub) = results
    assert a.landmark_ids.size > 10
    np.testing.assert_array_equal(a.landmark_ids, b.landmark_ids)
    np.testing.assert_allclose(a.landmarks_xy, b.landmarks_xy, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.poses, b.poses, rtol=0, atol=1e-9)
    np.testing.assert_allclose(pa, pb, rtol=0, atol=1e-9)
    assert (ga, ua) == (gb, ub)


def _heading_model(x: np.ndarray):
    """A bearing that measures the robot's heading itself: ``h = psi``, ``H = [0, 0, 1, 0..]``
    (linear, so the iterated update must equal the plain one)."""
    h_row = np.zeros((1, len(x)))
    h_row[0, 2] = 1.0
    return np.array([x[2]]), rows_from_dense(h_row)


@pytest.mark.parametrize("iterations", [1, 3])
def test_update_wraps_the_innovation_and_the_iterates_across_pi(iterations: int) -> None:
    """Heading pi - 0.01 (variance 0.01), measured at -pi + 0.03 (0.04 rad further on, across
    the cut) with sigma 0.1: the innovation is +0.04, the gain 0.5, so the heading moves to
    pi + 0.01, i.e. -pi + 0.01 (a plain ``z - h`` gives an innovation of 0.04 - 2 pi). filterpy's own
    ``update`` with ``residual=angle_residual`` is the reference. The model is linear, so the
    iterated update (whose iterates cross pi and whose ``x_0 - x_i`` must be wrapped too)
    gives the same state and covariance."""
    psi0 = np.pi - 0.01
    f = BearingEkf(np.array([0.5, -0.2, psi0]), np.diag([0.04, 0.04, 0.01]), 0.1)
    f.augment(np.array([2.0, 1.0]), np.arange(3), np.array([[1.0, 0, 0.3], [0, 1.0, -0.2]]),
              np.array([0.2, 0.3]), np.array([False, False]))
    ref = ExtendedKalmanFilter(dim_x=5, dim_z=1)
    ref.x, ref.P, ref.R = f.x.copy(), f.P.copy(), np.eye(1) * 0.01
    z = np.array([-np.pi + 0.03])
    ref.update(z, lambda x: np.eye(5)[2:3], lambda x: np.array([x[2]]), R=ref.R,
               residual=angle_residual)
    f.update(z, _heading_model, iterations=iterations)
    assert abs(float(f.x[2] - (-np.pi + 0.01))) < 1e-12
    np.testing.assert_allclose(angle_residual(f.x, ref.x), 0.0, atol=1e-12)
    np.testing.assert_allclose(f.P, ref.P, atol=1e-12)


def test_iterated_update_across_pi_is_the_map_estimate() -> None:
    """The MAP test above with the heading at pi - 0.01 and a bearing that turns it ~0.05 rad
    further, past pi: the iterates wrap, so ``x_0 - x_i`` must be differenced with the wrap
    (unwrapped, the second iterate jumps by ~2 pi K and the last linearisation is made there).
    """
    psi0 = np.pi - 0.01
    f = BearingEkf(np.array([0.0, 0.0, psi0]), np.diag([0.1, 0.1, 0.1]) ** 2, 0.02)
    f.augment(np.array([-2.0, -1.0]), np.arange(3), np.zeros((2, 3)),
              np.diag([0.3, 0.3]) ** 2, np.array([False, False]))
    x0, p0 = f.x.copy(), f.P.copy()
    info = np.linalg.inv(p0)
    z, var = _bearing(x0) - 0.06, np.array([0.02 ** 2])

    def cost(x: np.ndarray) -> float:
        d = x - x0
        d[2] = float(angle_residual(x[2], x0[2]))
        r = float(angle_residual(z[0], _bearing(x)[0]))
        return 0.5 * d @ info @ d + 0.5 * r * r / var[0]

    best = minimize(cost, x0, method="BFGS", options={"gtol": 1e-12}).x
    assert best[2] > np.pi                               # the MAP heading is past the cut
    f.update(z, _model, var, iterations=30)
    assert f.x[2] < 0                                    # held wrapped
    np.testing.assert_allclose(angle_residual(f.x, best), 0.0, atol=1e-6)
