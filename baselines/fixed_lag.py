"""Fixed-lag relinearisation of the bearing-only graph, for long recordings.

A scheduled solve of ``gtsam-batch`` / ``oracle`` / ``hybrid`` on a graph of ``T`` steps costs
``O(T)`` per Levenberg-Marquardt iteration, so solving the whole history at every checkpoint
costs ``O(T^2)`` over a recording. Past ``lag_after_steps`` steps,
:class:`baselines.factor_graph.BatchState` solves only a window instead (this module) and the
whole graph again each time it has grown by ``full_growth``, so the whole-graph solves add up to
a geometric series (``O(T)`` in all) and the cost per checkpoint is bounded by the window.

The window problem at step ``T`` with boundary ``b = T - lag_steps``:

* variables: the poses ``x_b .. x_{T-1}`` (and the intermediate ``m_t``), and the *active*
  landmarks (a bearing from a window pose, or entered since the last solve);
* ``x_b`` held at its current value by a prior with the floor sigmas; the older poses are
  constants;
* the odometry and bearing factors of the window poses, the known distances between active
  landmarks;
* for each active landmark, its bearings from the older (held) poses folded into one Gaussian
  prior: their Gauss-Newton linearisation at the current point ``l0``, information
  ``H = sum J^T J / sigma^2`` and mean ``l0 + H^-1 sum J^T r / sigma^2`` (Cauchy weights if the
  bearings are robust), which is exact to first order.

Pure functions on the state's arrays; the solve itself is :func:`baselines.factor_graph.solve_lm`.
"""

from __future__ import annotations

from typing import Sequence

import gtsam
import numpy as np

from bomgraph.angles import angle_residual
from bomgraph.geometry import bearing_offsets
from bomgraph.stream import StreamHeader

from .bearing_graph import (BearingGraph, FactorGraphConfig, bearing_noise, landmark_key,
                            mid_key, odometry_factors, pose_key, prior_factor)


def old_bearing_priors(poses: np.ndarray, points: np.ndarray, bearings_rad: np.ndarray,
                       which: np.ndarray, sigma_rad: float,
                       cauchy_k: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Newton summary of bearings on landmarks from held poses.

    Parameters
    ----------
    poses : (J, 3) the pose of each bearing; points : (n, 2) the landmarks' current points;
    bearings_rad : (J,); which : (J,) int, the landmark (0 .. n-1) of each bearing;
    sigma_rad : bearing std. dev.; cauchy_k : Cauchy threshold (whitened) or None.

    Returns
    -------
    info : (n, 2, 2) information matrices, mean : (n, 2) prior means (the current point plus
    the Gauss-Newton step; the current point where the information is singular).
    """
    n = len(points)
    pred, d, r2 = bearing_offsets(poses, points[which])
    r2 = np.maximum(r2, 1e-18)
    res = angle_residual(bearings_rad, pred) / sigma_rad
    jac = np.column_stack([-d[:, 1], d[:, 0]]) / r2[:, None] / sigma_rad       # (J, 2)
    w = np.ones_like(res) if cauchy_k is None else 1.0 / (1.0 + (res / cauchy_k) ** 2)
    info = np.zeros((n, 2, 2))
    grad = np.zeros((n, 2))
    np.add.at(info, which, w[:, None, None] * jac[:, :, None] * jac[:, None, :])
    np.add.at(grad, which, (w * res)[:, None] * jac)
    det = info[:, 0, 0] * info[:, 1, 1] - info[:, 0, 1] * info[:, 1, 0]
    tr = info[:, 0, 0] + info[:, 1, 1]
    ok = det > 1e-9 * np.maximum(tr, 1e-300) ** 2
    step = np.zeros((n, 2))
    safe = np.where(ok, det, 1.0)
    step[:, 0] = (info[:, 1, 1] * grad[:, 0] - info[:, 0, 1] * grad[:, 1]) / safe
    step[:, 1] = (info[:, 0, 0] * grad[:, 1] - info[:, 1, 0] * grad[:, 0]) / safe
    return info, points + np.where(ok[:, None], step, 0.0)


def window_problem(header: StreamHeader, config: FactorGraphConfig, problem: BearingGraph,
                   bearings: tuple[np.ndarray, np.ndarray, np.ndarray],
                   odometry_sigma: np.ndarray, poses: np.ndarray, held: gtsam.Values,
                   initial: gtsam.Values, boundary: int, fresh: Sequence[int]
                   ) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    """The fixed-lag problem (module docstring): its factors and its start.

    Parameters
    ----------
    bearings : (owner (J,), landmark id (J,), bearing (J,)), every bearing of the stream
    odometry_sigma : (T, 3) per step; poses : (T, 3) the held (current) poses
    held : the current values (every variable); initial : the start of the window variables
    boundary : the first window step ``b``; fresh : landmarks entered since the last solve
    """
    n = problem.n_steps
    owner, lid, brg = bearings
    ids = np.array(sorted(problem.landmark_ids), dtype=np.int64)
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    fm, fr = config.sigma_floor_m, config.sigma_floor_rad
    graph.add(gtsam.PriorFactorPose2(pose_key(boundary), held.atPose2(pose_key(boundary)),
                                     gtsam.noiseModel.Diagonal.Sigmas([fm, fm, fr])))
    values.insert(pose_key(boundary), initial.atPose2(pose_key(boundary)))
    for t in range(boundary + 1, n):
        for f in odometry_factors(t, problem.odoms[t], odometry_sigma[t], config):
            graph.add(f)
        values.insert(mid_key(t), initial.atPose2(mid_key(t)))
        values.insert(pose_key(t), initial.atPose2(pose_key(t)))
    if ids.size == 0 or owner.size == 0:
        return graph, values
    pos = np.clip(np.searchsorted(ids, lid), 0, ids.size - 1)
    in_graph = ids[pos] == lid
    recent = in_graph & (owner >= boundary)
    active = np.zeros(ids.size, bool)
    active[pos[recent]] = True
    active[np.isin(ids, np.asarray(list(fresh), dtype=np.int64))] = True
    act_ids = ids[active]
    for i in act_ids.tolist():
        values.insert(landmark_key(i), initial.atPoint2(landmark_key(i)))
    noise = bearing_noise(header, cauchy_k=config.bearing_cauchy_k)
    for t, i, b in zip(owner[recent].tolist(), lid[recent].tolist(), brg[recent].tolist()):
        graph.add(gtsam.BearingFactor2D(pose_key(t), landmark_key(i), gtsam.Rot2(b), noise))
    old = in_graph & (owner < boundary) & active[pos]
    if old.any():
        slot = np.searchsorted(act_ids, lid[old])
        xy = np.array([held.atPoint2(landmark_key(i)) for i in act_ids.tolist()]).reshape(-1, 2)
        info, mean = old_bearing_priors(poses[owner[old]], xy, brg[old], slot,
                                        float(header.bearing_sigma_rad),
                                        config.bearing_cauchy_k)
        for k in np.unique(slot).tolist():
            h = info[k] + (1e-12 + 1e-9 * np.trace(info[k])) * np.eye(2)
            graph.add(gtsam.PriorFactorPoint2(landmark_key(int(act_ids[k])),
                                              gtsam.Point2(*mean[k]),
                                              gtsam.noiseModel.Gaussian.Information(h)))
    act = set(act_ids.tolist())
    for p in header.priors:
        if p.i in act and p.j in act:
            graph.add(prior_factor(p))
    return graph, values


__all__ = ["window_problem", "old_bearing_priors"]
