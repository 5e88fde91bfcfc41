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
from .graph_values import is_pose_key

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


#: The elimination orderings :func:`solve_lm` computes for its plain passes and Gauss-Newton
#: check, by name: COLAMD (GTSAM's default) and METIS (nested dissection). On the large
#: loop-closing graphs of a long run METIS leaves smaller cliques: on the 12,861-variable graph
#: of ``scripts/bench_batch_scale.py`` at 5,931 steps one elimination takes 0.55 s against
#: COLAMD's 0.99 s, for 0.26 s against 0.11 s to compute the ordering, which a solve computes
#: once for all its eliminations (``docs/measurements.md``, "METIS orderings for the long
#: mode's whole-graph solves").
ORDERINGS: dict[str, Callable[[gtsam.NonlinearFactorGraph], gtsam.Ordering]] = {
    "colamd": gtsam.Ordering.ColamdNonlinearFactorGraph,
    "metis": gtsam.Ordering.MetisNonlinearFactorGraph,
}


def lm_params(config: FactorGraphConfig) -> gtsam.LevenbergMarquardtParams:
    """GTSAM LM parameters from the config (tight tolerances, a large lambda bound)."""
    p = gtsam.LevenbergMarquardtParams()
    p.setMaxIterations(config.max_iterations)
    p.setRelativeErrorTol(config.relative_error_tol)
    p.setAbsoluteErrorTol(config.absolute_error_tol)
    p.setlambdaUpperBound(config.lambda_upper_bound)
    p.setDiagonalDamping(config.diagonal_damping)
    return p


def gauss_newton_check(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values,
                       ordering: gtsam.Ordering | None = None) -> tuple[float, float]:
    """The Gauss-Newton step at ``values``: its max-norm (metres or radians) and the decrease
    of the error (``graph.error``, i.e. chi^2 / 2) its linear model predicts; ``(inf, inf)``
    if the linear system is singular. ``ordering``: the elimination ordering, if the caller
    already has the graph's COLAMD ordering (:func:`solve_lm`: the one its LM pass used);
    without it the linear graph's own COLAMD ordering is computed, which is the same one
    (so the step is the same bit for bit)."""
    try:
        linear = graph.linearize(values)
        delta = linear.optimize() if ordering is None else linear.optimize(ordering)
    except GTSAM_ERRORS:
        return math.inf, math.inf
    zero = gtsam.VectorValues(delta)
    zero.setZero()
    v = delta.vector()
    step = float(np.max(np.abs(v))) if v.size else 0.0
    return step, float(linear.error(zero) - linear.error(delta))


def gtsam_error_line(exc: BaseException) -> str:
    """The gist of a GTSAM exception: one line, without the generic help text."""
    text = " ".join(str(exc).split())
    text = text.split(" Thrown when")[0]
    return text[:300] if text else type(exc).__name__


def plain_gaussian(graph: gtsam.NonlinearFactorGraph) -> bool:
    """Whether every factor of ``graph`` has a plain Gaussian noise model (no robust kernel, no
    constrained rows): then a linearisation's error at zero is the graph's error at the point
    of linearisation, to rounding, which :func:`polish` uses with ``gaussian=True``. A factor
    without a noise model (or an empty slot) gives False."""
    for i in range(graph.size()):
        model = getattr(graph.at(i), "noiseModel", None)
        if model is None:
            return False
        m = model()
        if not isinstance(m, gtsam.noiseModel.Gaussian) or isinstance(
                m, gtsam.noiseModel.Constrained):
            return False
    return True


def polish(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, iterations: int,
           decrease_tol: float, *, gaussian: bool = False
           ) -> tuple[gtsam.Values, float, float, float]:
    """Up to ``iterations`` Gauss-Newton steps on ``graph`` from ``values``, each kept only if
    it lowers the error; the last one computed is also the convergence check, and after a
    step predicting at most ``decrease_tol`` the polish stops. Returns ``(values, max-norm of
    the last step, the decrease its linear model predicted, graph.error(values))``; ``(values,
    inf, inf, error)`` if the linear system is singular. With ``iterations = 0`` it is only the
    check. Every step eliminates in the first linearisation's COLAMD ordering, with its
    variable index (both computed once: the graph's structure does not change between steps,
    so they are the ones each step's own ``optimize()`` would compute, and the steps are the
    same bit for bit).

    ``gaussian=True`` says that every factor is plain Gaussian (:func:`plain_gaussian`): the
    errors are then read from the linearisations the steps make anyway (a linearisation's error
    at zero, which the predicted decrease needs, is ``graph.error`` at its point to ~1e-16
    relative). A step that will be followed by another linearises at its trial point at once
    and compares that error; only the last step's trial is evaluated on the nonlinear graph.
    The steps, the values, the step norms and the predicted decreases are the same bit for
    bit; the returned error can differ in the last bits (it is ``graph.error`` when the last
    step was kept). One whole-graph error evaluation a call instead of one a step plus one."""
    n = max(iterations, 1)
    step = decrease = math.inf
    index = ordering = zero = None
    error = None if gaussian else float(graph.error(values))
    linear = None      # the linearisation at ``values`` once made
    at_zero = None     # its error at zero, once known
    for k in range(n):
        try:
            if linear is None:
                linear = graph.linearize(values)
            if index is None:
                index = gtsam.VariableIndex(linear)
                ordering = gtsam.Ordering.Colamd(index)
            delta = linear.eliminateMultifrontal(ordering, variableIndex=index).optimize()
        except GTSAM_ERRORS:
            if error is None:
                error = float(graph.error(values))
            return values, math.inf, math.inf, error
        v = delta.vector()
        step = float(np.max(np.abs(v))) if v.size else 0.0
        if zero is None:
            zero = gtsam.VectorValues(delta)
            zero.setZero()
        if at_zero is None:
            at_zero = float(linear.error(zero))
        if error is None:
            error = at_zero
        decrease = float(at_zero - linear.error(delta))
        if iterations == 0 or not (math.isfinite(step) and math.isfinite(decrease)):
            break
        trial = values.retract(delta)
        ahead = None
        if gaussian and decrease > decrease_tol and k < n - 1:
            try:
                ahead = graph.linearize(trial)
            except GTSAM_ERRORS:   # the next step's own linearisation raises again
                ahead = None
        e = float(ahead.error(zero)) if ahead is not None else float(graph.error(trial))
        if not e < error:
            break
        values, error = trial, e
        linear, at_zero = ahead, (e if ahead is not None else None)
        if decrease <= decrease_tol:
            break
    assert error is not None
    return values, step, decrease, error


def solve_lm(graph: gtsam.NonlinearFactorGraph, initial: gtsam.Values,
             config: FactorGraphConfig,
             robust_graph: gtsam.NonlinearFactorGraph | None = None, *,
             looks_off: Callable[[gtsam.Values], bool] | None = None,
             ordering: str = "colamd") -> tuple[gtsam.Values, SolveReport]:
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

    ``ordering``: the elimination ordering of the plain passes and the check, a name of
    :data:`ORDERINGS` (the robust pass orders itself, by COLAMD).
    """
    params = lm_params(config)
    order_of = ORDERINGS[ordering]
    # the plain passes and the Gauss-Newton check all eliminate ``graph``: its ordering,
    # computed once, is the one each would compute for itself (with COLAMD, GTSAM's default,
    # results the same bit for bit as without it)
    plain: list[tuple[gtsam.LevenbergMarquardtParams, gtsam.Ordering]] = []

    def plain_params() -> tuple[gtsam.LevenbergMarquardtParams, gtsam.Ordering]:
        if not plain:
            elimination = order_of(graph)
            p = lm_params(config)
            p.setOrdering(elimination)
            plain.append((p, elimination))
        return plain[0]

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
            opt = gtsam.LevenbergMarquardtOptimizer(
                g, start, plain_params()[0] if g is graph else params)
            if g is graph:
                errors.setdefault(id(start), (start, float(opt.error())))
            result = opt.optimize()
        except GTSAM_ERRORS as exc:
            messages.append(f"{name} pass failed: {gtsam_error_line(exc)}")
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
    step, decrease = (gauss_newton_check(graph, values, plain_params()[1]) if check
                      else (math.nan, math.nan))
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


#: Above this many unknowns (the graph's tangent-space dimension) the SVD of
#: :func:`marginal_covariances` is not tried (it is O(m n^2), single-threaded here: 2-3 s for
#: the 700 unknowns of a 100-step paper world, about 30 s for the 1,900 of a 300-step one):
#: the variables ``gtsam.Marginals`` raised on are then reported without a covariance.
DENSE_MARGINALS_MAX = 2000


@dataclass(frozen=True)
class MarginalCovariances:
    """World-frame marginal covariances of a solution (:func:`marginal_covariances`).

    ``landmark_cov`` ``(n, 2, 2)`` (m^2) and ``pose_cov`` ``(m, 3, 3)`` over ``(x_m, y_m,
    psi_rad)``, in the order asked for; the block of a variable whose marginal is not
    reported is all NaN and the variable is listed in ``undefined_landmarks`` /
    ``undefined_poses`` with ``reason``. ``source`` says where the blocks came from
    (``"gtsam.Marginals"``, or ``"svd"``: the SVD of the whitened Jacobian gave every block)
    and ``marginals_failed`` on how many variables ``gtsam.Marginals`` raised.
    """

    landmark_cov: np.ndarray
    pose_cov: np.ndarray
    undefined_landmarks: tuple[int, ...] = ()
    undefined_poses: tuple[int, ...] = ()
    source: str = "gtsam.Marginals"
    marginals_failed: int = 0
    reason: str = ""

    @property
    def complete(self) -> bool:
        """Whether every variable asked for has its covariance."""
        return not (self.undefined_landmarks or self.undefined_poses)

    def as_info(self) -> dict[str, Any]:
        """What ``MapEstimate.info`` says of them: ``covariances`` (True when every variable
        has one, ``"partial"`` when some do, False when none does); when some have none,
        ``covariances_undefined`` (their landmark ids and pose steps, and why); when
        ``gtsam.Marginals`` raised, ``marginals_failed`` and ``covariances_from``."""
        n_undefined = len(self.undefined_landmarks) + len(self.undefined_poses)
        total = len(self.landmark_cov) + len(self.pose_cov)
        info: dict[str, Any] = {"covariances": (True if n_undefined == 0 else
                                                False if n_undefined == total else "partial")}
        if n_undefined:
            info["covariances_undefined"] = {"landmarks": list(self.undefined_landmarks),
                                             "poses": list(self.undefined_poses),
                                             "reason": self.reason}
        if self.marginals_failed:
            info["marginals_failed"] = self.marginals_failed
            info["covariances_from"] = self.source
        return info


def _svd_marginals(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values,
                   want: list[int]) -> tuple[dict[int, np.ndarray], str] | None:
    """The tangent-space marginal covariance of each key of ``want`` from an SVD of the
    whole whitened Jacobian ``J`` at ``values``: the blocks of ``V_r diag(1/s_r^2) V_r^T``
    over the singular values above numpy's rank tolerance (``s_max * max(m, n) * eps``), i.e.
    ``(J^T J)^-1`` when ``J`` has full column rank. A key that the null space of ``J`` moves
    (a block of its basis with norm above ``sqrt(eps)``), or that no factor holds, has no
    defined marginal and is left out. Returns ``({key: block}, reason)``, the reason saying
    why keys were left out ("" if none was), or None above :data:`DENSE_MARGINALS_MAX`
    unknowns (not tried)."""
    keys = [int(k) for k in graph.keyVector()]
    dims = np.where(is_pose_key(np.array(keys, dtype=np.uint64)), 3, 2)  # Pose2, Point2
    if int(dims.sum()) > DENSE_MARGINALS_MAX:
        return None
    a, _ = graph.linearize(values).jacobian(gtsam.Ordering(keys))
    if a.shape[0] < a.shape[1]:   # zero rows, so that vt spans the null space too
        a = np.vstack([a, np.zeros((a.shape[1] - a.shape[0], a.shape[1]))])
    _, s, vt = np.linalg.svd(a, full_matrices=False)
    tol = (s[0] if s.size else 0.0) * max(a.shape) * np.finfo(float).eps
    r = int(np.sum(s > tol))
    w = vt[:r].T / s[:r]                   # V_r diag(1/s_r): the covariance is w w^T
    null = vt[r:].T
    start = dict(zip(keys, np.r_[0, np.cumsum(dims)[:-1]].tolist()))
    dim = dict(zip(keys, dims.tolist()))
    out: dict[int, np.ndarray] = {}
    for k in want:
        if k not in start:
            continue
        rows = slice(start[k], start[k] + dim[k])
        if null.shape[1] and np.linalg.norm(null[rows]) > np.sqrt(np.finfo(float).eps):
            continue
        out[k] = w[rows] @ w[rows].T
    reason = ("" if len(out) == len(want) else
              f"the whitened Jacobian at the solution has rank {r} of {a.shape[1]} and its "
              f"null space moves them (or no factor holds them): their marginal is not "
              f"defined")
    return out, reason


def marginal_covariances(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values,
                         pose_t: np.ndarray, landmark_ids: np.ndarray) -> MarginalCovariances:
    """Marginal covariances of the landmarks ``landmark_ids`` and the poses at ``pose_t``,
    in the world frame, as a ``MapEstimate`` holds them (poses over ``(x_m, y_m,
    psi_rad)``, the order of ``MapEstimate.poses``): the blocks of the Gauss-Newton
    covariance ``(J^T J)^-1`` of ``graph``'s whitened factors at ``values``.

    The blocks come from ``gtsam.Marginals`` (a Cholesky of the graph). Where it raises on
    any variable (an "indeterminate" system: a landmark micrometres from a pose that took a
    bearing of it makes that bearing's whitened Jacobian ``1 / (rho sigma)``, 10^6 and more,
    and the Cholesky of a clique holding it loses its pivots), every block is taken instead
    from an SVD of the whole whitened Jacobian (:func:`_svd_marginals`: the same matrix, and
    more accurate than the Cholesky's blocks near such a bearing, where ``J^T J`` has a
    condition number of 10^12 or more), which also tells a variable whose marginal is truly
    not defined (moved by the Jacobian's null space): that variable's block is NaN and listed
    with the reason, never filled in. Above :data:`DENSE_MARGINALS_MAX` unknowns the SVD is
    not tried: the blocks ``gtsam.Marginals`` gave are kept and the variables it raised on
    are left NaN likewise.

    ``gtsam.Marginals`` gives a ``Pose2``'s covariance in its tangent space at the pose, whose
    translation axes are the robot's own (GTSAM retracts as ``T * Exp(d)``); to first order a
    body-frame perturbation ``(d_x, d_y, d_psi)`` moves the pose by ``(R(psi) [d_x, d_y],
    d_psi)`` in the world, so each is turned by ``J = diag(R(psi), 1)``: ``J P J^T``. A
    ``Point2``'s tangent space is the world's. The SVD works in the same tangent spaces.
    """
    lkeys = [landmark_key(int(i)) for i in landmark_ids]
    pkeys = [pose_key(int(t)) for t in pose_t]
    blocks: dict[int, np.ndarray] = {}
    failed: list[int] = []
    try:
        marg = gtsam.Marginals(graph, values)
    except GTSAM_ERRORS:
        failed = lkeys + pkeys
    else:
        for k in lkeys + pkeys:
            try:
                blocks[k] = np.asarray(marg.marginalCovariance(k), dtype=float)
            except GTSAM_ERRORS:
                failed.append(k)
    reason, source = "", "gtsam.Marginals"
    if failed:
        svd = _svd_marginals(graph, values, lkeys + pkeys)
        if svd is None:
            reason = (f"gtsam.Marginals found the linear system indeterminate near them, and "
                      f"the graph has more unknowns than the SVD check's {DENSE_MARGINALS_MAX}")
        else:
            (blocks, reason), source = svd, "svd"
    lc = (np.stack([blocks.get(k, np.full((2, 2), np.nan)) for k in lkeys]) if lkeys
          else np.zeros((0, 2, 2)))
    pc = (np.stack([blocks.get(k, np.full((3, 3), np.nan)) for k in pkeys]) if pkeys
          else np.zeros((0, 3, 3)))
    if len(pc):
        psi = np.array([values.atPose2(k).theta() if values.exists(k) else 0.0
                        for k in pkeys])
        turn = np.zeros_like(pc)
        turn[:, :2, :2] = rotation(psi)
        turn[:, 2, 2] = 1.0
        pc = turn @ pc @ turn.transpose(0, 2, 1)
        pc = 0.5 * (pc + pc.transpose(0, 2, 1))
    return MarginalCovariances(
        lc, pc, tuple(int(i) for i, k in zip(landmark_ids, lkeys) if k not in blocks),
        tuple(int(t) for t, k in zip(pose_t, pkeys) if k not in blocks), source, len(failed),
        reason)


def estimate_from_values(bearing_graph: BearingGraph, values: gtsam.Values,
                         factors: gtsam.NonlinearFactorGraph,
                         info: dict[str, Any] | None = None,
                         covariances: bool = False) -> MapEstimate:
    """The MapEstimate of a solution ``values``: every pose of ``bearing_graph`` (the
    :class:`BearingGraph` that made the factors), its landmarks in the graph (sorted by id),
    ``info`` plus its counts, and, if ``covariances``, the marginal covariances of ``factors``
    (the factor graph ``values`` solves, e.g. every factor handed to iSAM2) at ``values``."""
    ids = np.array(sorted(bearing_graph.landmark_ids), dtype=np.int64)
    pose_t = np.arange(bearing_graph.n_steps, dtype=np.int64)
    poses = all_poses(values, bearing_graph.n_steps)
    xy = landmarks_from_values(values, ids)
    info = dict(info or {})
    info.update({"n_landmarks": int(ids.size), "pending": len(bearing_graph.pending()),
                 "n_bearing_factors": bearing_graph.n_bearing_factors,
                 "n_prior_factors": bearing_graph.n_prior_factors,
                 "n_factors": int(factors.size())})
    lc = pc = None
    if covariances and ids.size:
        marg = marginal_covariances(factors, values, pose_t, ids)
        info.update(marg.as_info())
        if info["covariances"] is not False:   # NaN blocks mark the undefined ones
            lc, pc = marg.landmark_cov, marg.pose_cov
    if ids.size == 0:
        info.setdefault("reason", "no landmark has two bearings with enough parallax yet")
    return MapEstimate(ids, xy, pose_t=pose_t, poses=poses, landmark_cov=lc, pose_cov=pc,
                       info=info)


__all__ = ["GTSAM_ERRORS", "ABSURD_STEP", "ORDERINGS", "DENSE_MARGINALS_MAX", "MarginalCovariances",
           "SolveReport", "lm_params", "solve_lm",
           "gauss_newton_check", "plain_gaussian", "polish", "all_poses",
           "marginal_covariances", "estimate_from_values", "gtsam_error_line"]
