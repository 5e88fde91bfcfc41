"""What a Levenberg-Marquardt solve of the LM mappers reports, and the pieces it is made of.

:class:`SolveReport` (honest: an LM run that gave up is never "converged"), the LM parameters
of a :class:`~baselines.bearing_graph.FactorGraphConfig` (:func:`lm_params`), the Gauss-Newton
check of a solution (:func:`gauss_newton_check`), the kept-if-lower Gauss-Newton polish of the
iSAM2 mappers (:func:`polish`), what GTSAM raises (:data:`GTSAM_ERRORS`), and the
:class:`~bomgraph.mapper.MapEstimate` of a solution (:func:`estimate_from_values`), and
:func:`solve_lm`, which puts them together; they live here so that
:mod:`baselines.lm_window` can use them without importing the mappers (:mod:`baselines.factor_graph`
re-exports them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import gtsam
import numpy as np

from bomgraph.errors import ConfigError
from bomgraph.geometry import rotation
from bomgraph.mapper import MapEstimate

from .bearing_graph import (BearingGraph, FactorGraphConfig, landmark_key, landmarks_from_values,
                            pose_key)

#: What a failing GTSAM call raises in Python: its C++ exceptions arrive as RuntimeError,
#: except one whose message is not UTF-8 (an indeterminate-system message naming a key by a
#: raw character), which pybind11 turns into UnicodeDecodeError while converting it.
GTSAM_ERRORS: tuple[type[Exception], ...] = (RuntimeError, UnicodeDecodeError)


@dataclass(frozen=True)
class SolveReport:
    """How a Levenberg-Marquardt solve went.

    ``stop`` is why the plain pass ended: ``"tolerance"`` (the error stopped decreasing),
    ``"lambda_bound"`` (no damped step decreased the error up to ``lambda_upper_bound``: LM
    gave up), ``"max_iterations"``, or ``"failed"`` (it raised). ``converged`` is True only if
    the error did not grow and either LM stopped on its tolerance or a Gauss-Newton step at the
    result predicts less than ``decrease_tol`` of further decrease; an LM run that gave up far
    from a minimum is never reported as converged, nor a result whose Gauss-Newton step is
    infinite or longer than :data:`ABSURD_STEP`. ``gn_step`` and ``predicted_decrease`` are NaN
    when no check was needed (:func:`solve_lm` with ``looks_off``).
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
                # NaN: no Gauss-Newton check was needed (solve_lm)
                "gn_step": None if math.isnan(self.gn_step) else self.gn_step,
                "predicted_decrease": (None if math.isnan(self.predicted_decrease)
                                       else self.predicted_decrease),
                "stop": self.stop, "passes": list(self.passes),
                **({"message": self.message} if self.message else {})}


#: A Gauss-Newton step longer than this (metres or radians, max-norm) at a solution means a
#: direction the measurements do not determine (e.g. a landmark sliding along its rays): such a
#: solution is never "converged". Infinite when the linear system is singular.
ABSURD_STEP = 1e3


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
    except GTSAM_ERRORS:
        return math.inf, math.inf
    zero = gtsam.VectorValues(delta)
    zero.setZero()
    v = delta.vector()
    step = float(np.max(np.abs(v))) if v.size else 0.0
    return step, float(linear.error(zero) - linear.error(delta))


def _first_line(exc: BaseException) -> str:
    """The gist of a GTSAM exception: one line, without the generic help text."""
    text = " ".join(str(exc).split())
    text = text.split(" Thrown when")[0]
    return text[:300] if text else type(exc).__name__


def polish(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, iterations: int,
           decrease_tol: float) -> tuple[gtsam.Values, float, float, float]:
    """Up to ``iterations`` Gauss-Newton steps on ``graph`` from ``values``, each kept only if
    it lowers the error; the last one computed is also the convergence check, and after a
    step predicting at most ``decrease_tol`` the polish stops. Returns ``(values, max-norm of
    the last step, the decrease its linear model predicted, graph.error(values))``; ``(values,
    inf, inf, error)`` if the linear system is singular. With ``iterations = 0`` it is only the
    check."""
    error = float(graph.error(values))
    step = decrease = math.inf
    for _ in range(max(iterations, 1)):
        try:
            linear = graph.linearize(values)
            delta = linear.optimize()
        except GTSAM_ERRORS:
            return values, math.inf, math.inf, error
        v = delta.vector()
        step = float(np.max(np.abs(v))) if v.size else 0.0
        zero = gtsam.VectorValues(delta)
        zero.setZero()
        decrease = float(linear.error(zero) - linear.error(delta))
        if iterations == 0 or not (math.isfinite(step) and math.isfinite(decrease)):
            break
        trial = values.retract(delta)
        e = float(graph.error(trial))
        if not e < error:
            break
        values, error = trial, e
        if decrease <= decrease_tol:
            break
    return values, step, decrease, error


def solve_lm(graph: gtsam.NonlinearFactorGraph, initial: gtsam.Values,
             config: FactorGraphConfig,
             robust_graph: gtsam.NonlinearFactorGraph | None = None, *,
             looks_off: Callable[[gtsam.Values], bool] | None = None
             ) -> tuple[gtsam.Values, SolveReport]:
    """Levenberg-Marquardt on ``graph`` from ``initial``, with a robust pass if called for.

    Without ``looks_off`` (the default): the Huber pass on ``robust_graph`` (if given) runs
    first, the plain pass from its result, and a Gauss-Newton check of the result follows
    (:func:`gauss_newton_check`). With ``looks_off(values)`` (True when a solution's residuals
    or geometry are implausible): the plain pass runs first; only if ``looks_off`` says so of
    its result does the Huber pass run (from ``initial``, then a plain pass from there: the
    lower plain error is kept) and the Gauss-Newton check; an LM run that did not stop on its
    tolerance is checked too. A Gauss-Newton step that is infinite (a singular system) or
    predicts more than ``decrease_tol`` of decrease is never "converged". Never raises on a
    failed solve: returns the best values reached and a report saying why
    (:class:`SolveReport`).
    """
    params = lm_params(config)
    iterations = 0
    passes: list[str] = []
    messages: list[str] = []
    # id(values) -> (values, plain error): read off the optimizer where it has it; the values
    # are held so that no id is reused
    errors: dict[int, tuple[gtsam.Values, float]] = {}

    def plain_error(v: gtsam.Values) -> float:
        if id(v) not in errors:
            errors[id(v)] = (v, float(graph.error(v)))
        return errors[id(v)][1]

    def run(name: str, g: gtsam.NonlinearFactorGraph, start: gtsam.Values
            ) -> tuple[gtsam.Values, str] | None:
        nonlocal iterations
        try:
            opt = gtsam.LevenbergMarquardtOptimizer(g, start, params)
            if g is graph:
                errors.setdefault(id(start), (start, float(opt.error())))
            result = opt.optimize()
        except GTSAM_ERRORS as exc:
            messages.append(f"{name} pass failed: {_first_line(exc)}")
            return None
        if g is graph:
            errors[id(result)] = (result, float(opt.error()))
        n_it = int(opt.iterations())
        iterations += n_it
        passes.append(name)
        stop = ("max_iterations" if n_it >= config.max_iterations else
                "lambda_bound" if float(opt.lambda_()) >= config.lambda_upper_bound else
                "tolerance")
        return result, stop

    def robust_then_plain(start: gtsam.Values) -> tuple[gtsam.Values, str] | None:
        assert robust_graph is not None
        got = run("huber", robust_graph, start)
        if got is not None and plain_error(got[0]) <= plain_error(start):
            start = got[0]
        return run("plain", graph, start)

    best: tuple[gtsam.Values, str] | None
    if looks_off is None:
        best = robust_then_plain(initial) if robust_graph is not None else \
            run("plain", graph, initial)
        check = True
    else:
        best = run("plain", graph, initial)
        off = best is None or looks_off(best[0])
        if off and robust_graph is not None:
            other = robust_then_plain(initial)
            if other is not None and (best is None
                                      or plain_error(other[0]) < plain_error(best[0])):
                best = other
        check = off or best is None or best[1] != "tolerance"
    e0 = plain_error(initial)
    values, stop = best if best is not None else (initial, "failed")
    e1 = plain_error(values)
    step, decrease = gauss_newton_check(graph, values) if check else (math.nan, math.nan)
    gn_ok = not check or (step <= ABSURD_STEP and (stop == "tolerance"
                                                   or decrease <= config.decrease_tol))
    converged = bool(stop != "failed" and math.isfinite(e1)
                     and e1 <= e0 * (1 + 1e-12) + 1e-12 and gn_ok)
    if not converged and not messages:
        messages.append(
            f"LM stopped on {stop}; " + (
                "the linear system at the result is singular (a direction the measurements "
                "do not determine)" if not math.isfinite(step) else
                f"a Gauss-Newton step at the result has max-norm {step:.3g} and would still "
                f"lower the error by {decrease:.3g} (decrease_tol {config.decrease_tol:g})"))
    return values, SolveReport(converged, iterations, e0, e1, step, decrease, stop,
                               tuple(passes), "; ".join(messages))


def all_poses(values: gtsam.Values, n: int) -> np.ndarray:
    """The robot poses ``x_0 .. x_{n-1}`` of ``values``, shape (n, 3), in one call.

    ``gtsam.utilities.extractPose2`` returns every ``Pose2`` in key order: the intermediate
    poses ``m_t`` (symbol ``m``) first, then ``x_t`` (symbol ``x``, the last symbol used).
    """
    if n == 0:
        return np.zeros((0, 3))
    p = np.asarray(gtsam.utilities.extractPose2(values)).reshape(-1, 3)
    if len(p) < n:
        raise ConfigError(f"the values hold {len(p)} poses, fewer than the {n} steps")
    return p[len(p) - n:]


def marginal_covariances(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values,
                         pose_t: np.ndarray, landmark_ids: np.ndarray
                         ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Marginal covariances ``(n, 2, 2)`` of the landmarks and ``(m, 3, 3)`` of the poses at
    ``pose_t``, or ``(None, None)`` if singular; all in the world frame, as a ``MapEstimate``
    holds them (poses over ``(x_m, y_m, psi_rad)``, the order of ``MapEstimate.poses``).

    ``gtsam.Marginals`` gives a ``Pose2``'s covariance in its tangent space at the pose, whose
    translation axes are the robot's own (GTSAM retracts as ``T * Exp(d)``); to first order a
    body-frame perturbation ``(d_x, d_y, d_psi)`` moves the pose by ``(R(psi) [d_x, d_y],
    d_psi)`` in the world, so each is turned by ``J = diag(R(psi), 1)``: ``J P J^T``. A
    ``Point2``'s tangent space is the world's.
    """
    try:
        marg = gtsam.Marginals(graph, values)
        lc = np.array([marg.marginalCovariance(landmark_key(int(i))) for i in landmark_ids])
        pc = np.array([marg.marginalCovariance(pose_key(int(t))) for t in pose_t])
    except GTSAM_ERRORS:
        return None, None
    pc = pc.reshape(-1, 3, 3)
    if len(pc):
        psi = np.array([values.atPose2(pose_key(int(t))).theta() for t in pose_t])
        turn = np.zeros_like(pc)
        turn[:, :2, :2] = rotation(psi)
        turn[:, 2, 2] = 1.0
        pc = turn @ pc @ turn.transpose(0, 2, 1)
        pc = 0.5 * (pc + pc.transpose(0, 2, 1))
    return lc.reshape(-1, 2, 2), pc


def estimate_from_values(graph: BearingGraph, values: gtsam.Values,
                         solved: gtsam.NonlinearFactorGraph, info: dict[str, Any],
                         covariances: bool) -> MapEstimate:
    """The MapEstimate of a solution: every pose, the landmarks in the graph (sorted by id),
    ``info`` plus the graph's counts, and marginal covariances of ``solved`` if asked."""
    ids = np.array(sorted(graph.landmark_ids), dtype=np.int64)
    pose_t = np.arange(graph.n_steps, dtype=np.int64)
    poses = all_poses(values, graph.n_steps)
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


__all__ = ["GTSAM_ERRORS", "ABSURD_STEP", "SolveReport", "lm_params", "solve_lm",
           "gauss_newton_check", "polish", "all_poses", "marginal_covariances",
           "estimate_from_values"]
