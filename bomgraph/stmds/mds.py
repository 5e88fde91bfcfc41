"""Coordinates from distances: classical scaling and weighted SMACOF (paper section III-D, eq. 6).

Classical scaling double-centres the squared distance matrix, ``B = -1/2 J D2 J`` with
``J = I - 11^T / n``, and takes the top two eigenpairs (``scipy.linalg.eigh`` with a subset of
eigenvalues, or Lanczos ``eigsh`` for large ``n``; negative eigenvalues are clipped to zero).
It minimises Strain globally.

Weighted SMACOF minimises the raw stress of eq. 6,
``sigma(X) = sum_{known i<j} w_ij (delta_ij - |x_i - x_j|)^2``, by iterative majorisation: the
Guttman transform ``X+ = V^+ B(X) X`` where ``V = sum w_ij (e_i - e_j)(e_i - e_j)^T`` is the
weighted graph Laplacian and ``B(X) X`` is accumulated edge by edge (no dense ``n x n`` work).
``V^+`` is never formed: the Laplacian with one vertex grounded is factorised once (sparse LU)
and the factorisation is reused by every iteration; the grounded solution is then centred, which
equals ``V^+ b`` for a connected graph. An over-relaxed step ``X + alpha (X+ - X)`` with
``0 < alpha < 2`` still never increases the stress (the majoriser is a quadratic symmetric about
``X+``); ``alpha = 1`` is the textbook algorithm. Weights are binary (the paper) or inverse
variances of the fused distances (an option, chosen by the caller). Stress-1 is
``sqrt(sigma(X) / sum w delta^2)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg
from scipy.sparse import coo_matrix
import scipy.sparse.linalg
from scipy.sparse.linalg import splu

from ..errors import ConfigError, DegenerateGeometryError


_DENSE_EIG_MAX = 300   # above this many points classical scaling uses Lanczos (eigsh)


def double_centre(squared_distance: np.ndarray) -> np.ndarray:
    """``-1/2 J D2 J`` of a symmetric ``(n, n)`` squared distance matrix (a new array)."""
    d2 = np.asarray(squared_distance, dtype=float)
    row = d2.mean(axis=1)
    total = row.mean()
    return -0.5 * (d2 - row[:, None] - row[None, :] + total)


def classical_scaling(squared_distance: np.ndarray, dim: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Classical (Torgerson) scaling of a complete squared distance matrix.

    Parameters
    ----------
    squared_distance : array of shape (n, n)
        Symmetric, zero diagonal, finite (m^2).
    dim : int
        Embedding dimension.

    Returns
    -------
    points : ndarray of shape (n, dim)
        Centred coordinates (m).
    eigenvalues : ndarray of shape (dim,)
        The top eigenvalues of ``B``, descending (before clipping at zero).
    """
    d2 = np.asarray(squared_distance, dtype=float)
    n = d2.shape[0]
    if d2.shape != (n, n):
        raise ConfigError(f"classical_scaling: need a square matrix, got {d2.shape}")
    if not np.all(np.isfinite(d2)):
        raise DegenerateGeometryError("classical_scaling: the squared distance matrix has "
                                      "missing (non-finite) entries; complete it first "
                                      "(shortest_path_completion)")
    if n == 0:
        return np.zeros((0, dim)), np.zeros(dim)
    b = double_centre(d2)
    k = min(dim, n)
    if n > _DENSE_EIG_MAX:
        # Lanczos (ARPACK) for the few top eigenpairs; a fixed start vector keeps it
        # deterministic (the result does not depend on it beyond round-off)
        v0 = np.cos(0.7 * np.arange(n)) + 0.5
        vals, vecs = scipy.sparse.linalg.eigsh(b, k=k, which="LA", v0=v0)
        order = np.argsort(vals)[::-1]
        vals, vecs = vals[order], vecs[:, order]
    else:
        vals, vecs = scipy.linalg.eigh(b, subset_by_index=[n - k, n - 1], check_finite=False)
        vals, vecs = vals[::-1], vecs[:, ::-1]
    pts = np.zeros((n, dim))
    pts[:, :k] = vecs * np.sqrt(np.maximum(vals, 0.0))
    ev = np.zeros(dim)
    ev[:k] = vals
    return pts, ev


def landmark_scaling(pivot_rows: np.ndarray, pivots: np.ndarray,
                     dim: int = 2) -> np.ndarray:
    """Landmark MDS (de Silva and Tenenbaum, 2004): classical scaling of the pivots, then every
    point placed from its squared distances to the pivots.

    With ``D2_p`` the pivots' squared distances (column means ``mu``) and their classical
    scaling ``B_p = V diag(lambda) V^T``, a point with squared distances ``delta`` to the pivots
    goes to ``x = -1/2 diag(lambda)^(-1/2) V^T (delta - mu)``: exact for Euclidean distances,
    the same map as classical scaling of the full matrix then.

    Parameters
    ----------
    pivot_rows : array of shape (m, n)
        Distances (not squared) from each pivot to every point; finite.
    pivots : array of shape (m,)
        The pivots' own point indices.

    Returns
    -------
    ndarray of shape (n, dim)
    """
    d2 = np.asarray(pivot_rows, float) ** 2
    d2_pp = d2[:, pivots]
    d2_pp = 0.5 * (d2_pp + d2_pp.T)
    b = double_centre(d2_pp)
    m = len(pivots)
    k = min(dim, m)
    vals, vecs = scipy.linalg.eigh(b, subset_by_index=[m - k, m - 1])
    vals, vecs = vals[::-1], vecs[:, ::-1]
    scale = np.where(vals > 0, 1.0 / np.sqrt(np.maximum(vals, 1e-300)), 0.0)
    mu = d2_pp.mean(axis=0)
    pts = np.zeros((d2.shape[1], dim))
    pts[:, :k] = -0.5 * ((d2 - mu[:, None]).T @ vecs) * scale
    return pts - pts.mean(axis=0)


def trilaterate(anchors_xy: np.ndarray, distance_m: np.ndarray,
                variance_m2: np.ndarray | None = None, n_refine: int = 5,
                min_anchors: int = 4) -> np.ndarray | None:
    """A point from its distances to known points (least squares), or None if undetermined.

    The squared-range equations ``|x|^2 - 2 a_i . x + |a_i|^2 = r_i^2`` are linear in
    ``(x, y, |x|^2)``: solved by weighted least squares (weights ``1 / var(r^2)``; exact for
    exact distances and anchors not on a line), then refined by Gauss-Newton steps on the
    ranges themselves (weights ``1 / var(r)``), each kept only if it lowers the cost. Needs
    ``min_anchors`` anchors (3 unknowns; one more gives redundancy against a bad range).

    Parameters
    ----------
    anchors_xy : array of shape (m, 2)
    distance_m : array of shape (m,)
    variance_m2 : array of shape (m,), optional
        Variances of the distances (equal if None).
    """
    a = np.asarray(anchors_xy, float).reshape(-1, 2)
    r = np.asarray(distance_m, float).reshape(-1)
    if len(a) < max(3, min_anchors):
        return None
    v = np.ones_like(r) if variance_m2 is None else np.maximum(np.asarray(variance_m2), 1e-300)
    w_sq = 1.0 / (4.0 * np.maximum(r * r, 1e-12) * v)
    lhs = np.column_stack([-2.0 * a, np.ones(len(a))]) * np.sqrt(w_sq)[:, None]
    rhs = (r * r - (a * a).sum(axis=1)) * np.sqrt(w_sq)
    sol, _, rank, _ = np.linalg.lstsq(lhs, rhs, rcond=None)
    if rank < 3:
        return None
    x = sol[:2]
    sw = 1.0 / np.sqrt(v)

    def residual(p: np.ndarray) -> np.ndarray:
        return (r - np.sqrt(((p - a) ** 2).sum(axis=1))) * sw

    cost = float(np.sum(residual(x) ** 2))
    for _ in range(n_refine):
        off = x - a
        d = np.sqrt((off * off).sum(axis=1))
        if np.any(d == 0):
            break
        jac = (off / d[:, None]) * sw[:, None]
        step, *_ = np.linalg.lstsq(jac, (r - d) * sw, rcond=None)
        new_cost = float(np.sum(residual(x + step) ** 2))
        if not new_cost < cost:
            break
        x, cost = x + step, new_cost
    return x


def raw_stress(points: np.ndarray, first: np.ndarray, second: np.ndarray,
               dissimilarity: np.ndarray, weights: np.ndarray) -> float:
    """Eq. 6: ``sum w (delta - |x_i - x_j|)^2`` over the listed pairs."""
    # rows gathered as complex numbers (one element each: many times faster than a gather
    # of (n, 2) rows) and subtracted part by part, the same bits as ``points[first] - ...``
    rows = np.ascontiguousarray(points, dtype=float).view(np.complex128)[:, 0]
    diff = (rows[first] - rows[second]).view(np.float64).reshape(-1, 2)
    r = np.sqrt(np.einsum("pa,pa->p", diff, diff)) - dissimilarity
    return float(np.dot(weights, r * r))


def stress1(points: np.ndarray, first: np.ndarray, second: np.ndarray,
            dissimilarity: np.ndarray, weights: np.ndarray) -> float:
    """Kruskal's Stress-1 ``sqrt(raw stress / sum w delta^2)``."""
    norm = float(np.dot(weights, dissimilarity * dissimilarity))
    if norm <= 0:
        return 0.0
    return float(np.sqrt(raw_stress(points, first, second, dissimilarity, weights) / norm))


class LaplacianSolver:
    """Solves ``V y = b`` for the weighted Laplacian ``V`` of a connected graph (``b`` summing to
    zero), returning the centred solution ``V^+ b``; factorised once, reused.

    Small graphs (``n <= dense_max``) invert ``M = V + 1 1^T / n`` once (for ``b`` orthogonal to
    the ones, ``M^-1 b = V^+ b``); larger ones factorise the Laplacian with one vertex grounded
    (sparse LU) and centre the result.

    Parameters
    ----------
    n : int
    first, second : arrays of shape (P,)
        Edges (each once).
    weights : array of shape (P,)
        Positive edge weights.
    dense_max : int
        Largest ``n`` solved densely.
    """

    def __init__(self, n: int, first: np.ndarray, second: np.ndarray,
                 weights: np.ndarray, dense_max: int = 300) -> None:
        self.n = n
        self._minv: np.ndarray | None = None
        self._minv_complex: np.ndarray | None = None     # the same, cast once for complex b
        self._lu = None
        if n <= 1:
            return
        w = np.asarray(weights, float)
        deg = np.bincount(first, w, n) + np.bincount(second, w, n)
        if n <= dense_max:
            lap = np.zeros(n * n)                  # (n, n), filled through flat indices
            neg = -w
            lap[first * n + second] = neg
            lap[second * n + first] = neg
            lap[::n + 1] = deg
            lap = lap.reshape(n, n)
            self._minv = np.linalg.inv(lap + 1.0 / n)
            return
        rows = np.concatenate([first, second, np.arange(n)])
        cols = np.concatenate([second, first, np.arange(n)])
        vals = np.concatenate([-w, -w, deg])
        lap = coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsc()
        self._lu = splu(lap[1:, 1:].tocsc())

    def _complex_inverse(self) -> np.ndarray | None:
        """``(V + 1 1^T / n)^-1`` cast to complex, shape (n, n) (cast once, kept), for a
        caller that multiplies complex ``b`` itself; None on the sparse path (use :meth:`solve`).
        """
        if self._minv is None:
            return None
        if self._minv_complex is None:
            self._minv_complex = self._minv.astype(np.complex128)
        return self._minv_complex

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``V^+ b`` for ``b`` of shape (n,) or (n, k), real or complex, with zero (column) sums."""
        if self._minv is not None:
            if np.iscomplexobj(b):
                return self._complex_inverse() @ b
            return self._minv @ b
        if self._lu is None:
            return np.zeros_like(b)
        y = np.zeros_like(b)
        if np.iscomplexobj(b):
            y[1:] = (self._lu.solve(np.ascontiguousarray(b[1:].real))
                     + 1j * self._lu.solve(np.ascontiguousarray(b[1:].imag)))
        else:
            y[1:] = self._lu.solve(np.ascontiguousarray(b[1:]))
        return y - y.mean(axis=0)


@dataclass(frozen=True, eq=False)
class SmacofResult:
    """The outcome of :func:`smacof`.

    Attributes
    ----------
    points : ndarray of shape (n, 2)
        Centred coordinates (m).
    stress1 : float
        Stress-1 of ``points``.
    raw_stress : float
        Eq. 6 at ``points``.
    n_iter : int
        Guttman transforms applied.
    converged : bool
        The relative stress decrease fell below ``tol`` before ``max_iter``.
    history : ndarray of shape (n_iter + 1,)
        Raw stress before each iteration and at the end (non-increasing).
    """

    points: np.ndarray
    stress1: float
    raw_stress: float
    n_iter: int
    converged: bool
    history: np.ndarray


def _smacof_single(z: np.ndarray, first: np.ndarray, second: np.ndarray, delta: np.ndarray,
                   weights: np.ndarray, solver: LaplacianSolver, max_iter: int, tol: float,
                   relaxation: float) -> tuple[np.ndarray, list[float], bool]:
    """The SMACOF loop on points as complex numbers ``x + i y`` (one vectorised Guttman
    transform per iteration, no loop over pairs).

    ``B(X) X`` at vertex ``i`` is ``sum_j w_ij delta_ij / d_ij (z_i - z_j)``: one complex
    ``np.add.at`` over the first ends of the edges and one ``np.subtract.at`` over the second
    ends, into a fresh ``(n,)`` complex array (the sums of a ``bincount`` over both ends of
    ``(v, -v)``, in the same order: the same bits). The scatter's target and indices are
    arrays made here (fresh and contiguous: ``ufunc.at`` is slow on arrays read back from a
    pickle); the Laplacian's complex inverse is taken once, outside the loop. Plain operators
    rather than ``out=`` keywords: numpy reuses their temporaries, and parsing the keyword
    costs more than the allocation at these sizes. Returns the final points, the raw stress
    history (starting point first) and whether the relative decrease fell below ``tol``. An
    iterate whose stress rose (only possible through round-off at a stationary point) is not
    accepted.
    """
    n = z.shape[0]
    e = first.size
    wd = weights * delta
    # both ends of every edge in one fresh int64 array: one gather per iteration
    ends = np.concatenate((first, second))
    first, second = ends[:e], ends[e:]
    minv = solver._complex_inverse()               # (n, n) complex, None: the sparse LU
    relaxed = relaxation != 1.0
    z = z - z.mean()
    diff = z[first] - z[second]
    dist = np.abs(diff)
    r = dist - delta
    s = float(np.dot(weights, r * r))
    history = [s]
    ratio = np.zeros(e)
    for _ in range(max_iter):
        if s == 0.0:
            return z, history, True
        if dist.min() > 0:                       # no coincident points: no mask needed
            ratio = wd / dist
        else:                                    # (coincident: the last ratio kept there)
            np.divide(wd, dist, out=ratio, where=dist > 0)
        v = ratio * diff
        bz = np.zeros(n, np.complex128)
        np.add.at(bz, first, v)
        np.subtract.at(bz, second, v)
        g = minv @ bz if minv is not None else solver.solve(bz)
        z_new = z + relaxation * (g - z) if relaxed else g
        at_ends = z_new[ends]                    # both ends of every edge in one gather
        diff_new = at_ends[:e] - at_ends[e:]
        dist_new = np.abs(diff_new)
        r = dist_new - delta
        s_new = float(np.dot(weights, r * r))
        if s_new > s:
            return z, history, True
        z, diff, dist = z_new, diff_new, dist_new
        history.append(s_new)
        done = (s - s_new) <= tol * s
        s = s_new
        if done:
            return z, history, True
    return z, history, False


def smacof(n: int, first: np.ndarray, second: np.ndarray, dissimilarity: np.ndarray, *,
           init: np.ndarray, weights: np.ndarray | None = None, max_iter: int = 300,
           tol: float = 1e-6, relaxation: float = 1.0,
           solver: LaplacianSolver | None = None) -> SmacofResult:
    """Weighted SMACOF on the known pairs only (eq. 6), started from ``init``.

    Parameters
    ----------
    n : int
        Number of points; the graph of ``first -- second`` must be connected.
    first, second : arrays of shape (P,), int
        The known pairs (each once).
    dissimilarity : array of shape (P,)
        Target distances (m, not squared).
    init : array of shape (n, 2)
        Starting coordinates (e.g. classical scaling after DMC-SPL, or the previous map).
    weights : array of shape (P,), optional
        Positive weights; all ones (the paper's binary weights) if None.
    max_iter : int
        Most Guttman transforms.
    tol : float
        Stop when the raw stress decreases by less than ``tol`` times itself.
    relaxation : float
        Step ``X + relaxation (X+ - X)``, in ``(0, 2)``; 1 is the plain Guttman transform.
    solver : LaplacianSolver, optional
        A factorisation of the weighted Laplacian to reuse.

    Returns
    -------
    SmacofResult
    """
    first = np.asarray(first, np.int64)
    second = np.asarray(second, np.int64)
    delta = np.asarray(dissimilarity, float)
    w = np.ones_like(delta) if weights is None else np.asarray(weights, float)
    x0 = np.array(init, dtype=float)
    if x0.shape != (n, 2):
        raise ConfigError(f"smacof: init must have shape (n={n}, 2), got {x0.shape}")
    if not (first.shape == second.shape == delta.shape == w.shape):
        raise ConfigError("smacof: first, second, dissimilarity and weights differ in length")
    # all positive and finite checked by two reductions (NaN fails both comparisons)
    weights_ok = w.size == 0 or (w.min() > 0 and w.max() < math.inf)
    if not weights_ok:
        raise ConfigError("smacof: weights must be finite and > 0 (leave unknown pairs out)")
    if not 0 < relaxation < 2:
        raise ConfigError(f"smacof: relaxation must be in (0, 2), got {relaxation}")
    if max_iter < 0:
        raise ConfigError("smacof: max_iter must be >= 0")
    if solver is None:
        solver = LaplacianSolver(n, first, second, w)
    z, hist, conv = _smacof_single(x0[:, 0] + 1j * x0[:, 1], first, second, delta, w, solver,
                                   max_iter, tol, relaxation)
    x = z.view(np.float64).reshape(n, 2)          # (x, y) rows: the parts of the fresh z
    norm = float(np.dot(w, delta * delta))
    s1 = float(np.sqrt(hist[-1] / norm)) if norm > 0 else 0.0
    return SmacofResult(x, s1, hist[-1], len(hist) - 1, conv, np.array(hist))


__all__ = ["double_centre", "classical_scaling", "landmark_scaling", "trilaterate",
           "raw_stress", "stress1", "LaplacianSolver", "SmacofResult", "smacof"]
