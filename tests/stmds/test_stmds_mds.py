"""BOM-STMDS reconstruction (paper III-D): DMC-SPL, classical scaling, weighted SMACOF."""

from __future__ import annotations

import numpy as np
import pytest

from bomgraph.errors import ConfigError, DegenerateGeometryError
from bomgraph.evaluate import align
from bomgraph.stmds.completion import (largest_component, prune_low_degree,
                                       shortest_path_completion)
from bomgraph.stmds.mds import (LaplacianSolver, classical_scaling, raw_stress, smacof,
                                stress1)


def _points(n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(0.0, 2.5, size=(n, 2))


def _pairs_within(x: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    i, j = np.triu_indices(len(x), 1)
    d = np.linalg.norm(x[i] - x[j], axis=1)
    keep = d <= radius
    return i[keep], j[keep], d[keep]


def _max_error_after_alignment(est: np.ndarray, truth: np.ndarray) -> float:
    al = align(est, truth)
    return float(np.abs(al.apply(est) - truth).max())


def test_classical_scaling_recovers_a_complete_matrix_exactly() -> None:
    x = _points(30, 0)
    d2 = ((x[:, None] - x[None]) ** 2).sum(-1)
    est, ev = classical_scaling(d2)
    assert est.shape == (30, 2)
    assert ev[0] >= ev[1] > 0
    assert _max_error_after_alignment(est, x) < 1e-10
    np.testing.assert_allclose(est.mean(0), 0, atol=1e-12)


def test_classical_scaling_textbook_square_and_small_inputs() -> None:
    # the unit square: eigenvalues of B are 1, 1 (with the points centred on the origin)
    sq = np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]])
    d2 = ((sq[:, None] - sq[None]) ** 2).sum(-1)
    est, ev = classical_scaling(d2)
    np.testing.assert_allclose(ev, [1.0, 1.0], atol=1e-12)
    assert _max_error_after_alignment(est, sq) < 1e-12
    one, _ = classical_scaling(np.zeros((1, 1)))
    np.testing.assert_array_equal(one, np.zeros((1, 2)))
    two, _ = classical_scaling(np.array([[0.0, 4.0], [4.0, 0.0]]))
    assert np.linalg.norm(two[0] - two[1]) == pytest.approx(2.0)
    with pytest.raises(DegenerateGeometryError):
        classical_scaling(np.array([[0.0, np.inf], [np.inf, 0.0]]))


def test_dmc_spl_uses_distances_not_squares_and_keeps_known_entries() -> None:
    # a path 0 - 1 - 2 with lengths 3 and 4: the missing 0-2 entry is 7 (not 5, not sqrt(25))
    full = shortest_path_completion(4, np.array([0, 1]), np.array([1, 2]),
                                    np.array([3.0, 4.0]))
    assert full[0, 2] == full[2, 0] == 7.0
    assert np.isinf(full[0, 3]) and full[3, 3] == 0
    # a known pair longer than a path keeps its distance (the paper)
    f, s, d = np.array([0, 1, 0]), np.array([1, 2, 2]), np.array([1.0, 1.0, 5.0])
    assert shortest_path_completion(3, f, s, d)[0, 2] == 5.0


def test_largest_component_reports_the_left_out_vertices() -> None:
    comp = largest_component(7, np.array([0, 1, 4, 5]), np.array([1, 2, 5, 6]))
    # {0,1,2} and {4,5,6} tie: the one with the smallest vertex wins; 3 is isolated
    np.testing.assert_array_equal(comp.kept, [0, 1, 2])
    np.testing.assert_array_equal(comp.left_out, [3, 4, 5, 6])
    assert comp.n_components == 3
    empty = largest_component(0, np.zeros(0, np.int64), np.zeros(0, np.int64))
    assert empty.kept.size == 0


def test_prune_low_degree_keeps_triangles_and_drops_dangling_vertices() -> None:
    tri = prune_low_degree(3, np.array([0, 1, 0]), np.array([1, 2, 2]), 3)
    assert tri.all()
    # K4 plus a vertex hanging on two edges
    f = np.array([0, 0, 0, 1, 1, 2, 4, 4])
    s = np.array([1, 2, 3, 2, 3, 3, 0, 1])
    np.testing.assert_array_equal(prune_low_degree(5, f, s, 3), [True] * 4 + [False])


def test_laplacian_solver_is_the_pseudo_inverse() -> None:
    x = _points(25, 1)
    f, s, _ = _pairs_within(x, 1.2)
    w = np.random.default_rng(2).uniform(0.5, 2.0, len(f))
    lap = np.zeros((25, 25))
    np.add.at(lap, (f, s), -w)
    np.add.at(lap, (s, f), -w)
    lap[np.arange(25), np.arange(25)] = -lap.sum(1)
    b = np.random.default_rng(3).normal(size=(25, 2))
    b -= b.mean(0)
    np.testing.assert_allclose(LaplacianSolver(25, f, s, w).solve(b), np.linalg.pinv(lap) @ b,
                               atol=1e-10)


@pytest.mark.parametrize("relaxation", [1.0, 1.8])
@pytest.mark.parametrize("weighted", [False, True])
def test_smacof_stress_never_increases(relaxation: float, weighted: bool) -> None:
    rng = np.random.default_rng(4)
    x = _points(40, 5)
    f, s, d = _pairs_within(x, 1.3)
    d_noisy = d * (1 + 0.1 * rng.standard_normal(len(d)))
    w = rng.uniform(0.2, 3.0, len(d)) if weighted else None
    res = smacof(40, f, s, d_noisy, init=rng.normal(size=(40, 2)), weights=w, max_iter=200,
                 tol=0.0, relaxation=relaxation)
    assert np.all(np.diff(res.history) <= 1e-12 * res.history[0])
    assert res.history[-1] < 0.2 * res.history[0]
    ww = np.ones(len(d)) if w is None else w
    assert res.raw_stress == pytest.approx(raw_stress(res.points, f, s, d_noisy, ww))
    assert res.stress1 == pytest.approx(stress1(res.points, f, s, d_noisy, ww))


def test_smacof_recovers_an_incomplete_noise_free_graph_from_a_rough_start() -> None:
    x = _points(40, 6)
    f, s, d = _pairs_within(x, 1.2)
    full = shortest_path_completion(40, f, s, d)
    assert np.isfinite(full).all()
    init, _ = classical_scaling(full ** 2)
    assert _max_error_after_alignment(init, x) > 1e-3        # DMC-SPL is only approximate
    res = smacof(40, f, s, d, init=init, max_iter=5000, tol=0.0, relaxation=1.9)
    assert _max_error_after_alignment(res.points, x) < 1e-9
    assert res.stress1 < 1e-10


def test_smacof_checks_its_inputs() -> None:
    f, s, d = np.array([0]), np.array([1]), np.array([1.0])
    with pytest.raises(ConfigError):
        smacof(2, f, s, d, init=np.zeros((3, 2)))
    with pytest.raises(ConfigError):
        smacof(2, f, s, d, init=np.zeros((2, 2)), weights=np.array([0.0]))
    with pytest.raises(ConfigError):
        smacof(2, f, s, d, init=np.zeros((2, 2)), relaxation=2.0)
    # one point, and a pair starting at the same spot, do not crash
    assert smacof(1, np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0),
                  init=np.zeros((1, 2))).points.shape == (1, 2)
    res = smacof(2, f, s, d, init=np.array([[0.0, 0.0], [0.5, 0.0]]))
    assert np.linalg.norm(res.points[0] - res.points[1]) == pytest.approx(1.0)


def test_component_labels_match_scipy() -> None:
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from bomgraph.stmds.completion import component_labels

    rng = np.random.default_rng(7)
    for n, e in ((1, 0), (30, 10), (60, 45), (200, 400)):
        f = rng.integers(0, n, e)
        s = rng.integers(0, n, e)
        lab = component_labels(n, f, s)
        g = coo_matrix((np.ones(e), (f, s)), shape=(n, n))
        k, ref = connected_components(g, directed=False)
        assert len(np.unique(lab)) == k
        # same partition, and each label is the smallest vertex of its component
        for c in range(k):
            members = np.flatnonzero(ref == c)
            assert np.all(lab[members] == members.min())


def test_classical_scaling_of_a_large_map_uses_lanczos_and_is_exact() -> None:
    x = _points(420, 8) * 4
    d2 = ((x[:, None] - x[None]) ** 2).sum(-1)
    est, ev = classical_scaling(d2)
    assert ev[0] >= ev[1] > 0
    assert _max_error_after_alignment(est, x) < 1e-9


def test_landmark_mds_is_exact_for_euclidean_distances() -> None:
    from bomgraph.stmds.completion import pivot_shortest_paths
    from bomgraph.stmds.mds import landmark_scaling

    x = _points(60, 9)
    f, s, d = np.triu_indices(60, 1) + (None,)
    d = np.linalg.norm(x[f] - x[s], axis=1)
    pivots, rows = pivot_shortest_paths(60, f, s, d, 8)   # complete graph: paths = distances
    assert len(np.unique(pivots)) == 8
    np.testing.assert_allclose(rows, np.linalg.norm(x[pivots][:, None] - x[None], axis=2),
                               atol=1e-12)
    est = landmark_scaling(rows, pivots)
    assert _max_error_after_alignment(est, x) < 1e-10


def test_trilaterate_is_exact_and_refuses_undetermined_points() -> None:
    from bomgraph.stmds.mds import trilaterate

    anchors = _points(6, 10)
    x = np.array([1.1, 0.7])
    d = np.linalg.norm(anchors - x, axis=1)
    np.testing.assert_allclose(trilaterate(anchors, d), x, atol=1e-12)
    # noisy ranges: the Gauss-Newton refinement lowers the range residual
    noisy = d + np.random.default_rng(11).normal(0, 0.02, 6)
    est = trilaterate(anchors, noisy)
    assert np.linalg.norm(est - x) < 0.06
    assert trilaterate(anchors[:3], d[:3]) is None                 # needs 4 by default
    line = np.column_stack([np.linspace(0, 2, 5), np.zeros(5)])
    assert trilaterate(line, np.linalg.norm(line - x, axis=1)) is None
