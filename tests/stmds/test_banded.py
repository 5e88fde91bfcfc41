"""The window bundle's pose block in band form (``stmds.banded``): the same numbers, bit for
bit, as the dense construction it replaces on the arrow path of long windows (the damped step,
``arrow_inverse``, the leverages), so the ``real`` preset's maps do not move."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import lapack

import bomgraph
import bomgraph.stmds.bundle_lm as bundle_lm
from bomgraph.stmds.banded import UNIT_COLUMNS, PoseBlock, solve_lower_unit, upper_band

from test_leverage import _long_window, _near_pose_window


def _bits(x: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=float).view(np.int64)


def _assert_close(x, y) -> None:
    """Equal to rounding: two summation orders of the same products (a banded solve on the
    trailing block against one on the whole; five nonzeros against a dense row) give the
    same bits with the OpenBLAS that numpy and scipy bundle here (``scripts/check_identical.py``
    and the map hashes in ``docs/measurements.md``), but a BLAS is free to group a short
    sum otherwise, so the test asks for equality to rounding only."""
    x, y = np.asarray(x), np.asarray(y)
    assert x.shape == y.shape
    np.testing.assert_array_equal(x == 0, y == 0)                  # the same structure
    np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-14 * max(np.abs(y).max(), 1.0))


def _assert_same_bits(x, y) -> None:
    if isinstance(x, tuple):
        assert isinstance(y, tuple) and len(x) == len(y)
        for a, b in zip(x, y):
            _assert_same_bits(a, b)
        return
    x, y = np.asarray(x), np.asarray(y)
    assert x.shape == y.shape
    np.testing.assert_array_equal(_bits(x), _bits(y))


@pytest.mark.parametrize("seed", [21, 22, 23])
def test_pose_block_is_the_pose_block_of_the_information(seed: int) -> None:
    """A long window's pose block comes as a ``PoseBlock``; its dense form is the poses'
    block of ``J^T J`` and its band is that matrix's upper diagonals, exactly."""
    prob, p0, q0 = _long_window(seed)
    _, blocks = prob.normal_equations(p0, q0)
    a = blocks[0]
    assert isinstance(a, PoseBlock)
    jac = prob.linearise(p0, q0)[1]
    n_p = prob.n_pose_vars
    info = jac.T @ jac
    dense = np.asarray(a)
    np.testing.assert_allclose(dense, info[:n_p, :n_p], rtol=0,
                               atol=1e-12 * np.abs(info).max())
    band = upper_band(a)
    for k in range(6):
        np.testing.assert_array_equal(band[5 - k, k:], dense.diagonal(k))
        np.testing.assert_array_equal(band[5 - k, :k], 0.0)
    assert np.count_nonzero(np.triu(dense, 6)) == 0        # nothing outside the band


@pytest.mark.parametrize("seed", [21, 22, 23])
def test_band_and_dense_pose_blocks_give_the_same_bits(seed: int) -> None:
    """The damped step, ``arrow_inverse`` and the dense information from a ``PoseBlock`` are
    those from the dense matrix (the construction before the band form), bit for bit."""
    prob, p0, q0 = _long_window(seed)
    _, blocks = prob.normal_equations(p0, q0)
    dense = (np.asarray(blocks[0]), *blocks[1:])
    for lam in (1e-9, 1e-4, 1.0):
        _assert_same_bits(bundle_lm._schur_step(blocks, lam), bundle_lm._schur_step(dense, lam))
    _assert_same_bits(bundle_lm.arrow_inverse(blocks), bundle_lm.arrow_inverse(dense))
    _assert_same_bits(bundle_lm._dense_information(blocks),
                      bundle_lm._dense_information(dense))


@pytest.mark.parametrize("n_p", [1, 5, 6, UNIT_COLUMNS - 1, UNIT_COLUMNS, 2 * UNIT_COLUMNS + 7,
                                 301])
def test_unit_solve_is_one_dtbtrs_call_bit_for_bit(n_p: int) -> None:
    """``U^-T [B, I]`` by trailing blocks equals LAPACK's ``dtbtrs`` on the whole ``[B, I]``
    (to rounding: :func:`_assert_close`), zeros above the diagonal included."""
    rng = np.random.default_rng(n_p)
    factor = rng.normal(size=(6, n_p))
    factor[5] = np.abs(factor[5]) + 0.5
    for k in range(1, 6):
        factor[5 - k, :k] = 0.0
    rhs = rng.normal(size=(n_p, 7))
    whole, fail = lapack.dtbtrs(factor, np.column_stack([rhs, np.eye(n_p)]), uplo="U",
                                trans="T")
    assert fail == 0
    _assert_close(solve_lower_unit(factor, rhs), whole)
    _assert_close(solve_lower_unit(factor, rhs[:, :0]), whole[:, 7:])
    singular = factor.copy()
    singular[5, n_p // 2] = 0.0
    assert solve_lower_unit(singular, rhs) is None
    assert solve_lower_unit(singular, rhs[:, :0]) is None


@pytest.mark.parametrize("make", [_long_window, _near_pose_window])
def test_leverages_from_the_nonzeros_are_those_of_the_dense_rows(make) -> None:
    """``WindowInverse.leverages_at`` (each bearing row's five nonzeros) gives the bits of
    ``leverages`` on the dense rows (to rounding: :func:`_assert_close`), on the arrow path
    and on the dense fallback."""
    prob, p0, q0 = make(21)
    _, blocks = prob.normal_equations(p0, q0)
    inverse = bundle_lm.WindowInverse(prob, blocks)
    assert (inverse._arrow is None) == (make is _near_pose_window)
    _assert_close(inverse.leverages_at(p0, q0), inverse.leverages(prob.bearing_rows(p0, q0)))


_NO_LANDMARKS = """
import numpy as np
import bomgraph.stmds.bundle_lm as bundle_lm
from bomgraph.stmds.bundle import BundleProblem
rng = np.random.default_rng(3)
m = 25                                                  # 75 pose variables: the arrow path
odoms = np.tile([0.5, 0.0, 0.05], (m, 1)) + rng.normal(0.0, 0.01, (m, 3))
none = np.zeros(0, np.int64)
prob = BundleProblem(odoms, np.full((m, 3), 0.02), 0.02, none, none, np.zeros(0), 0)
poses = np.vstack([np.zeros(3), np.cumsum(odoms, 0)])
_, blocks = prob.normal_equations(poses, np.zeros((0, 2)))
assert bundle_lm.uses_arrow(prob.n_pose_vars, 0)
for _ in range(50):
    s, ainv_kk, ainv_b, schur = bundle_lm.arrow_inverse(blocks)
    junk = [np.empty(i % 17 + 1) for i in range(200)]
a = np.asarray(blocks[0]) * s[:, None] * s[None, :]
inv = np.linalg.inv(a).reshape(m, 3, m, 3)[np.arange(m), :, np.arange(m), :]
assert ainv_b.shape == (3 * m, 0) and schur.shape == (0, 0)
assert np.abs(ainv_kk - inv).max() < 1e-9 * np.abs(inv).max()
print("ok")
"""


def test_arrow_inverse_of_a_window_without_landmarks_leaves_the_heap_alone() -> None:
    """A long window without landmarks has no ``A^-1 B`` to solve: scipy's ``dtbtrs`` on a
    right-hand side of zero columns writes outside its buffers (the heap corrupted, the
    process aborted by glibc a few allocations later), so it is not called. In a subprocess,
    which such a fault kills."""
    env = {**os.environ, "PYTHONPATH": str(Path(bomgraph.__file__).resolve().parents[1])}
    done = subprocess.run([sys.executable, "-c", _NO_LANDMARKS], capture_output=True,
                          text=True, timeout=600, env=env)   # this test's bomgraph
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "ok"


def test_pose_block_refuses_an_array_without_a_copy() -> None:
    """numpy 2's ``__array__(copy=False)`` asks for no copy; the dense matrix is always a new
    array, so it raises as numpy's protocol asks instead of copying quietly."""
    prob, p0, q0 = _long_window(21)
    a = prob.normal_equations(p0, q0)[1][0]
    assert isinstance(a, PoseBlock)
    with pytest.raises(ValueError, match="copy"):
        np.asarray(a, copy=False)
    np.testing.assert_array_equal(np.asarray(a, copy=True), a.dense())
    assert np.asarray(a, dtype=np.float32).dtype == np.float32


def test_pose_block_diagonals_outside_the_band_are_those_of_the_matrix() -> None:
    """``PoseBlock.diagonal(k)`` stands in for ``ndarray.diagonal``: beyond the band (``k >=
    6``) it is zeros, below it (``k < 0``) the upper one by symmetry; ``k = 6`` gave the main
    diagonal (``band[-1]``) before, ``k = -1`` an IndexError."""
    prob, p0, q0 = _long_window(22)
    a = prob.normal_equations(p0, q0)[1][0]
    dense = a.dense()
    for k in (-7, -5, -1, 0, 3, 5, 6, 7, 11, a.shape[0] - 1, a.shape[0], a.shape[0] + 4):
        np.testing.assert_array_equal(a.diagonal(k), dense.diagonal(k))
