"""Distance matrix correction by shortest path lengths, DMC-SPL (paper section III-D.1).

The known pairs form an undirected graph whose edge lengths are the fused *distances* (not
squared: path lengths add). A missing entry of the distance matrix is replaced by the length of
the shortest path between its two landmarks: Floyd-Warshall on the dense matrix for up to
:data:`DENSE_PATHS_MAX` vertices (``O(n^3)`` but no sparse-matrix overhead: faster there), else
Dijkstra over ``scipy.sparse.csgraph`` (``O(n E log n)`` on the sparse graph). A graph in
several pieces cannot be embedded as one map: :func:`largest_component` picks the biggest piece
and names the landmarks left out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import floyd_warshall, shortest_path

from ..errors import ConfigError

# csgraph treats an explicit 0 as "no edge"; coincident landmarks get this length instead.
_MIN_EDGE_M = 1e-12
#: Largest graph completed by dense Floyd-Warshall (faster than Dijkstra up to here, see
#: ``docs/measurements.md``; the two differ by round-off in the completed entries only).
DENSE_PATHS_MAX = 300


def edge_graph(n: int, first: np.ndarray, second: np.ndarray,
               length: np.ndarray) -> csr_matrix:
    """The symmetric sparse ``(n, n)`` graph with ``length`` on edges ``first -- second``."""
    first = np.asarray(first, np.int64)
    second = np.asarray(second, np.int64)
    w = np.maximum(np.asarray(length, float), _MIN_EDGE_M)
    if first.size and (first.min() < 0 or max(first.max(), second.max()) >= n):
        raise ConfigError(f"edge_graph: vertex index out of range 0..{n - 1}")
    rows = np.concatenate([first, second])
    cols = np.concatenate([second, first])
    return coo_matrix((np.concatenate([w, w]), (rows, cols)), shape=(n, n)).tocsr()


@dataclass(frozen=True, eq=False)
class Component:
    """The vertices kept (largest connected component) and those left out, as index arrays."""

    kept: np.ndarray
    left_out: np.ndarray
    n_components: int


def largest_component(n: int, first: np.ndarray, second: np.ndarray,
                      size_weight: np.ndarray | None = None) -> Component:
    """The largest connected component of the graph of known pairs on ``n`` vertices.

    Ties go to the component holding the smallest vertex index. Vertices without any edge count
    as components of their own (so an empty graph keeps vertex 0 alone). ``size_weight``
    (shape ``(n,)``) counts vertices unequally, e.g. landmarks 1 and robot positions 0.
    """
    if n == 0:
        return Component(np.zeros(0, np.int64), np.zeros(0, np.int64), 0)
    labels = component_labels(n, first, second)
    if not labels.any():             # one component (every vertex labelled 0): keep them all
        return Component(np.arange(n), np.zeros(0, np.int64), 1)
    roots, labels = np.unique(labels, return_inverse=True)
    sizes = np.bincount(labels, weights=size_weight, minlength=len(roots))
    best = int(np.argmax(sizes))   # argmax takes the first maximum: the smallest vertex
    keep = labels == best
    return Component(np.flatnonzero(keep), np.flatnonzero(~keep), len(roots))


def component_labels(n: int, first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """Connected components of an undirected graph: each vertex labelled by the smallest vertex
    of its component, shape ``(n,)``.

    Minimum-label propagation along the edges with pointer jumping (``label[label]``), a few
    vectorised passes (about the log of the diameter), no loop over vertices or edges. Much
    cheaper than building a ``scipy.sparse`` graph for the small graphs mapped at every step.
    The labels are final once both ends of every edge carry the same one (a pass would then
    change nothing: the labels are already their own roots), so that is checked between
    passes instead of running one more.
    """
    first = np.asarray(first, np.int64)
    second = np.asarray(second, np.int64)
    label = np.arange(n)
    low = np.minimum(first, second)      # the first pass: every label is its vertex
    while True:
        np.minimum.at(label, first, low)
        np.minimum.at(label, second, low)
        while True:                      # pointer jumping: follow labels to their roots
            jumped = label[label]
            if not (jumped != label).any():
                break
            label = jumped
        at_first, at_second = label[first], label[second]
        if not (at_first != at_second).any():
            return label
        low = np.minimum(at_first, at_second)


def prune_low_degree(n: int, first: np.ndarray, second: np.ndarray,
                     min_degree: int) -> np.ndarray:
    """The ``k``-core: repeatedly drop vertices with fewer than ``k`` edges.

    ``k = min(min_degree, n_with_edges - 1)`` so that a complete graph on few vertices (a
    triangle, ...) is kept whole. In the plane a vertex needs 3 known distances to a rigid set
    to be located uniquely (2 leave a mirror ambiguity, 1 a free rotation); the 3-core removes
    such under-determined landmarks (e.g. ones known only through one or two priors).

    Returns
    -------
    ndarray of shape (n,), bool
        Vertices kept.
    """
    first = np.asarray(first, np.int64)
    second = np.asarray(second, np.int64)
    deg = np.bincount(first, minlength=n) + np.bincount(second, minlength=n)
    alive = deg > 0                      # the vertices with an edge
    k = min(int(min_degree), max(int(np.count_nonzero(alive)) - 1, 0))
    while True:
        drop = alive & (deg < k)
        if not drop.any():
            return alive
        alive &= ~drop
        edge = alive[first] & alive[second]  # the edges between live vertices
        deg = np.bincount(first[edge], minlength=n) + np.bincount(second[edge], minlength=n)


def shortest_path_completion(n: int, first: np.ndarray, second: np.ndarray,
                             distance_m: np.ndarray) -> np.ndarray:
    """The distance matrix with missing entries completed by shortest paths (DMC-SPL).

    Known pairs keep their fused distance (the paper); only missing entries take the shortest
    path length.

    Returns a dense symmetric ``(n, n)`` array of distances (zero diagonal, ``inf`` where no
    path exists).

    Parameters
    ----------
    n : int
        Number of vertices.
    first, second : arrays of shape (P,)
        Edges (dense indices).
    distance_m : array of shape (P,)
        Edge lengths (distances, not squared).
    """
    if n <= DENSE_PATHS_MAX:
        first = np.asarray(first, np.int64)
        second = np.asarray(second, np.int64)
        if first.size and (first.min() < 0 or max(first.max(), second.max()) >= n):
            raise ConfigError(f"shortest_path_completion: vertex index out of range 0..{n - 1}")
        w = np.full((n, n), np.inf)
        d = np.maximum(np.asarray(distance_m, float), _MIN_EDGE_M)
        w[first, second] = d
        w[second, first] = d
        # handed over masked (the non-edges: inf, and NaN as scipy's dense conversion takes
        # it): that conversion finds its null entries with ``masked_values``, a third of
        # this call at n = 50
        full = floyd_warshall(np.ma.MaskedArray(w, mask=~np.isfinite(w)), directed=True,
                              overwrite=True)
    else:
        # the graph is stored symmetric, so the directed search gives the undirected answer
        # without csgraph symmetrising it again (about a quarter faster)
        full = shortest_path(edge_graph(n, first, second, distance_m), method="D",
                             directed=True)
        d = np.maximum(np.asarray(distance_m, float), _MIN_EDGE_M)
    if len(first):
        full[first, second] = d
        full[second, first] = d
    return full


def pivot_shortest_paths(n: int, first: np.ndarray, second: np.ndarray,
                         distance_m: np.ndarray, n_pivots: int) -> tuple[np.ndarray, np.ndarray]:
    """Shortest path lengths from a spread-out set of pivots only (for landmark MDS).

    Pivots are chosen by farthest-point sampling on the graph: the first is the vertex with
    the largest summed length of its known pairs, each next one the vertex farthest (in path
    length) from the pivots so far. ``n_pivots`` single-source Dijkstra searches instead of
    ``n``. The graph must be connected.

    Returns
    -------
    pivots : ndarray of shape (m,), int64
    rows : ndarray of shape (m, n)
        Path lengths from each pivot to every vertex.
    """
    g = edge_graph(n, first, second, distance_m)
    m = min(int(n_pivots), n)
    strength = np.bincount(first, distance_m, n) + np.bincount(second, distance_m, n)
    pivots = np.zeros(m, np.int64)
    rows = np.zeros((m, n))
    pivots[0] = int(np.argmax(strength))
    nearest = np.full(n, np.inf)
    for k in range(m):                      # m single-source searches
        rows[k] = shortest_path(g, method="D", directed=True, indices=int(pivots[k]))
        np.minimum(nearest, rows[k], out=nearest)
        if k + 1 < m:
            pivots[k + 1] = int(np.argmax(nearest))
    return pivots, rows


__all__ = ["DENSE_PATHS_MAX", "edge_graph", "pivot_shortest_paths", "Component", "largest_component",
           "component_labels", "prune_low_degree", "shortest_path_completion"]
