"""The EKF baselines' robust (Huber) bearing update (``robust_update``, baselines/ekf/robust.py).

What is checked here: ``"none"`` changes nothing, bit for bit, and neither does ``"huber"``
with a threshold no bearing reaches; a bearing whose normalised innovation ``|y_n| = |y| /
sqrt(H P H^T + var)`` is at most ``robust_k`` keeps its variance exactly, one above it (and
within the gate, which decides as before) gets ``var + (|y_n| / k - 1) (H P H^T + var)``,
and the filter's update with those variances is the Kalman update with ``R = diag(var_eff)``
computed here in plain numpy (the batched rows path, the general path, and the variances the
iterated path is given); on the paper's world with the header's sigma halved and 3 % of the
bearings off by 0.1-0.3 rad ``ekf-invdepth`` maps better with it; bad values are refused.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

from baselines.ekf import EkfConfig, InverseDepthConfig
from baselines.ekf.robust import huber_variance
from bomgraph.angles import angle_residual, wrap_angle
from bomgraph.errors import ConfigError
from bomgraph.evaluate import score_estimate
from bomgraph.mapper import create_mapper, run
from bomgraph.sim import SimConfig, simulate

METHODS = ("ekf", "ekf-invdepth")


def _halved(seed: int, steps: int) -> tuple[Any, list, Any]:
    s = simulate(SimConfig(n_steps=steps), np.random.default_rng(seed))
    header = dataclasses.replace(s.header, bearing_sigma_rad=s.header.bearing_sigma_rad / 2)
    return header, list(s.steps), s.truth


def _same_map(a: Any, b: Any) -> bool:
    return (np.array_equal(a.landmark_ids, b.landmark_ids)
            and np.array_equal(a.landmarks_xy, b.landmarks_xy)
            and np.array_equal(a.landmark_cov, b.landmark_cov)
            and np.array_equal(a.poses, b.poses) and np.array_equal(a.pose_cov, b.pose_cov))


@pytest.mark.parametrize("preset", ["paper", "real"])
@pytest.mark.parametrize("method", METHODS)
def test_off_and_an_unreached_threshold_change_nothing(method: str, preset: str) -> None:
    header, steps, _ = _halved(21, 120)
    base = run(create_mapper(method, header, preset=preset, robust_update="none"), steps).final
    none = run(create_mapper(method, header, preset="paper" if preset == "paper" else "real",
                             robust_update="none", robust_k=0.5), steps).final
    far = run(create_mapper(method, header, preset=preset, robust_update="huber",
                            robust_k=1e6), steps).final
    on = run(create_mapper(method, header, preset=preset, robust_update="huber",
                           robust_k=1.5), steps).final
    assert _same_map(base, none) and base.info == none.info
    assert "robust_downweighted" not in base.info
    # every bearing below k: the same floats, only the count added
    assert _same_map(base, far) and far.info.pop("robust_downweighted") == 0
    assert far.info == base.info
    # the option on is another map (so the comparisons above can fail)
    assert on.info["robust_downweighted"] > 0 and not _same_map(base, on)
    for cls in (EkfConfig, InverseDepthConfig):
        assert cls.preset("paper").robust_update == "none"


def test_huber_variance_against_the_formula() -> None:
    rng = np.random.default_rng(3)
    hph, var = rng.uniform(1e-5, 1e-3, 200), rng.uniform(1e-5, 1e-3, 200)
    y = rng.normal(0, 3, 200) * np.sqrt(hph + var)
    for k in (0.5, 1.5, 2.0, 3.0):
        out, inflated = huber_variance(y, hph, var, k)
        s = hph + var
        yn = np.abs(y) / np.sqrt(s)
        assert np.array_equal(inflated, yn > k) and 0 < inflated.sum() < 200
        assert np.array_equal(out[~inflated], var[~inflated])          # exactly as before
        # with a gate: the bearings past it on S keep their variance (the gate drops them)
        gated_out, gated_inflated = huber_variance(y, hph, var, k, gate=6.0)
        past = y * y > 6.0 * s
        assert past.any() and np.array_equal(gated_inflated, inflated & ~past)
        assert np.array_equal(gated_out[past], var[past])
        assert np.array_equal(gated_out[~past], out[~past])
        np.testing.assert_allclose(out[inflated], (s * yn / k - hph)[inflated], rtol=1e-12)
        # the step of a bearing alone, y / S_eff, is Huber's psi(y_n) / sqrt(S)
        psi = np.clip(y / np.sqrt(s), -k, k)
        np.testing.assert_allclose(y / (hph + out), psi / np.sqrt(s), rtol=1e-12)
    v3 = var[:3]
    same, none = huber_variance(y[:3] * 0, hph[:3], v3, 2.0)
    assert same is v3 and not none.any()


def _kalman(x0: np.ndarray, P0: np.ndarray, H: np.ndarray, y: np.ndarray,  # noqa: N803
            var: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    S = H @ P0 @ H.T + np.diag(var)                                       # noqa: N806
    K = P0 @ H.T @ np.linalg.inv(S)                                       # noqa: N806
    return x0 + K @ y, P0 - K @ S @ K.T


@pytest.mark.parametrize("method, preset, opts, target", [
    ("ekf", "paper", {}, "update_rows"),                 # the fused rows path
    ("ekf-invdepth", "real", {"iterations": 1}, "update_rows"),
    ("ekf-invdepth", "real", {"iterations": 1, "jacobians": "plain"}, "update_compact"),
    ("ekf", "real", {}, "update"),                       # the iterated update (2 iterations)
])
def test_the_update_is_the_kalman_update_with_the_inflated_variances(
        method: str, preset: str, opts: dict[str, Any], target: str) -> None:
    k = 1.0
    header, steps, _ = _halved(5, 80)
    m = create_mapper(method, header, preset=preset, robust_update="huber", robust_k=k, **opts)
    gate = m._gate
    calls: list[dict[str, Any]] = []
    variances, filt = m._variances, m.filter
    original = getattr(filt, target)

    def spy_variances(y, hph, var, usable):  # type: ignore[no-untyped-def]
        out = variances(y, hph, var, usable)
        calls.append({"y": np.array(y), "hph": hph.copy(), "var": np.array(var),
                      "usable": usable.copy(), "out": out.copy()})
        return out

    def spy_update(*args, **kw):  # type: ignore[no-untyped-def]
        calls[-1].update(x0=filt.x.copy(), P0=filt.P.copy(), args=args, kw=kw,
                         angle=filt._is_angle.copy())
        original(*args, **kw)
        calls[-1].update(x1=filt.x.copy(), P1=filt.P.copy())

    m._variances = spy_variances
    setattr(filt, target, spy_update)
    checked = 0
    for step in steps:
        calls.clear()
        m.step(step)
        for c in calls:
            y, hph, var, out = c["y"], c["hph"], c["var"], c["out"]
            s = hph + var
            yn = np.abs(y) / np.sqrt(s)
            past = y * y > gate * s
            low = (yn <= k) | past
            assert np.array_equal(out[low], var[low])
            np.testing.assert_allclose(out[~low], (s * yn / k - hph)[~low], rtol=1e-12)
            if "x1" not in c:
                continue
            keep = c["usable"] & ~(y * y > gate * (hph + out))
            assert np.array_equal(keep, c["usable"] & ~past)     # the gate decides as before
            if target == "update":
                np.testing.assert_array_equal(c["args"][2], out[keep])   # var_rad2
                checked += int((~low & keep).any())
                continue
            cols, jac, y_kept, var_kept = c["args"]
            np.testing.assert_array_equal(y_kept, y[keep])
            np.testing.assert_array_equal(var_kept, out[keep])
            n = len(c["x0"])
            H = np.zeros((len(y_kept), n))                                 # noqa: N806
            if target == "update_rows":
                np.add.at(H, (np.arange(len(y_kept))[:, None], cols), jac)
            else:
                H[:, cols] = jac
            x1, P1 = _kalman(c["x0"], c["P0"], H, y_kept, var_kept)       # noqa: N806
            dx = c["x1"] - x1
            a = c["angle"]
            dx[a] = angle_residual(c["x1"][a], wrap_angle(x1[a]))
            assert np.max(np.abs(dx)) < 1e-9
            np.testing.assert_allclose(c["P1"], P1, atol=1e-12)
            if (~low & keep).any():
                checked += 1
                plain = _kalman(c["x0"], c["P0"], H, y_kept, var[keep])[0]
                assert np.max(np.abs(plain - x1)) > 1e-6      # the inflation mattered
    assert checked >= 5, checked


def _with_outliers(seed: int) -> tuple[Any, list, Any]:
    """The paper's world, 200 steps, the header's sigma halved, 3 % of the bearings moved by
    0.1-0.3 rad (2-6 true sigmas) either way."""
    header, steps, truth = _halved(700 + seed, 200)
    rng = np.random.default_rng(900 + seed)
    out = []
    for st in steps:
        b = st.bearings_rad.copy()
        hit = rng.random(b.size) < 0.03
        b[hit] = wrap_angle(b[hit] + rng.uniform(0.1, 0.3, hit.sum())
                            * rng.choice([-1.0, 1.0], hit.sum()))
        out.append(dataclasses.replace(st, bearings_rad=b))
    return header, out, truth


def test_outliers_at_a_wrong_small_sigma_are_mapped_better() -> None:
    # ekf-invdepth at its chosen k; ekf (k = 2) does not gain here (measured: mean 19.9 ->
    # 19.4 cm, 3 of 8 runs better; docs/measurements.md), so it is not asserted
    method, k = "ekf-invdepth", 1.5
    off, on = [], []
    for seed in range(8):
        header, steps, truth = _with_outliers(seed)
        for opts, acc in (({"robust_update": "none"}, off),
                          ({"robust_update": "huber", "robust_k": k}, on)):
            final = run(create_mapper(method, header, preset="real", **opts), steps).final
            acc.append(100 * score_estimate(final, truth).mpe_m)
    off_a, on_a = np.array(off), np.array(on)
    # measured (cm, mean of 8): 7.14 -> 5.45, 6 of 8 runs better
    assert on_a.mean() < 0.85 * off_a.mean(), (off, on)
    assert np.count_nonzero(on_a < off_a) >= 5, (off, on)


@pytest.mark.parametrize("field, bad", [("robust_update", "Huber"), ("robust_update", None),
                                        ("robust_update", ""), ("robust_k", 0.0),
                                        ("robust_k", -1.0), ("robust_k", float("inf")),
                                        ("robust_k", float("nan")), ("robust_k", True),
                                        ("robust_k", "2")])
@pytest.mark.parametrize("cls", [EkfConfig, InverseDepthConfig])
def test_bad_values_are_refused(cls: type, field: str, bad: object) -> None:
    with pytest.raises(ConfigError, match=field):
        cls(**{field: bad})


def test_bad_values_are_refused_through_create_mapper() -> None:
    s = simulate(SimConfig(n_steps=5), np.random.default_rng(0))
    with pytest.raises(ConfigError, match="robust_update"):
        create_mapper("ekf", s.header, preset="real", robust_update="cauchy")
