"""Coordinates from the known pairs (paper section III-D): the pure step of every estimate.

Given the fused pairs of nodes (landmarks ``0 .. n_landmarks-1``, then any robot positions,
eq. 7) :func:`reconstruct` keeps the nodes with ``min_degree`` triangulated distances (the
3-core: a point in the plane needs three) in the largest connected piece, and maps them:

* Method 1 (``method="cs"``): DMC-SPL (shortest paths on distances, III-D.1) + classical
  scaling.
* Method 2 (``method="smacof"``): Method 1 while ``t < smacof_from_t``, weighted SMACOF
  (III-D.2, eq. 6) on the known pairs from then on, warm-started from the previous map the
  caller kept (:class:`.mapper.StmdsMapper` keeps one every ``WARM_EVERY`` steps; nodes new
  to it placed by the classical-scaling map aligned onto it) and, every
  ``smacof_restart_every`` kept SMACOF maps (every map in the recording settings), also from
  the classical-scaling map, keeping the lower weighted stress; with ``smacof_keep=2`` the
  runner-up of the previous map's starts is a further start (a beam of two local minima: a
  greedy choice at each map alone can lose the basin that is lowest later). Large maps start
  from landmark MDS (pivot shortest paths) instead.

No state is kept here: the previous map(s) and the number of SMACOF estimates made so far come
in as arguments and the caller keeps what comes out.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from ..evaluate import align
from .completion import (Component, largest_component, pivot_shortest_paths, prune_low_degree,
                         shortest_path_completion)
from .config import StmdsConfig
from .mds import LaplacianSolver, classical_scaling, landmark_scaling, smacof, stress1

@dataclass(frozen=True, eq=False)
class Reconstruction:
    """The mapped nodes of one estimate.

    Attributes
    ----------
    nodes : ndarray of shape (n,), int64
        Node indices mapped (landmarks ``< n_landmarks``, robot positions after them).
    points_xy : ndarray of shape (n, 2)
        Their coordinates (metres, an arbitrary frame: MDS fixes the shape, not the pose).
    left_out : ndarray of shape (m,), int64
        Nodes with known pairs that were not mapped (outside the core or the largest piece).
    used_smacof : bool
        SMACOF ran (the caller counts these for ``smacof_restart_every``).
    info : dict
        ``n_components``, ``n_mapped_pairs``, ``reconstruction``, SMACOF's iterations, start
        and starts tried (``smacof_start_stress1``: the Stress-1 each start reached),
        ``stress1``; or ``reason`` when nothing could be mapped.
    runner_up_xy : ndarray of shape (n, 2) or None
        With ``smacof_keep=2``: the SMACOF result of the start with the second-lowest stress
        (the next map starts from it too).
    """

    nodes: np.ndarray
    points_xy: np.ndarray
    left_out: np.ndarray
    used_smacof: bool = False
    info: dict[str, Any] = field(default_factory=dict)
    runner_up_xy: np.ndarray | None = None

    def landmark_maps(self, n_landmarks: int) -> tuple[np.ndarray, ...]:
        """The map and the runner-up (if kept) by landmark index (``(n_landmarks, 2)``, NaN
        where not mapped): the next map's SMACOF starts."""
        is_lm = self.nodes < n_landmarks
        maps = []
        for xy in (self.points_xy, self.runner_up_xy):
            if xy is not None:
                out = np.full((n_landmarks, 2), np.nan)
                out[self.nodes[is_lm]] = xy[is_lm]
                maps.append(out)
        return tuple(maps)


def _empty(reason: str, left_out: np.ndarray | None = None) -> Reconstruction:
    return Reconstruction(np.zeros(0, np.int64), np.zeros((0, 2)),
                          np.zeros(0, np.int64) if left_out is None else left_out,
                          info={"reason": reason})


def reconstruct(config: StmdsConfig, n_nodes: int, n_landmarks: int, first: np.ndarray,
                second: np.ndarray, distance_m: np.ndarray, variance_m2: np.ndarray,
                measured: np.ndarray, triangulated: np.ndarray, *, t: int,
                n_smacof: int, previous_maps: Sequence[np.ndarray]) -> Reconstruction:
    """Map the known pairs.

    Parameters
    ----------
    config : StmdsConfig
    n_nodes, n_landmarks : int
        Nodes in all (landmarks first) and landmarks.
    first, second : int arrays of shape (P,)
        The nodes of each known pair.
    distance_m, variance_m2 : arrays of shape (P,)
        Fused distances and their variances.
    measured : bool array of shape (P,)
        The pair has triangulated estimates (not a prior alone).
    triangulated : bool array
        By landmark index: the landmark ever passed the triangulation gates (may be shorter or
        longer than ``n_landmarks``).
    t : int
        The current step (Method 2 uses SMACOF from ``config.smacof_from_t``).
    n_smacof : int
        SMACOF estimates made before this one.
    previous_maps : sequence of arrays of shape (n_prev, 2)
        SMACOF's warm starts by landmark index, NaN where absent: the previous kept map and,
        with ``smacof_keep=2``, the runner-up of that map's starts (:meth:`Reconstruction.
        landmark_maps`); empty for none.
    """
    cfg = config
    n_lm = n_landmarks
    if len(first) == 0:
        return _empty("no known pair of landmarks yet")
    if not cfg.map_unobserved:
        seen = np.ones(n_nodes, bool)
        seen[:n_lm] = False
        m_seen = min(len(triangulated), n_lm)
        seen[:m_seen] = triangulated[:m_seen]
        if not seen.all():
            first, second, distance_m, variance_m2, measured = _select(
                seen[first] & seen[second], first, second, distance_m, variance_m2, measured)
        # which landmarks are mapped is decided by triangulated distances alone; priors
        # then constrain the mapped ones (a landmark held only by priors is left out)
        touched = prune_low_degree(n_nodes, *_select(measured, first, second),
                                   cfg.min_degree)
    else:
        touched = prune_low_degree(n_nodes, first, second, cfg.min_degree)
    dist, var = distance_m, variance_m2
    if not touched.all():
        first, second, dist, var = _select(touched[first] & touched[second], first, second,
                                           dist, var)
    if len(first) == 0:
        return _empty(f"no landmarks with {cfg.min_degree} known distances yet")
    nodes = np.flatnonzero(touched)
    if len(nodes) == n_nodes:                  # every node kept: local indices are the nodes
        lf, ls = first, second
    else:
        local = np.full(n_nodes, -1, np.int64)
        local[nodes] = np.arange(len(nodes))
        lf, ls = local[first], local[second]
    # the component with the most landmarks (robot positions do not count)
    comp = largest_component(len(nodes), lf, ls, (nodes < n_lm).astype(float))
    kept_nodes, ef, es, ed, ev = _restrict(comp, nodes, lf, ls, dist, var)
    n = len(kept_nodes)
    left = np.concatenate([nodes[comp.left_out], np.flatnonzero(~touched)])
    info: dict[str, Any] = {"n_components": comp.n_components, "n_mapped_pairs": len(ef)}

    use_smacof = cfg.method == "smacof" and t >= cfg.smacof_from_t and n >= 2
    w = np.ones(len(ed)) if cfg.weights == "binary" else _inverse_variance(ev)
    warms: list[np.ndarray] = []
    if use_smacof and cfg.smacof_init != "classical":
        for prev in previous_maps:
            warm = _previous_positions(prev, kept_nodes)
            if warm is not None:
                warms.append(warm)
    restart = (use_smacof and cfg.smacof_init == "best"
               and n_smacof % cfg.smacof_restart_every == 0)
    xy_cs = None
    if not use_smacof or cfg.smacof_init == "classical" or restart or not warms \
            or not all(np.isfinite(warm).all() for warm in warms):
        if use_smacof and n > cfg.landmark_mds_above:
            # only a starting point for SMACOF: landmark MDS on pivot shortest paths
            pivots, rows = pivot_shortest_paths(n, ef, es, ed, cfg.n_pivots)
            xy_cs = landmark_scaling(rows, pivots)
            info["init_completion"] = f"landmark MDS, {len(pivots)} pivots"
        else:
            full = shortest_path_completion(n, ef, es, ed)
            xy_cs, _ = classical_scaling(full * full)
        warms = [warm if np.isfinite(warm).all() else _complete_warm_start(warm, xy_cs)
                 for warm in warms]
    xy = xy_cs
    runner_up = None
    info["reconstruction"] = "classical-scaling"
    if use_smacof:
        inits = list(zip(("previous", "runner-up"), warms))
        if xy_cs is not None and (restart or not inits):
            inits.append(("classical", xy_cs))
        solver = LaplacianSolver(n, ef, es, w)
        results = []
        for name, init in inits:
            res = smacof(n, ef, es, ed, init=init, weights=w, max_iter=cfg.smacof_max_iter,
                         tol=cfg.smacof_tol, relaxation=cfg.smacof_relaxation, solver=solver)
            results.append((name, res))
        # the lowest weighted stress first (stable: a tie keeps the earlier start)
        results.sort(key=lambda r: r[1].raw_stress)
        name, best = results[0]
        xy = best.points
        if cfg.smacof_keep >= 2 and len(results) >= 2:
            runner_up = results[1][1].points
        info.update(reconstruction="smacof", smacof_iterations=best.n_iter,
                    smacof_converged=best.converged, smacof_init=name,
                    smacof_starts=[name for name, _ in inits],
                    smacof_start_stress1={name: res.stress1 for name, res in results})
    assert xy is not None
    info["stress1"] = stress1(xy, ef, es, ed, w) if len(ed) else 0.0
    return Reconstruction(kept_nodes, xy, left, use_smacof, info, runner_up)


def _select(mask: np.ndarray, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    """``arrays`` at the entries where the bool ``mask`` (shape (P,)) holds; the arrays
    themselves (not copies: nothing here writes to them) when it holds everywhere."""
    if mask.all():
        return arrays
    return tuple(a[mask] for a in arrays)


def _restrict(comp: Component, nodes: np.ndarray, first: np.ndarray, second: np.ndarray,
              dist: np.ndarray, var: np.ndarray) -> tuple[np.ndarray, ...]:
    """The kept component's nodes and its pairs renumbered ``0 .. n-1`` (``first``,
    ``second``: local indices into ``nodes``): ``(kept nodes, first, second, distances,
    variances)``; the arrays as given when the component is the whole graph."""
    if len(comp.left_out) == 0:
        return nodes, first, second, dist, var
    keep = np.zeros(len(nodes), bool)
    keep[comp.kept] = True
    sel = keep[first] & keep[second]
    renum = np.full(len(nodes), -1, np.int64)
    renum[comp.kept] = np.arange(len(comp.kept))
    return (nodes[comp.kept], renum[first[sel]], renum[second[sel]], dist[sel], var[sel])


def _inverse_variance(var: np.ndarray) -> np.ndarray:
    w = 1.0 / np.maximum(var, 1e-300)
    return w / w.mean()


def _previous_positions(previous_xy: np.ndarray, kept_nodes: np.ndarray) -> np.ndarray | None:
    """The previous map's positions of ``kept_nodes`` (NaN where it had none); None when it
    shares fewer than 3 nodes."""
    out = np.full((len(kept_nodes), 2), np.nan)
    inside = kept_nodes < len(previous_xy)
    out[inside] = previous_xy[kept_nodes[inside]]
    if np.isfinite(out[:, 0]).sum() < 3:
        return None
    return out


def _complete_warm_start(warm: np.ndarray, xy_cs: np.ndarray) -> np.ndarray:
    """Nodes new to the previous map: the classical-scaling map aligned onto it."""
    have = np.isfinite(warm[:, 0])
    al = align(xy_cs[have], warm[have], allow_reflection=True)
    out = al.apply(xy_cs)
    out[have] = warm[have]
    return out


__all__ = ["Reconstruction", "reconstruct"]
