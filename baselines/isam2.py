"""``gtsam-isam2``: the bearing-only graph of :mod:`baselines.bearing_graph` solved incrementally.

One iSAM2 update per step with only the new factors and values; a failed update is recovered
by a rebuild, and a rebuild that fails hands over to batch Levenberg-Marquardt
(:func:`baselines.factor_graph.solve_lm`). The paper's section IV, Exp. 2 comparison.
"""

from __future__ import annotations

from typing import Any, Sequence

import gtsam
import numpy as np

from bomgraph.config import resolve
from bomgraph.errors import ConfigError
from bomgraph.mapper import MapEstimate
from bomgraph.stream import Step, StreamHeader

from .bearing_graph import (BearingGraph, FactorGraphConfig, NewFactors, insert_pose,
                            pose_key)
from .factor_graph import _first_line, estimate_from_values, gauss_newton_check, solve_lm


class Isam2Mapper:
    """``gtsam-isam2``: one iSAM2 update per step with only the new factors and values.

    The new factors and values are collected in buffers, handed to ``isam.update`` and
    cleared (GTSAM's ``IMUKittiExampleGPS.py`` pattern); the whole graph is kept only to
    rebuild after a failure. If an update raises (e.g. an indeterminate linear system), the
    solver is rebuilt from the factors accepted so far and the last good estimate, the step's
    odometry and the bearings to known landmarks are applied again, and the landmarks that had
    just entered go back to the pending buffer (they retry with their next bearing); external
    factors of that update are dropped. Each event is counted in ``info``.

    iSAM2 never iterates to convergence; ``info["converged"]`` says whether a Gauss-Newton
    step on the whole graph at the current estimate would lower the error by less than
    ``decrease_tol`` (computed at each ``estimate()``; ``checkpoint_updates`` extra updates
    run before it).

    Parameters
    ----------
    header : StreamHeader
    start_pose : (x_m, y_m, psi_rad)
    config, preset, **options
        As for :class:`BatchMapper` (the ``"robust"`` preset is refused, see below).
    """

    def __init__(self, header: StreamHeader, *,
                 start_pose: Sequence[float] = (0.0, 0.0, 0.0),
                 config: FactorGraphConfig | None = None, preset: str | None = None,
                 **options: Any) -> None:
        self.config = resolve(FactorGraphConfig, config, preset, options)
        if (self.config.odometry_cauchy_k is not None
                or self.config.bearing_cauchy_k is not None):
            raise ConfigError(
                "gtsam-isam2 does not take Cauchy kernels (odometry_cauchy_k, "
                "bearing_cauchy_k): where a kernel switches off every factor of a variable, "
                "iSAM2's undamped linear solve finds the system indeterminate and so does its "
                "rebuild (measured on MRCLAM6 robots 2 and 5); use gtsam-batch, whose damped "
                "Levenberg-Marquardt copes")
        self.header = header
        self.problem = BearingGraph(header, self.config, np.asarray(start_pose, dtype=float))
        self.accepted = gtsam.NonlinearFactorGraph()   # every factor iSAM2 holds
        self.estimate_values = gtsam.Values()          # after the last good update
        self._isam = self._new_isam()
        self._external = gtsam.NonlinearFactorGraph()
        self._external_values = gtsam.Values()
        self.failures: list[str] = []
        self.rebuilds = 0
        self._batch = False  # set when iSAM2 cannot be rebuilt (see _rebuild)
        self.dropped_external = 0
        self.withdrawn: list[int] = []

    def _new_isam(self) -> gtsam.ISAM2:
        """A fresh iSAM2: Cholesky, and Powell's dogleg instead of Gauss-Newton (a trust region:
        plain Gauss-Newton diverged on early, weakly constrained landmarks)."""
        p = gtsam.ISAM2Params()
        p.setRelinearizeThreshold(self.config.relinearize_threshold)
        p.relinearizeSkip = self.config.relinearize_skip
        p.setFactorization("CHOLESKY")
        p.setOptimizationParams(gtsam.ISAM2DoglegParams())
        return gtsam.ISAM2(p)

    def add_factors(self, factors: gtsam.NonlinearFactorGraph,
                    values: gtsam.Values | None = None) -> None:
        """Queue external factors (and initial values of new variables they bring) for the
        next update, e.g. known constraints. If they make the update fail they are dropped
        and counted in ``info["dropped_external_factors"]``."""
        self._external.push_back(factors)
        if values is not None:
            self._external_values.insert(values)

    def step(self, step: Step) -> None:
        self.problem.add_step(step)
        t = step.t
        prev = (self.estimate_values.atPose2(pose_key(t - 1)) if t > 0 else None)
        prev_np = None if prev is None else np.array([prev.x(), prev.y(), prev.theta()])
        new_poses = gtsam.Values()
        insert_pose(new_poses, t, self.problem.predict_pose(t, prev_np), prev_np)
        lookup = _Lookup(self.estimate_values, new_poses)
        self.problem.admit(lookup.poses, only_fresh=True)
        new = self.problem.take_new()
        self._update(new, new_poses)

    def _update(self, new: NewFactors, new_poses: gtsam.Values) -> None:
        factors = gtsam.NonlinearFactorGraph()
        factors.push_back(new.core)
        factors.push_back(new.landmark)
        factors.push_back(self._external)
        values = gtsam.Values(new_poses)
        values.insert(new.landmark_values)
        values.insert(self._external_values)
        self._external = gtsam.NonlinearFactorGraph()
        self._external_values = gtsam.Values()
        if self._batch:  # iSAM2 could not be rebuilt: the graph is solved in batch from now on
            self.accepted.push_back(factors)
            self.estimate_values.insert(values)
            return
        try:
            self._isam.update(factors, values)
            self._accept(factors)
            return
        except RuntimeError as exc:
            self.failures.append(_first_line(exc))
        # iSAM2 is unusable after a failed update: rebuild from what it held before, then
        # apply only the odometry and bearings to known landmarks.
        if new.landmark_ids:
            self.problem.withdraw(new.landmark_ids)
            self.withdrawn.extend(new.landmark_ids)
        self.dropped_external += int(factors.size() - new.core.size() - new.landmark.size())
        if not self._rebuild(self.accepted, self.estimate_values):
            self.accepted.push_back(new.core)
            self.estimate_values.insert(new_poses)
            return
        try:
            self._isam.update(new.core, new_poses)
            self._accept(new.core)
        except RuntimeError as exc2:        # even the core fails: solve it in batch
            self.failures.append(_first_line(exc2))
            full = gtsam.NonlinearFactorGraph(self.accepted)
            full.push_back(new.core)
            start = gtsam.Values(self.estimate_values)
            start.insert(new_poses)
            values_lm, _ = solve_lm(full, start, self.config)
            self.accepted = full
            self.estimate_values = values_lm
            if self._rebuild(full, values_lm):
                self.estimate_values = self._isam.calculateEstimate()

    def _accept(self, factors: gtsam.NonlinearFactorGraph) -> None:
        self.estimate_values = self._isam.calculateEstimate()
        self.accepted.push_back(factors)

    def _rebuild(self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> bool:
        """A new iSAM2 holding ``graph`` at ``values``. If its undamped solve finds the system
        indeterminate, the graph is first solved by (damped) LM and iSAM2 started from there;
        if that fails too, the mapper goes on in batch (LM at each estimate, reported in
        ``info["mode"]``) and this returns False."""
        self.rebuilds += 1
        start = values
        for attempt in range(2):
            self._isam = self._new_isam()
            try:
                self._isam.update(graph, start)
                return True
            except RuntimeError as exc:
                self.failures.append(_first_line(exc))
            if attempt == 0:
                start, _ = solve_lm(graph, values, self.config)
        self._batch = True
        self.estimate_values = gtsam.Values(start)
        return False

    def estimate(self) -> MapEstimate:
        if self.problem.n_steps == 0:
            return MapEstimate.empty(reason="no steps yet")
        report = None
        if not self._batch:
            try:
                for _ in range(self.config.checkpoint_updates):
                    self._isam.update()
                self.estimate_values = self._isam.calculateEstimate()
            except RuntimeError as exc:
                self.failures.append(_first_line(exc))
                self._rebuild(self.accepted, self.estimate_values)
        if self._batch:
            self.estimate_values, report = solve_lm(self.accepted, self.estimate_values,
                                                    self.config)
        step, decrease = gauss_newton_check(self.accepted, self.estimate_values)
        converged = bool(decrease <= self.config.decrease_tol)
        if report is not None:
            converged = converged and report.converged
        info = {"converged": converged, "mode": "batch" if self._batch else "isam2",
                "cost": float(self.accepted.error(self.estimate_values)), "gn_step": step,
                "predicted_decrease": decrease,
                "update_failures": len(self.failures), "rebuilds": self.rebuilds,
                "withdrawn_landmarks": list(self.withdrawn),
                "dropped_external_factors": self.dropped_external}
        if self.failures:
            info["last_failure"] = self.failures[-1]
        return estimate_from_values(self.problem, self.estimate_values, self.accepted, info,
                                     self.config.covariances)


class _Lookup:
    """Pose estimates from the solver's values, the newest pose from the prediction."""

    def __init__(self, values: gtsam.Values, extra: gtsam.Values) -> None:
        self.values, self.extra = values, extra

    def poses(self, ts: np.ndarray) -> np.ndarray:
        out = np.empty((len(ts), 3))
        for k, t in enumerate(ts):
            key = pose_key(int(t))
            p = (self.values if self.values.exists(key) else self.extra).atPose2(key)
            out[k] = (p.x(), p.y(), p.theta())
        return out


__all__ = ["Isam2Mapper"]
