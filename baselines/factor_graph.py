"""GTSAM bearing-only SLAM baselines: batch Levenberg-Marquardt, incremental iSAM2, the oracle.

The graph (poses, split odometry, bearings, priors, delayed landmark entry) is built by
:class:`baselines.bearing_graph.BearingGraph`; this module solves it and wraps the solvers as
mappers (the paper's section IV, Exp. 2 comparison):

* :func:`solve_lm`: Levenberg-Marquardt after an optional Huber pass, with an honest report
  (:class:`SolveReport`: an LM run that gave up is never "converged");
* :class:`BatchState`: the graph, the factors taken from it and the current values, which the
  LM mappers (and :class:`baselines.hybrid.HybridMapper`) hold;
* :class:`BatchMapper` (``gtsam-batch``) and :class:`OracleMapper` (``oracle``, started from the ground truth; a benchmark bound, never a
  method for real data), registered in :mod:`bomgraph.mapper`; the incremental
  ``gtsam-isam2`` lives in :mod:`baselines.isam2`.

Each factory takes ``config=`` (a :class:`FactorGraphConfig`) or ``preset=`` (``"paper"``,
``"robust"``) and field overrides, through :func:`bomgraph.config.resolve`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Callable, Sequence

import gtsam
import numpy as np

from bomgraph.config import resolve
from bomgraph.errors import ConfigError
from bomgraph.geometry import rotation
from bomgraph.mapper import MapEstimate
from bomgraph.stream import Step, StreamHeader, Truth

from .bearing_graph import (BearingGraph, FactorGraphConfig, NewFactors, insert_pose,
                            landmark_key, landmarks_from_values, pose_key, poses_from_values)

# --------------------------------------------------------------------------------------------
# Solving
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class SolveReport:
    """How a Levenberg-Marquardt solve went.

    ``stop`` is why the plain pass ended: ``"tolerance"`` (the error stopped decreasing),
    ``"lambda_bound"`` (no damped step decreased the error up to ``lambda_upper_bound``: LM
    gave up), ``"max_iterations"``, or ``"failed"`` (it raised). ``converged`` is True only if
    the error did not grow and either LM stopped on its tolerance or a Gauss-Newton step at the
    result predicts less than ``decrease_tol`` of further decrease; an LM run that gave up far
    from a minimum is never reported as converged.
    """

    converged: bool
    iterations: int
    initial_error: float
    final_error: float
    gn_step: float
    predicted_decrease: float
    stop: str
    passes: tuple[str, ...]
    message: str = ""

    def as_info(self) -> dict[str, Any]:
        return {"converged": self.converged, "iterations": self.iterations,
                "initial_cost": self.initial_error, "cost": self.final_error,
                "gn_step": self.gn_step, "predicted_decrease": self.predicted_decrease,
                "stop": self.stop, "passes": list(self.passes),
                **({"message": self.message} if self.message else {})}


def lm_params(config: FactorGraphConfig) -> gtsam.LevenbergMarquardtParams:
    """GTSAM LM parameters from the config (tight tolerances, a large lambda bound)."""
    p = gtsam.LevenbergMarquardtParams()
    p.setMaxIterations(config.max_iterations)
    p.setRelativeErrorTol(config.relative_error_tol)
    p.setAbsoluteErrorTol(config.absolute_error_tol)
    p.setlambdaUpperBound(config.lambda_upper_bound)
    p.setDiagonalDamping(config.diagonal_damping)
    return p


def gauss_newton_check(graph: gtsam.NonlinearFactorGraph,
                       values: gtsam.Values) -> tuple[float, float]:
    """The Gauss-Newton step at ``values``: its max-norm (metres or radians) and the decrease
    of the error (``graph.error``, i.e. chi^2 / 2) its linear model predicts; ``(inf, inf)``
    if the linear system is singular."""
    try:
        linear = graph.linearize(values)
        delta = linear.optimize()
    except RuntimeError:
        return math.inf, math.inf
    zero = gtsam.VectorValues(delta)
    zero.setZero()
    v = delta.vector()
    step = float(np.max(np.abs(v))) if v.size else 0.0
    return step, float(linear.error(zero) - linear.error(delta))


def solve_lm(graph: gtsam.NonlinearFactorGraph, initial: gtsam.Values,
             config: FactorGraphConfig,
             robust_graph: gtsam.NonlinearFactorGraph | None = None
             ) -> tuple[gtsam.Values, SolveReport]:
    """Levenberg-Marquardt on ``graph`` from ``initial``, after a robust pass if given.

    The robust result is kept only if it lowers the plain error. Never raises on a failed
    solve: returns the best values reached and a report saying why (:class:`SolveReport`).
    """
    params = lm_params(config)
    e0 = float(graph.error(initial))
    values = initial
    iterations = 0
    passes: list[str] = []
    message = ""
    stop = "failed"
    for name, g in (("huber", robust_graph), ("plain", graph)):
        if g is None:
            continue
        try:
            opt = gtsam.LevenbergMarquardtOptimizer(g, values, params)
            result = opt.optimize()
        except RuntimeError as exc:
            message = f"{name} pass failed: {_first_line(exc)}"
            continue
        n_it = int(opt.iterations())
        iterations += n_it
        passes.append(name)
        if name == "plain":
            values = result
            stop = ("max_iterations" if n_it >= config.max_iterations else
                    "lambda_bound" if float(opt.lambda_()) >= config.lambda_upper_bound else
                    "tolerance")
        elif float(graph.error(result)) <= float(graph.error(values)):
            values = result
    e1 = float(graph.error(values))
    step, decrease = gauss_newton_check(graph, values)
    converged = bool(stop != "failed" and math.isfinite(e1)
                     and e1 <= e0 * (1 + 1e-12) + 1e-12
                     and (stop == "tolerance" or decrease <= config.decrease_tol))
    if not converged and not message:
        message = (f"LM stopped on {stop}; a Gauss-Newton step would still lower the error by "
                   f"{decrease:.3g} (> decrease_tol {config.decrease_tol:g})")
    return values, SolveReport(converged, iterations, e0, e1, step, decrease, stop,
                               tuple(passes), message)


def marginal_covariances(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values,
                         pose_t: np.ndarray, landmark_ids: np.ndarray
                         ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Marginal covariances ``(n, 2, 2)`` of the landmarks and ``(m, 3, 3)`` of the poses
    (pose covariances in GTSAM's body frame convention), or ``(None, None)`` if singular."""
    try:
        marg = gtsam.Marginals(graph, values)
        lc = np.array([marg.marginalCovariance(landmark_key(int(i))) for i in landmark_ids])
        pc = np.array([marg.marginalCovariance(pose_key(int(t))) for t in pose_t])
    except RuntimeError:
        return None, None
    return lc.reshape(-1, 2, 2), pc.reshape(-1, 3, 3)


def _first_line(exc: BaseException) -> str:
    """The gist of a GTSAM exception: one line, without the generic help text."""
    text = " ".join(str(exc).split())
    text = text.split(" Thrown when")[0]
    return text[:300] if text else type(exc).__name__


def estimate_from_values(graph: BearingGraph, values: gtsam.Values,
                         solved: gtsam.NonlinearFactorGraph, info: dict[str, Any],
                         covariances: bool) -> MapEstimate:
    """The MapEstimate of a solution: every pose, the landmarks in the graph (sorted by id),
    ``info`` plus the graph's counts, and marginal covariances of ``solved`` if asked."""
    ids = np.array(sorted(graph.landmark_ids), dtype=np.int64)
    pose_t = np.arange(graph.n_steps, dtype=np.int64)
    poses = poses_from_values(values, pose_t)
    xy = landmarks_from_values(values, ids)
    info = dict(info)
    info.update({"n_landmarks": int(ids.size), "pending": len(graph.pending()),
                 "n_bearing_factors": graph.n_bearing_factors,
                 "n_prior_factors": graph.n_prior_factors, "n_factors": int(solved.size())})
    lc = pc = None
    if covariances and ids.size:
        lc, pc = marginal_covariances(solved, values, pose_t, ids)
        info["covariances"] = lc is not None
    if ids.size == 0:
        info.setdefault("reason", "no landmark has two bearings with enough parallax yet")
    return MapEstimate(ids, xy, pose_t=pose_t, poses=poses, landmark_cov=lc, pose_cov=pc,
                       info=info)


# --------------------------------------------------------------------------------------------
# Batch LM
# --------------------------------------------------------------------------------------------

class BatchState:
    """What Levenberg-Marquardt solves at each ``estimate()``: the growing
    :class:`BearingGraph` (``problem``), the factors moved out of it (``graph`` and, with a
    Huber pass, ``robust_graph``) and the current values (``values``: the last solution, the
    poses added since predicted by composing the odometry onto the last pose).

    Parameters
    ----------
    header : StreamHeader
    config : FactorGraphConfig
    start_pose : array of shape (3,)
        The map frame: the first pose is tied here.
    """

    def __init__(self, header: StreamHeader, config: FactorGraphConfig,
                 start_pose: Sequence[float]) -> None:
        self.config = config
        self.problem = BearingGraph(header, config, np.asarray(start_pose, dtype=float))
        self.graph = gtsam.NonlinearFactorGraph()
        self.robust_graph = (gtsam.NonlinearFactorGraph() if config.huber_k is not None
                             else None)
        self.values = gtsam.Values()

    def add_step(self, step: Step) -> None:
        """Record ``step`` and predict its pose from the previous one by the odometry."""
        self.problem.add_step(step)
        t = step.t
        prev = (poses_from_values(self.values, [t - 1])[0] if t > 0 else None)
        insert_pose(self.values, t, self.problem.predict_pose(t, prev), prev)

    def poses(self, ts: np.ndarray) -> np.ndarray:
        """Poses ``ts`` in the current values, shape (k, 3)."""
        return poses_from_values(self.values, ts)

    def absorb(self, pose_at: Callable[[np.ndarray], np.ndarray] | None = None) -> NewFactors:
        """Let in the landmarks now determined on the poses ``pose_at(ts)`` (the current values
        by default) and move all new factors and landmark points into ``graph`` / ``values``.
        """
        self.problem.admit(self.poses if pose_at is None else pose_at)
        new = self.problem.take_new()
        self.graph.push_back(new.core)
        self.graph.push_back(new.landmark)
        if self.robust_graph is not None and new.robust is not None:
            self.robust_graph.push_back(new.robust)
        self.values.insert(new.landmark_values)
        return new

    def solve(self, initial: gtsam.Values) -> tuple[gtsam.Values, SolveReport]:
        """:func:`solve_lm` on ``graph`` from ``initial`` (after the Huber pass if the config
        has one); ``values`` is left to the caller."""
        return solve_lm(self.graph, initial, self.config, self.robust_graph)

    def to_estimate(self, values: gtsam.Values, info: dict[str, Any]) -> MapEstimate:
        """The MapEstimate of ``values`` (:func:`estimate_from_values`)."""
        return estimate_from_values(self.problem, values, self.graph, info,
                                    self.config.covariances)


class BatchMapper:
    """``gtsam-batch``: Levenberg-Marquardt on the whole graph at each ``estimate()``.

    Warm-started from the previous solution; poses added since then are predicted by
    composing the odometry onto the last solved pose. A Huber pass on the bearings precedes
    the plain pass (``huber_k``).

    Parameters
    ----------
    header : StreamHeader
    start_pose : (x_m, y_m, psi_rad)
        The map frame: the first pose is tied here (the origin by default).
    config : FactorGraphConfig, optional
    preset : str, optional
        A :class:`FactorGraphConfig` preset (``"paper"``, ``"robust"``).
    **options
        Fields of :class:`FactorGraphConfig` (with ``preset``, not with ``config``).
    """

    def __init__(self, header: StreamHeader, *,
                 start_pose: Sequence[float] = (0.0, 0.0, 0.0),
                 config: FactorGraphConfig | None = None, preset: str | None = None,
                 **options: Any) -> None:
        self.config = resolve(FactorGraphConfig, config, preset, options)
        self.header = header
        self.state = BatchState(header, self.config, start_pose)

    def step(self, step: Step) -> None:
        self.state.add_step(step)

    def estimate(self) -> MapEstimate:
        if self.state.problem.n_steps == 0:
            return MapEstimate.empty(reason="no steps yet")
        self.state.absorb()
        values, report = self.state.solve(self.state.values)
        self.state.values = values
        return self.state.to_estimate(values, report.as_info())


class OracleMapper:
    """``oracle``: LM started from the ground truth at each ``estimate()`` (benchmarks only).

    The truth (poses and landmarks) is moved into the map frame (the first true pose onto
    ``start_pose``); landmarks enter by the same rule as the other mappers, judged on the true
    poses, so the graph matches theirs. The converged result is the maximum-likelihood
    estimate reached from the best possible start: the accuracy bound of the baselines. No
    Huber pass (``huber_k`` is ignored: the start needs none).

    Parameters
    ----------
    header : StreamHeader
    truth : Truth
        Must have poses.
    start_pose, config, preset, **options
        As for :class:`BatchMapper`.
    """

    def __init__(self, header: StreamHeader, *, truth: Truth,
                 start_pose: Sequence[float] = (0.0, 0.0, 0.0),
                 config: FactorGraphConfig | None = None, preset: str | None = None,
                 **options: Any) -> None:
        if truth is None or truth.poses is None:
            raise ConfigError("the oracle needs the true poses (truth.poses)")
        self.config = replace(resolve(FactorGraphConfig, config, preset, options), huber_k=None)
        self.header = header
        self.state = BatchState(header, self.config, start_pose)
        p0 = truth.poses[0]
        s = np.asarray(start_pose, dtype=float)
        r = rotation(s[2] - p0[2])
        self._true_poses = np.column_stack([(truth.poses[:, :2] - p0[:2]) @ r.T + s[:2],
                                            truth.poses[:, 2] - p0[2] + s[2]])
        self._true_xy = {int(i): (xy - p0[:2]) @ r.T + s[:2]
                         for i, xy in zip(truth.landmark_ids, truth.landmarks_xy)}

    def step(self, step: Step) -> None:
        if step.t >= len(self._true_poses):
            raise ConfigError(f"the truth has {len(self._true_poses)} poses; step {step.t} "
                              f"has none")
        self.state.add_step(step)

    def _true_pose_at(self, ts: np.ndarray) -> np.ndarray:
        return self._true_poses[np.asarray(ts, dtype=np.int64)]

    def initial_values(self) -> gtsam.Values:
        """The truth in the map frame (landmarks without truth at their ray intersection)."""
        v = gtsam.Values()
        for t in range(self.state.problem.n_steps):
            insert_pose(v, t, self._true_poses[t], self._true_poses[t - 1] if t else None)
        for lid in self.state.problem.landmark_ids:
            xy = self._true_xy.get(lid)
            if xy is None:
                xy = self.state.values.atPoint2(landmark_key(lid))
            v.insert(landmark_key(lid), gtsam.Point2(float(xy[0]), float(xy[1])))
        return v

    def estimate(self) -> MapEstimate:
        if self.state.problem.n_steps == 0:
            return MapEstimate.empty(reason="no steps yet")
        self.state.absorb(self._true_pose_at)
        values, report = self.state.solve(self.initial_values())
        self.state.values = values
        return self.state.to_estimate(values, report.as_info())


__all__ = ["FactorGraphConfig", "SolveReport", "BatchState", "BatchMapper", "OracleMapper",
           "solve_lm", "lm_params", "gauss_newton_check", "marginal_covariances",
           "estimate_from_values"]
