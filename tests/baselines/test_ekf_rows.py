"""The fused paper path of the EKF baselines (baselines/ekf/rows.py, ``BearingEkf.update_rows``):
the fused kernel gives what the per-function pipeline gives (bearing model, OC-EKF constraint,
``H_i P H_i^T``, second-order variance) to rounding, also where it falls back to the projected
constraint; the row-sparse update is the compact one; and the maps of the paper presets are
pinned to those of the implementation before the fused path (main at a747ac7)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from baselines.ekf import EkfMapper, InverseDepthEkfMapper
from baselines.ekf.models import bearing_and_jacobian, second_order_variance
from baselines.ekf.rows import landmark_rows
from bomgraph.mapper import run
from bomgraph.sim import paper_design, simulate_run

#: Final maps of ``ekf`` and ``ekf-invdepth`` (paper presets) on paper runs 0 and 7 of
#: ``paper_design(0)`` (300 steps, a map every 10 steps), made by baselines/ekf at a747ac7
#: (landmark ids, positions, covariances, every 10th pose, and the gated / nonlinear / used
#: bearing counts).
REFERENCE = Path(__file__).resolve().parents[1] / "data" / "ekf_paper_maps_a747ac7.npz"


def _mid_run_mapper() -> EkfMapper:
    st = simulate_run(paper_design(0)[2])
    mapper = EkfMapper(st.header)
    for step in st.steps[:150]:
        mapper.step(step)
    return mapper


def _pipeline(mapper: EkfMapper, cols: np.ndarray):
    """The per-function arithmetic the fused kernel replaces."""
    x, P = mapper.filter.x, mapper.filter.P
    v = x[cols]
    h, j = bearing_and_jacobian(v[:, :3], v[:, 3:])
    j = mapper._constrain(j, cols)
    block = P[cols[:, :, None], cols[:, None, :]]
    hph = np.einsum("mi,mij,mj->m", j, block, j)
    var, index = second_order_variance(v, block, mapper._white_sigma)
    return h, j, hph, var, index


def _landmark_cols(mapper: EkfMapper) -> np.ndarray:
    offs = np.array([o for kind, o in mapper._mapped.values() if kind == "lm"], np.int64)
    cols = np.empty((len(offs), 5), np.int64)
    cols[:, :3] = np.arange(3)
    cols[:, 3:] = offs[:, None] + np.arange(2)
    return cols


@pytest.mark.parametrize("fallback", [False, True])
def test_fused_landmark_rows_are_the_per_function_pipeline(fallback: bool) -> None:
    mapper = _mid_run_mapper()
    cols = _landmark_cols(mapper)
    assert len(cols) > 10
    if fallback:     # landmarks anchored where the robot is: no constrained linearisation
        mapper.filter.nullspace[cols[:4, 3:], 2] = mapper.filter.nullspace[cols[:4, :2], 2]
    f = mapper.filter
    h, j, hph, var, index = landmark_rows(f.x, f.P, f.nullspace, cols, mapper._white_sigma,
                                          mapper._constrain)
    h0, j0, hph0, var0, index0 = _pipeline(mapper, cols)
    d = f.x[cols[:, 3:5]] - f.x[cols[:, :2]]
    length = (d[:, 0] * (f.nullspace[cols[:, 4], 2] - f.nullspace[cols[:, 1], 2])
              + d[:, 1] * (f.nullspace[cols[:, 0], 2] - f.nullspace[cols[:, 3], 2]))
    assert np.any(length <= 0) == fallback                  # the fallback rows are there
    np.testing.assert_allclose(np.angle(np.exp(1j * (h - h0))), 0, rtol=0, atol=1e-12)
    for a, b in ((j, j0), (hph, hph0), (var, var0), (index, index0)):
        np.testing.assert_allclose(a, b, rtol=1e-11, atol=1e-14)


def test_row_sparse_update_is_the_compact_update() -> None:
    mapper = _mid_run_mapper()
    cols = _landmark_cols(mapper)[:8]
    f = mapper.filter
    _, j, _, var, _ = landmark_rows(f.x, f.P, f.nullspace, cols, 0.01, mapper._constrain)
    y = np.linspace(-0.02, 0.03, len(cols))
    x0, p0 = f.x.copy(), f.P.copy()
    f.update_rows(cols, j, y, var)
    x_rows, p_rows = f.x.copy(), f.P.copy()
    f.kf.x, f.kf.P = x0.copy(), p0.copy()
    u = np.unique(cols)
    hu = np.zeros((len(cols), len(u)))
    hu[np.arange(len(cols))[:, None], np.searchsorted(u, cols)] = j
    f.update_compact(u, hu, y, var)
    np.testing.assert_allclose(x_rows, f.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(p_rows, f.P, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(p_rows, p_rows.T)
    assert np.abs(x_rows - x0).max() > 1e-4                 # the update did something


@pytest.mark.parametrize("name, cls", [("ekf", EkfMapper), ("ekf_invdepth",
                                                           InverseDepthEkfMapper)])
@pytest.mark.parametrize("run_index", [0, 7])
def test_paper_maps_are_pinned_to_the_implementation_before_the_fused_path(
        name: str, cls: type, run_index: int) -> None:
    ref = np.load(REFERENCE)
    p = f"{name}_run{run_index}_"
    st = simulate_run(paper_design(0)[run_index])
    est = run(cls(st.header), st.steps, checkpoint_every=10).final
    np.testing.assert_array_equal(est.landmark_ids, ref[p + "ids"])
    assert len(est.landmark_ids) > 40
    np.testing.assert_allclose(est.landmarks_xy, ref[p + "xy"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(est.poses[::10], ref[p + "poses"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(est.landmark_cov, ref[p + "lmcov"], rtol=0, atol=1e-12)
    counts = [est.info[k] for k in ("gated_bearings", "nonlinear_bearings", "used_bearings")]
    np.testing.assert_array_equal(counts, ref[p + "counts"])


def test_clone_is_augment_with_the_identity() -> None:
    mapper = _mid_run_mapper()
    f = mapper.filter
    x0, p0, n0 = f.x.copy(), f.P.copy(), f.nullspace.copy()
    angle0 = f._is_angle.copy()
    idx = np.array([0, 1, 2])
    assert f.clone(idx) == len(x0)
    x_c, p_c, n_c = f.x.copy(), f.P.copy(), f.nullspace.copy()
    f.nullspace, f._is_angle = n0, angle0
    f._set_state(x0, p0)
    f.augment(x0[idx], idx, np.eye(3), np.zeros((3, 3)), angle0[idx])
    np.testing.assert_array_equal(p_c, f.P)
    np.testing.assert_array_equal(n_c, f.nullspace)
    np.testing.assert_allclose(x_c, f.x, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(f._angle_index, np.flatnonzero(f._is_angle))
