"""Independent checks of the reconstruction formulas (paper III-D, eq. 6).

The existing tests check exact recovery from noise-free distances and that the stress never
increases; these check one Guttman transform against its dense textbook form
``X+ = V^+ B(X) X``, that SMACOF's answer is a stationary point of eq. 6 (numeric gradient),
classical scaling's eigenvalues against the points' scatter matrix and its invariance under
relabelling, and trilateration against a generic least-squares solver.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from bomgraph.stmds.mds import classical_scaling, double_centre, raw_stress, smacof, trilaterate


def _graph(n: int, seed: int, radius: float = 1.3):
    rng = np.random.default_rng(seed)
    x = rng.uniform(0.0, 2.5, (n, 2))
    i, j = np.triu_indices(n, 1)
    d = np.linalg.norm(x[i] - x[j], axis=1)
    keep = d <= radius
    return rng, x, i[keep], j[keep], d[keep]


def _guttman_dense(x: np.ndarray, f: np.ndarray, s: np.ndarray, delta: np.ndarray,
                   w: np.ndarray) -> np.ndarray:
    """Borg and Groenen (2005), eq. 8.29: ``X+ = V^+ B(X) X`` with dense ``V`` and ``B``."""
    n = len(x)
    v = np.zeros((n, n))
    b = np.zeros((n, n))
    dist = np.linalg.norm(x[f] - x[s], axis=1)
    for k in range(len(f)):
        i, j = f[k], s[k]
        v[i, j] = v[j, i] = -w[k]
        b[i, j] = b[j, i] = -w[k] * delta[k] / dist[k]
    v[np.diag_indices(n)] = -v.sum(1)
    b[np.diag_indices(n)] = -b.sum(1)
    return np.linalg.pinv(v) @ b @ x


def test_one_guttman_transform_is_the_dense_textbook_formula() -> None:
    rng, x, f, s, d = _graph(30, 41)
    delta = d * (1 + 0.1 * rng.standard_normal(len(d)))
    w = rng.uniform(0.3, 3.0, len(d))
    x0 = rng.normal(size=(30, 2))
    res = smacof(30, f, s, delta, init=x0, weights=w, max_iter=1, tol=0.0)
    assert res.n_iter == 1
    want = _guttman_dense(x0 - x0.mean(0), f, s, delta, w)
    np.testing.assert_allclose(res.points, want - want.mean(0), rtol=0, atol=1e-10)
    # and the over-relaxed step is X + alpha (X+ - X)
    res = smacof(30, f, s, delta, init=x0, weights=w, max_iter=1, tol=0.0, relaxation=1.5)
    xc = x0 - x0.mean(0)
    np.testing.assert_allclose(res.points, xc + 1.5 * (want - xc), rtol=0, atol=1e-10)


def test_smacof_ends_at_a_stationary_point_of_the_weighted_stress() -> None:
    rng, x, f, s, d = _graph(25, 42)
    delta = d * (1 + 0.05 * rng.standard_normal(len(d)))
    w = rng.uniform(0.3, 3.0, len(d))
    res = smacof(25, f, s, delta, init=x + rng.normal(0, 0.05, x.shape), weights=w,
                 max_iter=20000, tol=0.0, relaxation=1.9)
    p = res.points.reshape(-1)
    eps = 1e-6
    grad = np.empty_like(p)
    for k in range(p.size):
        up, dn = p.copy(), p.copy()
        up[k] += eps
        dn[k] -= eps
        grad[k] = (raw_stress(up.reshape(-1, 2), f, s, delta, w)
                   - raw_stress(dn.reshape(-1, 2), f, s, delta, w)) / (2 * eps)
    assert np.abs(grad).max() < 1e-7, np.abs(grad).max()
    assert res.raw_stress > 1e-3                # noisy distances: a true minimum, not a fit
    assert abs(res.raw_stress - raw_stress(res.points, f, s, delta, w)) <= 1e-12 * res.raw_stress


def test_classical_scaling_eigenvalues_are_the_scatter_matrix_and_relabelling_permutes() -> None:
    rng = np.random.default_rng(43)
    x = rng.uniform(0, 2.5, (40, 2))
    d2 = ((x[:, None] - x[None]) ** 2).sum(-1)
    est, ev = classical_scaling(d2)
    xc = x - x.mean(0)
    np.testing.assert_allclose(ev, np.linalg.eigvalsh(xc.T @ xc)[::-1], rtol=1e-10)
    np.testing.assert_allclose(double_centre(d2), xc @ xc.T, atol=1e-12)
    # relabelling: the same map, rows permuted (up to the sign of each axis)
    perm = rng.permutation(40)
    est_p, ev_p = classical_scaling(d2[np.ix_(perm, perm)])
    np.testing.assert_allclose(ev_p, ev, rtol=1e-12)
    signs = np.sign((est_p * est[perm]).sum(0))
    np.testing.assert_allclose(est_p * signs, est[perm], rtol=0, atol=1e-10)


def test_trilaterate_with_noisy_ranges_is_the_weighted_least_squares_minimum() -> None:
    rng = np.random.default_rng(44)
    solved = 0
    for _ in range(20):
        anchors = rng.uniform(0, 2.5, (6, 2))
        x = rng.uniform(0.3, 2.2, 2)
        var = rng.uniform(1e-4, 9e-4, 6)
        r = np.linalg.norm(anchors - x, axis=1) + rng.normal(0, 1, 6) * np.sqrt(var)
        est = trilaterate(anchors, r, var)
        ref = least_squares(lambda p: (r - np.linalg.norm(anchors - p, axis=1)) / np.sqrt(var),
                            x, xtol=1e-15, ftol=1e-15, gtol=1e-15).x
        np.testing.assert_allclose(est, ref, rtol=0, atol=1e-7)
        solved += 1
    assert solved == 20


def _floyd_warshall(n: int, f: np.ndarray, s: np.ndarray, d: np.ndarray) -> np.ndarray:
    """The textbook triple loop (vectorised over one index), for reference."""
    w = np.full((n, n), np.inf)
    np.fill_diagonal(w, 0.0)
    w[f, s] = np.minimum(w[f, s], d)
    w[s, f] = w[f, s]
    for k in range(n):
        w = np.minimum(w, w[:, k:k + 1] + w[k:k + 1, :])
    return w


def test_dmc_spl_is_floyd_warshall_with_the_known_pairs_kept_on_both_solvers() -> None:
    from bomgraph.stmds.completion import DENSE_PATHS_MAX, shortest_path_completion

    for n in (40, DENSE_PATHS_MAX + 20):                 # the dense and the sparse solver
        rng, x, f, s, d = _graph(n, 45, radius=0.6 if n > 100 else 1.0)
        d = d * (1 + 0.2 * rng.uniform(-1, 1, len(d)))   # known pairs not metric
        ref = _floyd_warshall(n, f, s, d)
        ref[f, s] = ref[s, f] = d                         # the paper: known pairs kept
        got = shortest_path_completion(n, f, s, d)
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=0)
        assert (got[f, s] > _floyd_warshall(n, f, s, d)[f, s]).any()   # the rule bites


def test_prune_low_degree_is_the_k_core_by_peeling_one_vertex_at_a_time() -> None:
    from bomgraph.stmds.completion import prune_low_degree

    rng = np.random.default_rng(46)
    sizes = []
    for _ in range(20):
        n = 30
        i, j = np.triu_indices(n, 1)
        keep = rng.random(i.size) < rng.uniform(0.07, 0.16)      # cores from empty to most
        f, s = i[keep], j[keep]
        alive = np.zeros(n, bool)
        alive[f] = alive[s] = True
        k = min(3, int(alive.sum()) - 1)
        adj = np.zeros((n, n), bool)
        adj[f, s] = adj[s, f] = True
        changed = True
        while changed:                                   # one vertex at a time
            changed = False
            for v in range(n):
                if alive[v] and adj[v, alive].sum() < k:
                    alive[v] = False
                    changed = True
        np.testing.assert_array_equal(prune_low_degree(n, f, s, 3), alive)
        sizes.append(int(alive.sum()))
    assert min(sizes) == 0 and 10 < np.median(sizes) < 30


def test_trilaterate_start_is_the_weighted_linear_solve_and_refinement_never_raises_cost() -> None:
    """With ``n_refine=0`` the answer is the linear solve of the squared-range equations
    ``2 a_i . x - |x|^2 = |a_i|^2 - r_i^2`` weighted by ``1 / var(r_i^2) = 1 / (4 r_i^2 v_i)``,
    written here as normal equations; the Gauss-Newton refinement keeps a step only if the
    range cost falls, so with coarse ranges (where a full step can overshoot) the refined
    cost is never above the start's."""
    rng = np.random.default_rng(45)
    for _ in range(200):
        anchors = rng.uniform(0, 2.5, (5, 2))
        x = rng.uniform(0.3, 2.2, 2)
        var = rng.uniform(1e-3, 0.09, 5)
        r = np.abs(np.linalg.norm(anchors - x, axis=1) + rng.normal(0, 1, 5) * np.sqrt(var))
        start = trilaterate(anchors, r, var, n_refine=0)
        a = np.column_stack([2.0 * anchors, -np.ones(5)])
        y = (anchors ** 2).sum(1) - r ** 2
        w = 1.0 / (4.0 * r ** 2 * var)
        sol = np.linalg.solve(a.T @ (w[:, None] * a), a.T @ (w * y))
        np.testing.assert_allclose(start, sol[:2], rtol=1e-7, atol=1e-9)

        def cost(p: np.ndarray) -> float:
            return float((((r - np.linalg.norm(anchors - p, axis=1)) ** 2) / var).sum())

        assert cost(trilaterate(anchors, r, var)) <= cost(start) * (1 + 1e-12)


def test_smacof_is_scale_equivariant_including_when_it_stops() -> None:
    """Distances and start scaled by 1000: the same iterations (``tol`` is relative to the
    stress), the points scaled by 1000, Stress-1 unchanged."""
    rng, x, f, s, d = _graph(30, 46)
    d_noisy = d * (1 + 0.05 * rng.standard_normal(len(d)))
    init = x + rng.normal(0, 0.3, x.shape)
    a = smacof(30, f, s, d_noisy, init=init, tol=1e-5)
    b = smacof(30, f, s, 1000.0 * d_noisy, init=1000.0 * init, tol=1e-5)
    assert a.converged and b.converged and a.n_iter == b.n_iter > 3
    np.testing.assert_allclose(b.points, 1000.0 * a.points, rtol=1e-9, atol=1e-9)
    assert b.stress1 == pytest.approx(a.stress1, rel=1e-9)


def test_sparse_laplacian_solver_is_the_centred_pseudo_inverse() -> None:
    """The sparse-LU path (grounded vertex, then centred) is ``V^+ b`` like the dense one:
    forced with ``dense_max=0``, real and complex ``b``."""
    from bomgraph.stmds.mds import LaplacianSolver

    rng, x, f, s, _ = _graph(40, 47)
    w = rng.uniform(0.5, 2.0, len(f))
    lap = np.zeros((40, 40))
    np.add.at(lap, (f, s), -w)
    np.add.at(lap, (s, f), -w)
    lap[np.diag_indices(40)] = -lap.sum(1)
    b = rng.normal(size=(40, 2))
    b -= b.mean(0)
    want = np.linalg.pinv(lap) @ b
    solver = LaplacianSolver(40, f, s, w, dense_max=0)
    np.testing.assert_allclose(solver.solve(b), want, atol=1e-10)
    got = solver.solve(b[:, 0] + 1j * b[:, 1])
    np.testing.assert_allclose(np.column_stack([got.real, got.imag]), want, atol=1e-10)
