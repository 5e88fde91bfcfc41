"""Bearings taken from nearly on top of their landmark, left out of the long mode's solves.

A bearing seen from a pose a distance ``rho`` from its landmark changes by ``d / rho`` radians
when the pose or the landmark moves sideways by ``d``: its Jacobian grows as ``1 / rho`` and
its linearisation holds only over steps much shorter than ``rho``. In a simulated world a robot
drives through point landmarks (millimetres, at times). On a long recording the LM mappers'
whole-graph solve comes after hundreds of steps of fixed-lag windows, and a loop closure then
moves the old poses by centimetres: a step across a landmark a few mm from a pose flips that
bearing's residual by up to pi and adds about ``(pi / sigma)^2 / 2`` to the cost, LM rejects
the step, raises lambda, and crawls to a stop short of the minimum. On the 1,000-landmark world
of ``scripts/bench_scale.py`` each late whole-graph solve took 8-9 iterations of two to eight
eliminations each, stopping tens of cost units short; without the bearings under 3 cm the same
solve takes 3-5 undamped iterations (``docs/measurements.md``, "Bearings from nearly on top of
their landmark").

The rule: past ``lag_after_steps`` steps, a whole-graph solve of
:class:`baselines.factor_graph.BatchState` leaves out the bearings whose landmark lies within
``near_range_m`` of the pose that took them, at the state's current values (the last solution
and the odometry predictions since), and so do its plausibility checks (a flipped near bearing
is no evidence of an outlier). With the default (``near_range_m=None``) the range is one
odometry step's translation sigma of the stream's header, ``hypot(sigma_dx, sigma_dy)``: a
landmark nearer than that to a pose cannot be told to lie on one side of it or the other from
the odometry.

Not in a run's first ``lag_after_steps`` steps (the paper's runs): there a whole-graph solve
every ``solve_every`` steps starts within millimetres of its minimum, the near bearings are
among the best-determined of the graph, and leaving them out costs accuracy (the 25 paper runs:
the oracle's mean MPE at t = 300 1.07 -> 1.11 cm with the rule there). On the recordings
(landmarks are objects a robot cannot drive through, 0.3 m or more away; odometry sigma
1-3 cm) no bearing is that near.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np

from bomgraph.stream import StreamHeader

__all__ = ["near_range_of", "near_bearings", "without_factors"]


def near_range_of(header: StreamHeader, near_range_m: float | None) -> float:
    """The near range in metres: ``near_range_m`` if given, else the header's odometry
    translation sigma ``hypot(sigma_dx_m, sigma_dy_m)``; 0 switches the rule off."""
    if near_range_m is not None:
        return float(near_range_m)
    s = np.asarray(header.odometry_sigma, dtype=float)
    return float(math.hypot(s[0], s[1]))


def near_bearings(owner_xy: np.ndarray, landmark_xy: np.ndarray, near_m: float) -> np.ndarray:
    """Mask ``(k,)`` of the bearings whose pose ``owner_xy[k]`` (k, 2) lies within ``near_m``
    metres of its landmark ``landmark_xy[k]`` (k, 2) (a NaN point is never near)."""
    d = landmark_xy - owner_xy
    return np.hypot(d[:, 0], d[:, 1]) < near_m


def without_factors(graph: gtsam.NonlinearFactorGraph, at: np.ndarray
                    ) -> gtsam.NonlinearFactorGraph:
    """A copy of ``graph`` sharing its factors, with the factors at indices ``at`` removed
    (their slots left empty, which GTSAM's linearisation, error and ordering skip)."""
    out = gtsam.NonlinearFactorGraph(graph)
    for i in np.unique(at).tolist():
        out.remove(int(i))
    return out
