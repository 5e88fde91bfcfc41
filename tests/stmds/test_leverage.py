"""Ray leverages of the window bundle (``bundle_lm.ray_leverages``, ``WindowInverse``): against
a QR and an SVD of the whitened Jacobian (independent computations), invariant to the units of
the variables, stable on numerically singular windows (the arrow path refused where the pose
block is singular), 1 for rays without redundancy, left out of the sigma estimate; and the
end-to-end property they serve: the ``real`` preset's outlier and sigma choices on a recording
are not decided by rounding."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bomgraph.stmds.bundle import BundleProblem
import bomgraph.stmds.bundle_lm as bundle_lm
from bomgraph.stmds.bundle_lm import LEVERAGE_RCOND, UNDETERMINED_LEVERAGE, ray_leverages

from test_stmds_bundle import _perturbed_problem  # the window problem helper
from _shared_data import DATA, missing  # tests/_shared_data.py


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
    with monkeypatch.context() as m:                     # the Cholesky branch, no eigh
        m.setattr(np.linalg, "eigh", lambda *a: pytest.fail("eigh on a well-posed window"))
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
    wide = BundleProblem(prob.odoms, np.full((len(p0) - 1, 3), 0.02), 0.02, k, lm, theta, n_lm + 1)
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
    ``stmds-smacof@real``'s final MPE within 1e-6 relative (it moved by 5.9 % when the
    leverages came from a plain solve of the numerically singular windows, and by 8.7e-5
    while an ill-conditioned pose block could take the arrow path; 1.3e-10 now;
    ``scripts/check_rounding.py``)."""
    if not (DATA / "mrclam6").is_dir():
        pytest.skip(missing("mrclam6"))
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


def _long_window(seed: int, far_m: float | None = None):
    """A window long enough for the arrow path (30-32 poses, 6 landmarks, rays from the fixed
    first pose among them); with ``far_m`` one more landmark ``far_m`` metres away seen from
    three poses, whose depth the window barely determines (``J^T J`` of condition >> 1e8)."""
    w, n = 30 + seed % 3, 6
    prob, p0, q0, _ = _perturbed_problem(seed, w, n)
    if far_m is None:
        return prob, p0, q0
    k = np.append(prob.k, [3, 10, 20])
    lm = np.append(prob.lm, [n, n, n])
    far = p0[10, :2] + far_m * np.array([np.cos(0.4), np.sin(0.4)])
    d = far - p0[[3, 10, 20], :2]
    theta = np.append(prob.theta, np.arctan2(d[:, 1], d[:, 0]) - p0[[3, 10, 20], 2] + 1e-3)
    wide = BundleProblem(prob.odoms, 1.0 / prob.w_odo, 1.0 / prob.w_b, k, lm, theta, n + 1)
    return wide, p0, np.vstack([q0, far])


@pytest.mark.parametrize("seed", [21, 22, 23])
def test_long_windows_take_leverages_and_covariance_from_the_arrow_to_the_dense_values(
        seed: int) -> None:
    """A long window's leverages and landmark covariance come from the arrow structure
    (banded pose block, the landmarks' Schur complement: ``arrow_inverse``) without the dense
    matrix; they equal a QR of ``J`` and the plain inverse, rays from the fixed pose included."""
    prob, p0, q0 = _long_window(seed)
    assert bundle_lm.uses_arrow(prob.n_pose_vars, prob.n - prob.n_pose_vars)
    assert np.any(prob.k == 0)
    _, blocks = prob.normal_equations(p0, q0)
    inverse = bundle_lm.WindowInverse(prob, blocks)
    assert inverse._arrow is not None                   # the arrow path, not the fallback
    jac = prob.linearise(p0, q0)[1]
    rows = prob.bearing_rows(p0, q0)
    np.testing.assert_allclose(inverse.leverages(rows), _qr_leverages(jac)[-len(rows):],
                               rtol=0, atol=1e-9)
    plain = np.linalg.inv(jac.T @ jac)[prob.n_pose_vars:, prob.n_pose_vars:]
    np.testing.assert_allclose(inverse.landmark_covariance(), plain, rtol=1e-7, atol=1e-14)


@pytest.mark.parametrize("seed", [21, 22])
def test_a_barely_determined_landmark_in_a_long_window(seed: int) -> None:
    """A landmark 1e7 m away seen from three poses: the window's ``J^T J`` is numerically
    singular. The arrow path and the dense pseudo-inverse agree on every leverage, and a
    rounding-level move of the rows moves none by more than 1e-7. (At 1e5 m its depth
    direction's eigenvalue, 1e-10 of the largest, straddles ``LEVERAGE_RCOND`` in one scaling
    and not the other, and the two paths differ by up to 0.28: a threshold on what is
    determined is a threshold.)"""
    prob, p0, q0 = _long_window(seed, far_m=1e7)
    _, blocks = prob.normal_equations(p0, q0)
    info = bundle_lm._dense_information(blocks)
    d = 1.0 / np.sqrt(np.diag(info))
    assert np.linalg.cond(info * d[:, None] * d[None, :]) > 1e10
    rows = prob.bearing_rows(p0, q0)
    inverse = bundle_lm.WindowInverse(prob, blocks)
    assert inverse._arrow is not None
    h = inverse.leverages(rows)
    np.testing.assert_allclose(h, ray_leverages(info, rows), rtol=0, atol=1e-7)
    rng = np.random.default_rng(seed)
    moved = rows * (1.0 + 1e-13 * rng.normal(size=rows.shape))
    assert np.abs(inverse.leverages(moved) - h).max() < 1e-7


def _two_ray_scene(seed: int, sigma_rad: float = 0.01):
    """A 12-pose window: 6 landmarks seen from every pose and 12 seen from two poses only
    (rays of leverage 1), bearings with noise ``sigma_rad``."""
    from bomgraph.geometry import bearings_to, dead_reckon, to_world

    rng = np.random.default_rng(seed)
    w = 12
    odoms = np.column_stack([rng.uniform(0.2, 0.3, w - 1), np.zeros(w - 1),
                             rng.uniform(-0.1, 0.1, w - 1)])
    poses = dead_reckon(odoms, np.zeros(3))
    local = np.column_stack([rng.uniform(0.0, 3.0, 18), rng.choice([-1.0, 1.0], 18)
                             * rng.uniform(1.0, 3.0, 18)])
    pts = to_world(np.zeros(3), local)
    brg = np.stack([bearings_to(p, pts) for p in poses]) + rng.normal(0, sigma_rad, (w, 18))
    for j in range(6, 18):
        seen = rng.choice(w, 2, replace=False)
        brg[np.setdiff1d(np.arange(w), seen), j] = np.nan
    return odoms, brg


def test_rays_without_redundancy_do_not_pull_the_sigma_estimate_down() -> None:
    """A window re-estimating its bearing sigma from its residuals: a third of its rays
    belong to two-ray landmarks, fitted exactly (residual 0 whatever the noise). Counted, they
    would pull the median residual, and so the sigma, down by about a third; left out, the
    estimate is the noise's (mean over 8 windows within 12 %)."""
    from bomgraph.stmds.bundle import bundle_adjust_window

    sigma = 0.01
    ratios = []
    for seed in range(8):
        odoms, brg = _two_ray_scene(seed, sigma)
        sig = np.tile([0.01, 0.005, 0.01], (len(odoms), 1))
        bundle = bundle_adjust_window(odoms, sig, brg, sigma, estimate_sigma=True,
                                      outlier_sigma=None)[0]
        assert len(bundle.column) == 18
        ratios.append(bundle.bearing_sigma_rad / sigma)
    assert abs(np.mean(ratios) - 1.0) < 0.12, ratios


def _near_pose_window(seed: int, gap_m: float = 2e-6):
    """A long window with one more landmark ``gap_m`` from pose 10, seen from poses 9-11:
    its bearings pin that pose's position so hard that the scaled pose block is numerically
    singular (condition ~1e11-1e13)."""
    prob, p0, q0 = _long_window(seed)
    n = len(q0)
    point = p0[10, :2] + gap_m * np.array([0.8, 0.6])
    d = point - p0[[9, 10, 11], :2]
    k = np.append(prob.k, [9, 10, 11])
    lm = np.append(prob.lm, [n, n, n])
    theta = np.append(prob.theta, np.arctan2(d[:, 1], d[:, 0]) - p0[[9, 10, 11], 2])
    near = BundleProblem(prob.odoms, 1.0 / prob.w_odo, 1.0 / prob.w_b, k, lm, theta, n + 1)
    return near, p0, np.vstack([q0, point])


def _symmetric_move(rng: np.random.Generator, a: np.ndarray, eps: float) -> np.ndarray:
    noise = rng.normal(size=a.shape)
    return a * (1.0 + eps * (noise + noise.T) / 2.0)


@pytest.mark.parametrize("seed", [21, 22])
def test_an_ill_conditioned_pose_block_takes_the_dense_path(seed: int, monkeypatch) -> None:
    """Where the scaled pose block is numerically singular, the arrow path's ``A^-1`` carries
    rounding into every leverage: moved by 1e-13 it moves them by ~1e-2. Such a window takes
    the dense path, which moves them by under 1e-7."""
    prob, p0, q0 = _near_pose_window(seed)
    _, blocks = prob.normal_equations(p0, q0)
    rows = prob.bearing_rows(p0, q0)
    rng = np.random.default_rng(seed)
    moved = (_symmetric_move(rng, blocks[0], 1e-13), *blocks[1:])
    inverse = bundle_lm.WindowInverse(prob, blocks)
    assert inverse._arrow is None                       # refused by the condition bound
    h = inverse.leverages(rows)
    assert np.abs(bundle_lm.WindowInverse(prob, moved).leverages(rows) - h).max() < 1e-7
    monkeypatch.setattr(bundle_lm, "ARROW_MAX_COND", np.inf)     # the arrow path forced
    forced = bundle_lm.WindowInverse(prob, blocks)
    assert forced._arrow is not None
    drift = np.abs(bundle_lm.WindowInverse(prob, moved).leverages(rows)
                   - forced.leverages(rows)).max()
    assert drift > 1e-4                                 # what the bound guards against
