"""The window bundle's pose block in band form (:mod:`.bundle_lm`'s arrow path, long windows).

A window's poses are linked only to their neighbours by the odometry and each bearing touches
one pose, so the pose block ``A`` of ``J^T J`` is block tridiagonal (3 x 3 blocks, half-bandwidth
5). The arrow path factorises it banded; here it is kept in that form (:class:`PoseBlock`,
never the dense ``3 M x 3 M`` matrix unless the dense fallback asks), and the banded triangular
solve :func:`.bundle_lm.arrow_inverse` needs for ``A``'s diagonal blocks of ``A^-1``
(:func:`solve_lower_unit`). Every function gives the numbers of the dense construction it
replaces (bit for bit with the OpenBLAS numpy and scipy bundle here, `scripts/check_identical.py`;
a BLAS may group a short sum otherwise, so the tests ask for equality to rounding).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.linalg import lapack


class PoseBlock:
    """The pose block ``A`` of a long window's ``J^T J`` (:func:`.bundle_lm.uses_arrow`): block
    tridiagonal, kept as its 3 x 3 blocks on the diagonal ``d`` ``(M, 3, 3)`` and beside it
    ``off`` ``(M - 1, 3, 3)`` (``A[k, k + 1]``). The arrow path reads its upper band alone
    (:attr:`band`, ``(6, 3 M)``, half-bandwidth 5: :func:`scipy.linalg.cholesky_banded`'s
    upper form); :meth:`dense` (or ``np.asarray``) gives the matrix itself, the numbers of
    the dense assembly, for the dense fallback."""

    def __init__(self, d: np.ndarray, off: np.ndarray) -> None:
        self.d, self.off = d, off
        m = len(d)
        self.shape = (3 * m, 3 * m)
        band = np.zeros((6, 3 * m))            # band[5 - k, j] = A[j - k, j]
        col = 3 * np.arange(m)
        for p in range(3):
            for q in range(p, 3):
                band[5 - (q - p), col + q] = d[:, p, q]
            for q in range(3):
                band[2 - q + p, col[1:] + q] = off[:, p, q]
        self.band = band

    def diagonal(self, k: int = 0) -> np.ndarray:
        """``A``'s ``k``-th diagonal (as ``ndarray.diagonal``): the band's for ``0 <= k <= 5``,
        zeros beyond it; below the main one from the dense matrix (the 3 x 3 blocks on the
        diagonal need not be symmetric to the last bit)."""
        if k < 0:
            return self.dense().diagonal(k)
        if k > 5:
            return np.zeros(max(self.shape[0] - k, 0))
        return self.band[5 - k, k:]

    def dense(self) -> np.ndarray:
        m = len(self.d)
        a = np.zeros(self.shape)
        a4 = a.reshape(m, 3, m, 3)
        i = np.arange(m)
        a4[i, :, i, :] = self.d
        a4[i[:-1], :, i[1:], :] = self.off
        a4[i[1:], :, i[:-1], :] = self.off.transpose(0, 2, 1)
        return a

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        if copy is False:       # numpy 2's protocol: the dense matrix is always a new array
            raise ValueError("a PoseBlock has no dense array to share: copy=False is not "
                             "possible, use np.asarray(a) or a.dense()")
        return self.dense() if dtype is None else self.dense().astype(dtype)


def upper_band(a: "PoseBlock | np.ndarray") -> np.ndarray:
    """The upper band ``(6, P)`` of a pose block (a :class:`PoseBlock` or a dense matrix)."""
    if isinstance(a, PoseBlock):
        return a.band
    band = np.zeros((6, len(a)))
    for k in range(6):
        band[5 - k, k:] = a.diagonal(k)
    return band


#: Columns of the identity solved together by :func:`solve_lower_unit`.
UNIT_COLUMNS = 64


def solve_lower_unit(factor: np.ndarray, rhs: np.ndarray) -> np.ndarray | None:
    """``U^-T [rhs, I]`` ``(P, R + P)``, Fortran order, for the banded upper factor ``U``
    (``factor``, ``(6, P)``); None if LAPACK's ``dtbtrs`` refuses (a zero on the diagonal).

    ``dtbtrs`` solves column by column; ``U^-T`` is lower triangular, so the identity's
    columns ``j0 ...`` are solved on the trailing block ``U[j0:, j0:]`` alone, the zeros
    above left as they are: the same numbers as one ``dtbtrs`` call on ``[rhs, I]`` (a
    column's leading zeros add only zeros to each later row's sum), in half the work and
    without the ``P x P`` identity. That holds for a finite factor (``arrow_inverse`` checks
    its band; the Cholesky factor of a finite band is finite): a NaN on the diagonal makes the
    whole call's later columns NaN (``0 / NaN``), the trailing blocks' not."""
    n_p, n_r = rhs.shape
    y = np.zeros((n_p, n_r + n_p), order="F")
    if n_r:
        y[:, :n_r], fail = lapack.dtbtrs(factor, rhs, uplo="U", trans="T")
        if fail:
            return None
    for j0 in range(0, n_p, UNIT_COLUMNS):
        m = min(UNIT_COLUMNS, n_p - j0)
        unit = np.zeros((n_p - j0, m), order="F")
        unit[np.arange(m), np.arange(m)] = 1.0
        y[j0:, n_r + j0:n_r + j0 + m], fail = lapack.dtbtrs(
            factor[:, j0:], unit, uplo="U", trans="T", overwrite_b=1)
        if fail:
            return None
    return y


__all__ = ["UNIT_COLUMNS", "PoseBlock", "solve_lower_unit", "upper_band"]
