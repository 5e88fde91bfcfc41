"""Ray leverages of the window bundle (``bundle_lm.ray_leverages``): against a QR and an SVD of
the whitened Jacobian (independent computations), invariant to the units of the variables,
stable on a numerically singular window, 1 for rays without redundancy; and the end-to-end property they serve: the
``real`` preset's outlier and sigma choices on a recording are not decided by rounding."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from bomgraph.stmds.bundle import _Problem
import bomgraph.stmds.bundle_lm as bundle_lm
from bomgraph.stmds.bundle_lm import LEVERAGE_RCOND, UNDETERMINED_LEVERAGE, ray_leverages

from test_stmds_bundle import _perturbed_problem  # the window problem helper

DATA = Path(os.environ.get("BOMGRAPH_DATA",
                           Path(__file__).resolve().parents[2].parent / "shared" / "data"))


def _qr_leverages(jac: np.ndarray) -> np.ndarray:
    q = np.linalg.qr(jac)[0]
    return np.einsum("ri,ri->r", q, q)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_leverages_are_the_hat_matrix_diagonal_of_a_qr(seed: int) -> None:
    prob, p0, q0, n_bearings = _perturbed_problem(seed)
    jac = prob.linearise(p0, q0)[1]
    assert np.linalg.matrix_rank(jac) == jac.shape[1]
    info = jac.T @ jac
    h = ray_leverages(info, prob.bearing_rows(p0, q0))
    expected = _qr_leverages(jac)[-n_bearings:]          # bearing rows follow the odometry
    np.testing.assert_allclose(h, expected, rtol=0, atol=1e-10)
    # every row's leverage sums to the rank
    assert ray_leverages(info, jac).sum() == pytest.approx(jac.shape[1], abs=1e-9)


def test_the_cholesky_and_the_eigendecomposition_paths_agree(monkeypatch) -> None:
    """A well-conditioned window takes the Cholesky factor; forced onto the pseudo-inverse it
    gives the same leverages (so the switch between them decides nothing)."""
    prob, p0, q0, _ = _perturbed_problem(4)
    jac = prob.linearise(p0, q0)[1]
    rows = prob.bearing_rows(p0, q0)
    d = 1.0 / np.linalg.norm(jac, axis=0)
    assert np.linalg.cond((jac * d).T @ (jac * d)) < bundle_lm.CHOLESKY_MAX_COND
    fast = ray_leverages(jac.T @ jac, rows)
    monkeypatch.setattr(bundle_lm, "CHOLESKY_MAX_COND", 0.0)
    np.testing.assert_allclose(ray_leverages(jac.T @ jac, rows), fast, rtol=0, atol=1e-10)


def test_leverages_do_not_depend_on_the_units_of_the_variables() -> None:
    prob, p0, q0, _ = _perturbed_problem(3)
    jac = prob.linearise(p0, q0)[1]
    rows = prob.bearing_rows(p0, q0)
    units = np.geomspace(1e-3, 1e3, jac.shape[1])        # metres to km, rad to mrad, ...
    jac_u = jac / units
    np.testing.assert_allclose(ray_leverages(jac_u.T @ jac_u, rows / units),
                               ray_leverages(jac.T @ jac, rows), rtol=0, atol=1e-10)


def _near_singular(rng: np.random.Generator, m: int = 40, n: int = 12, eps: float = 1e-9):
    """A whitened Jacobian whose last column repeats the first but for ``eps``: one direction
    the rows do not determine (condition of ``J^T J`` ~ 1 / eps^2)."""
    jac = rng.normal(size=(m, n))
    jac[:, -1] = jac[:, 0] + eps * rng.normal(size=m)
    return jac


def test_an_undetermined_direction_is_left_out_as_an_svd_of_the_jacobian_does() -> None:
    rng = np.random.default_rng(5)
    jac = _near_singular(rng)
    scale = 1.0 / np.linalg.norm(jac, axis=0)
    u, s, _ = np.linalg.svd(jac * scale, full_matrices=False)
    u = u[:, s > np.sqrt(LEVERAGE_RCOND) * s[0]]
    assert u.shape[1] == jac.shape[1] - 1
    expected = np.einsum("ri,ri->r", u, u)
    np.testing.assert_allclose(ray_leverages(jac.T @ jac, jac), expected, rtol=0, atol=1e-7)


def test_leverages_of_a_singular_window_are_stable_under_rounding_level_moves() -> None:
    rng = np.random.default_rng(6)
    jac = _near_singular(rng)
    h = ray_leverages(jac.T @ jac, jac)
    for _ in range(5):
        moved = jac * (1.0 + 1e-13 * rng.normal(size=jac.shape))
        assert np.abs(ray_leverages(moved.T @ moved, moved) - h).max() < 1e-7


def test_the_rays_of_a_two_ray_landmark_have_leverage_one() -> None:
    """A landmark seen by two rays only is fitted exactly (two equations, two unknowns): its
    rays have no redundancy, their residual is 0 whatever the noise, and their leverage is 1;
    the rays of landmarks seen three times or more have some redundancy."""
    prob, p0, q0, _ = _perturbed_problem(0)
    n_lm = len(q0)
    k = np.append(prob.k, [2, 5])
    lm = np.append(prob.lm, [n_lm, n_lm])
    q = np.vstack([q0, p0[2, :2] + [2.0, 1.0]])
    theta = np.append(prob.theta, [0.3, 0.9])
    wide = _Problem(prob.odoms, np.full((len(p0) - 1, 3), 0.02), 0.02, k, lm, theta, n_lm + 1)
    jac = wide.linearise(p0, q)[1]
    h = ray_leverages(jac.T @ jac, wide.bearing_rows(p0, q))
    assert np.all(h[-2:] >= UNDETERMINED_LEVERAGE)
    redundant = np.bincount(lm, minlength=n_lm + 1)[lm] >= 3
    assert redundant.any() and np.all(h[redundant] < UNDETERMINED_LEVERAGE)


def test_non_finite_information_gives_zero_leverages() -> None:
    info = np.full((3, 3), np.nan)
    assert np.array_equal(ray_leverages(info, np.ones((2, 3))), np.zeros(2))


def test_real_preset_on_a_recording_is_not_decided_by_rounding(tmp_path: Path) -> None:
    """MRCLAM6 robot 5 (``bomgraph import mrclam``): every bearing moved by 1e-12 rad leaves
    ``stmds-smacof@real``'s final MPE within 1e-6 (it moved by 5.9 % when the leverages came
    from a plain solve of the numerically singular windows; ``scripts/check_rounding.py``)."""
    if not (DATA / "mrclam6").is_dir():
        pytest.skip(f"no MRCLAM6 at {DATA / 'mrclam6'}")
    from bomgraph.cli import main as bomgraph_main

    from _scripts import load_script  # tests/_scripts.py

    check = load_script("check_rounding")
    path = tmp_path / "m6_r5.jsonl"
    assert bomgraph_main(["import", "mrclam", str(DATA / "mrclam6"), "--robot", "5",
                          "--out", str(path), "-q"]) == 0
    base = check.final_mpe_cm(str(path), "stmds-smacof@real", 0.0, 0)["mpe_cm"]
    for seed in (1, 2):
        moved = check.final_mpe_cm(str(path), "stmds-smacof@real", 1e-12, seed)["mpe_cm"]
        assert moved == pytest.approx(base, rel=1e-6)
