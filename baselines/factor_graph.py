"""GTSAM bearing-only SLAM baselines: batch Levenberg-Marquardt, incremental iSAM2, the oracle.

The graph (poses, split odometry, bearings, priors, delayed landmark entry) is built by
:class:`baselines.bearing_graph.BearingGraph`; this module solves it and wraps the solvers as
mappers (the paper's section IV, Exp. 2 comparison):

* :func:`~baselines.lm_report.solve_lm` (re-exported here): Levenberg-Marquardt after an
  optional Huber pass, with an honest report (:class:`SolveReport`: an LM run that gave up is
  never "converged");
* :class:`BatchState`: the graph, the factors taken from it and the current values, which the
  LM mappers (and :class:`baselines.hybrid.HybridMapper`) hold;
* :class:`BatchMapper` (``gtsam-batch``) and :class:`OracleMapper` (``oracle``, started from the ground truth; a benchmark bound, never a
  method for real data), registered in :mod:`bomgraph.mapper`; the incremental
  ``gtsam-isam2`` lives in :mod:`baselines.isam2`.

Each factory takes ``config=`` (a :class:`FactorGraphConfig`) or ``preset=`` (``"paper"``,
``"robust"``) and field overrides, through :func:`bomgraph.config.resolve`.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, Callable, Sequence

import gtsam
import numpy as np
from scipy.spatial import cKDTree

from bomgraph.angles import angle_residual
from bomgraph.config import resolve
from bomgraph.errors import ConfigError
from bomgraph.geometry import origin_spread, pair_bearings, rotation
from bomgraph.mapper import MapEstimate
from bomgraph.stream import Step, StreamHeader, Truth

from .bearing_graph import (BearingGraph, FactorGraphConfig, NewFactors, insert_pose,
                            landmark_key, landmarks_from_values, pose_key, poses_from_values)
from .lm_report import (GTSAM_ERRORS, SolveReport, all_poses,  # noqa: F401 (re-exported)
                        estimate_from_values, gauss_newton_check, lm_params,
                        marginal_covariances, solve_lm)
from .bearing_log import BearingFactors
from .lm_window import StepChunks
from .near_range import near_bearings, near_range_of, without_factors

#: A landmark whose observing poses span less than this many bearing sigmas, seen from its
#: solved point, is beyond its rays' reach (:meth:`BatchState.out_of_reach`). Victoria Park,
#: hybrid: the runaway landmarks (1e5 to 1e9 m away) span below 1e-4 rad, every other one
#: 0.056 rad or more against a sigma of 0.05 rad (``docs/measurements.md``).
UNDETERMINED_SPAN = 0.1


# --------------------------------------------------------------------------------------------
# Batch LM
# --------------------------------------------------------------------------------------------

class BatchState:
    """What Levenberg-Marquardt solves: the growing :class:`BearingGraph` (``problem``), the
    factors moved out of it (``graph`` and, with a Huber pass, ``robust_graph``) and the
    current values (``values``: the last solution, the poses added since predicted by
    composing the odometry onto the last pose).

    It also keeps every bearing as arrays (``bearings()``), so the plausibility checks of a
    solution (:meth:`looks_off`: whitened bearing residuals, landmarks out of the sensor's
    reach) are vectorised, with no loop over factors.

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
        self.header = header
        self.problem = BearingGraph(header, config, start_pose)   # refuses a bad start_pose
        self.graph = gtsam.NonlinearFactorGraph()
        self.robust_graph = (gtsam.NonlinearFactorGraph() if config.huber_k is not None
                             else None)
        self.values = gtsam.Values()
        self._lm_config = replace(config, relative_error_tol=config.warm_relative_error_tol)
        self._last = self.problem.start_pose.copy()
        self._odom_sigma: list[np.ndarray] = []
        self._full_n = 0                  # steps at the last whole-graph solve
        self._window_b = 0                # held pose of the last solve if a window, else 0
        self.whole_only = False           # set by ScheduledSolver.finish: no window solve
        self._fresh: list[int] = []       # landmarks entered since the last solution
        self.chunks = StepChunks(header, config, keep_conditionals=True)
        self._chunk_start = 0
        # landmarks out of reach after the last whole-graph solve that ran the robust pass
        self._unreached = np.zeros(0, np.int64)
        # bearings (indices in bearings()) above robust_trigger after that pass
        self._unsettled = np.zeros(0, np.int64)
        self._factors = BearingFactors()
        self._near_m = near_range_of(header, config.near_range_m)
        # bearings (indices in bearings()) left out of the last whole-graph solve as too near
        # their landmark, and the graph that solve used (:mod:`baselines.near_range`)
        self._near = np.zeros(0, np.int64)
        self.solved_graph = self.graph

    def add_step(self, step: Step) -> None:
        """Record ``step`` and predict its pose from the previous one by the odometry."""
        self.problem.add_step(step)
        t = step.t
        prev = self._last if t > 0 else None
        pose = self.problem.predict_pose(t, prev)
        insert_pose(self.values, t, pose, prev)
        self._last = np.asarray(pose, dtype=float)
        self._odom_sigma.append(np.asarray(step.odometry_sigma(self.header), dtype=float))

    def set_values(self, values: gtsam.Values) -> None:
        """Make ``values`` the current solution (the next poses are predicted from it)."""
        self.values = values
        self._fresh = []
        n = self.problem.n_steps
        if n:
            p = values.atPose2(pose_key(n - 1))
            self._last = np.array([p.x(), p.y(), p.theta()])

    def odometry_sigmas(self) -> np.ndarray:
        """The odometry std. devs. of every step so far, (T, 3) (``Step.odometry_sigma``)."""
        return np.array(self._odom_sigma)

    def bearings(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every bearing so far: owner step, landmark id, bearing (rad), each (J,)
        (:meth:`BearingGraph.bearings`)."""
        return self.problem.bearings()

    def poses(self, ts: np.ndarray) -> np.ndarray:
        """Poses ``ts`` in the current values, shape (k, 3)."""
        return poses_from_values(self.values, ts)

    def absorb(self, pose_at: Callable[[np.ndarray], np.ndarray] | None = None) -> NewFactors:
        """Let in the landmarks now determined on the poses ``pose_at(ts)`` (the current values
        by default) and move all new factors and landmark points into ``graph`` / ``values``.
        """
        self.problem.admit(self.poses if pose_at is None else pose_at)
        new = self.problem.take_new()
        off = self.graph.size()
        self._factors.add(new.bearing_rows, off, off + new.core.size(),
                          0 if self.robust_graph is None else self.robust_graph.size())
        self.graph.push_back(new.core)
        self.graph.push_back(new.landmark)
        # after the push: the chunk (new.core) gets the entering landmarks' recent bearings
        self.chunks.add(self._chunk_start, new.core, self.problem.entered_last())
        self._chunk_start = self.problem.n_steps
        if self.robust_graph is not None and new.robust is not None:
            self.robust_graph.push_back(new.robust)
        self.values.insert(new.landmark_values)
        self._fresh += list(new.landmark_ids)
        return new

    # -- plausibility ---------------------------------------------------------------------
    def landmark_arrays(self, values: gtsam.Values) -> tuple[np.ndarray, np.ndarray]:
        """The landmarks in the graph: ids sorted (n,) and their points in ``values`` (n, 2)."""
        ids = np.array(sorted(self.problem.landmark_ids), dtype=np.int64)
        return ids, landmarks_from_values(values, ids)

    def out_of_reach(self, values: gtsam.Values) -> np.ndarray:
        """Ids of the landmarks of ``values`` that are not finite, farther than ``range_gate *
        sensor_range_m`` from every pose (with a sensor range), or beyond their rays' reach:
        the poses that saw one span less than :data:`UNDETERMINED_SPAN` bearing sigmas seen
        from it, so its rays no longer tell it from a point at infinity (LM slid it out along
        them, or behind them; with or without a sensor range)."""
        ids, xy = self.landmark_arrays(values)
        if not ids.size:
            return ids
        bad = ~np.all(np.isfinite(xy), axis=1)
        poses = all_poses(values, self.problem.n_steps)[:, :2]
        owner, lid, _ = self.bearings()
        pos, sel = _locate(ids, lid)
        span = origin_spread(xy, poses[owner[sel]], pos[sel], ids.size)
        bad |= span < UNDETERMINED_SPAN * float(self.header.bearing_sigma_rad)
        rng = self.header.sensor_range_m
        if rng is not None:
            gate = self.config.range_gate * rng
            if gate < 1e150:     # a range beyond reach (or inf/NaN): no gate
                ok = ~bad
                near = np.zeros(ids.size, bool)
                d, _ = cKDTree(poses).query(xy[ok], distance_upper_bound=gate)
                near[ok] = d <= gate
                bad |= ~near
        return ids[bad]

    def whitened_residuals(self, values: gtsam.Values) -> tuple[np.ndarray, np.ndarray]:
        """Bearing residual / sigma (signed, (k,)) at ``values`` of the bearings in the graph,
        and their indices (k,) in :meth:`bearings` (after a window solve, of the window's
        bearings only: the older ones are in its marginal or folds)."""
        owner, lid, brg = self.bearings()
        at = np.arange(owner.size)
        if self._window_b:     # a window solution: the held poses' bearings are in its prior
            at = at[owner > self._window_b]
        if self._near.size:    # left out of the solve (:meth:`without_near`)
            at = at[~np.isin(at, self._near)]
        ids, xy = self.landmark_arrays(values)
        if not ids.size or not at.size:
            return np.zeros(0), at[:0]
        pos, sel = _locate(ids, lid[at])
        at, pos = at[sel], pos[sel]
        p = all_poses(values, self.problem.n_steps)[owner[at]]
        r = angle_residual(pair_bearings(p, xy[pos], wrapped=False), brg[at])
        return r / float(self.header.bearing_sigma_rad), at

    def max_whitened_residual(self, values: gtsam.Values) -> float:
        """Largest |bearing residual| / sigma over the bearings in the graph at ``values``
        (:meth:`whitened_residuals`; 0 if none)."""
        r, _ = self.whitened_residuals(values)
        return float(np.max(np.abs(r))) if r.size else 0.0

    def looks_off(self, values: gtsam.Values) -> bool:
        """True if a solution calls for the robust pass and a Gauss-Newton check: a whitened
        bearing residual above ``robust_trigger``, or a landmark out of reach."""
        return (self.max_whitened_residual(values) > self.config.robust_trigger
                or self.out_of_reach(values).size > 0)

    def solve(self, initial: gtsam.Values, warm: bool = False, adopt: bool = False
              ) -> tuple[gtsam.Values, SolveReport]:
        """:func:`solve_lm` on ``graph`` from ``initial``: the plain pass, the Huber pass (if
        the config has one) and a Gauss-Newton check only where :meth:`looks_off`; ``values``
        is left to the caller. ``warm``: ``initial`` is the current values (the last solution
        and the odometry predictions since), whose new poses are first solved alone
        (``warm_presolve_sigma_m``, :meth:`baselines.lm_window.StepChunks.warm_solve`).

        Past ``lag_after_steps`` steps, and until the graph has grown by ``full_growth`` since
        its last whole solve, only the last ``lag_steps`` poses and the landmarks they see are
        solved (:mod:`baselines.lm_window`; the rest held at ``values``); the result is the
        current values with the window replaced and the poses eliminated into the window's
        marginal back-substituted from its solution
        (:meth:`baselines.lm_window.StepChunks.back_substitute`; else they would keep the
        values they had when eliminated, which the moved landmarks no longer fit), its report
        the window's (``info["passes"]`` starts with ``"window"``). ``adopt``: the caller makes
        the result the current values at once (:meth:`set_values`), so a window's solution is
        written into ``values`` itself, not a copy (not for a caller that compares solves).
        """
        n, cfg = self.problem.n_steps, self.config
        lm_config = self._lm_config
        overlay = None      # the warm pre-solve's solution, laid over initial
        if warm and cfg.warm_presolve_sigma_m is not None:
            overlay, its = self.chunks.warm_solve(initial, self.values,
                                                  cfg.warm_presolve_sigma_m,
                                                  cfg.warm_relative_error_tol)
            if its:
                lm_config = replace(lm_config,
                                    relative_error_tol=cfg.presolved_relative_error_tol)
        if (n > cfg.lag_after_steps and n < cfg.full_growth * self._full_n
                and not self.whole_only):
            b = self.chunks.boundary(n, cfg.lag_steps)
            if b is not None:
                return self._solve_window(initial, b, overlay, adopt)
        if overlay is not None:
            initial = gtsam.Values(initial)
            initial.update(overlay)
        self._full_n = n
        self._window_b = 0
        self.chunks.reset_folds()
        graph, robust = self.without_near()
        values, report = solve_lm(graph, initial, lm_config, robust,
                                  looks_off=self._looks_off_again, ordering=self._ordering())
        if "huber" in report.passes:
            self._unreached = self.out_of_reach(values)
            r, at = self.whitened_residuals(values)
            self._unsettled = at[np.abs(r) > cfg.robust_trigger]
        return values, report

    def without_near(self) -> tuple[gtsam.NonlinearFactorGraph,
                                     gtsam.NonlinearFactorGraph | None]:
        """The graph and robust graph of a whole-graph solve: past ``lag_after_steps`` steps,
        without the bearings whose landmark lies within the near range of their pose in the
        current values (:mod:`baselines.near_range`; their indices in :meth:`bearings` kept in
        ``_near``, the graph in ``solved_graph``). The graphs themselves where none is that
        near, and in a run's first ``lag_after_steps`` steps."""
        self._near = np.zeros(0, np.int64)
        self.solved_graph = self.graph
        if self._near_m <= 0 or self.problem.n_steps <= self.config.lag_after_steps:
            return self.graph, self.robust_graph
        owner, lid, _ = self.bearings()
        ids, xy = self.landmark_arrays(self.values)
        if not ids.size or not owner.size:
            return self.graph, self.robust_graph
        pos, sel = _locate(ids, lid)
        at = np.flatnonzero(sel)
        poses = all_poses(self.values, self.problem.n_steps)
        self._near = at[near_bearings(poses[owner[at], :2], xy[pos[at]], self._near_m)]
        if not self._near.size:
            return self.graph, self.robust_graph
        g, r = self._factors.find(owner[self._near], lid[self._near])
        self.solved_graph = without_factors(self.graph, g)
        return self.solved_graph, (None if self.robust_graph is None
                                   else without_factors(self.robust_graph, r[r >= 0]))

    def with_near_bearings(self) -> tuple[gtsam.Values, SolveReport]:
        """Levenberg-Marquardt on the whole graph, every bearing in, from the current values
        (a whole-graph solution without the near bearings, :meth:`without_near`): plain LM,
        a Gauss-Newton check if it does not stop on its tolerance (:func:`solve_lm`). If it
        converged its solution becomes the current values and no bearing is left out any
        more; otherwise nothing changes. Returns its solution and report."""
        values, report = solve_lm(self.graph, self.values, self._lm_config,
                                  looks_off=never_off, ordering=self._ordering())
        if report.converged:
            self._near = np.zeros(0, np.int64)
            self.solved_graph = self.graph
            self.set_values(values)
        return values, report

    def _ordering(self) -> str:
        """The elimination ordering of a whole-graph solve (a name of
        :data:`baselines.lm_report.ORDERINGS`): past
        ``lag_after_steps`` steps ``config.long_ordering`` (METIS by default: a long run's
        graph is large and closes loops), before it COLAMD (the paper runs)."""
        return (self.config.long_ordering
                if self.problem.n_steps > self.config.lag_after_steps else "colamd")

    def _looks_off_again(self, values: gtsam.Values) -> bool:
        """:meth:`looks_off` for a whole-graph solve, except that what the last robust pass
        left as it was does not call for another: landmarks still out of reach that were out
        of reach after it (a landmark placed beyond reach stays there through every Huber
        pass), and bearings whose whitened residual is still above ``robust_trigger`` that
        were above it after it (in practice a landmark a few mm from a pose that saw it, whose
        bearing from there flips by ~180 degrees with a sub-mm move: ``docs/measurements.md``).
        Each pass costs as much as the solve; a cause it did not change is no reason to run it
        again, and a new cause still calls for one."""
        r, at = self.whitened_residuals(values)
        if np.any(np.abs(r[~np.isin(at, self._unsettled)]) > self.config.robust_trigger):
            return True
        return np.setdiff1d(self.out_of_reach(values), self._unreached).size > 0

    def _solve_window(self, initial: gtsam.Values, b: int, overlay: gtsam.Values | None,
                      adopt: bool) -> tuple[gtsam.Values, SolveReport]:
        n = self.problem.n_steps
        self._window_b = b
        self.solved_graph = self.graph      # covariances and counts: the whole graph
        ids = np.array(sorted(self.problem.landmark_ids), dtype=np.int64)
        graph, start = self.chunks.window(b, n, initial, self.values, self.poses,
                                          self.bearings(), ids, self._fresh, overlay)
        # the window's own LM report tells convergence; a check only if it did not stop
        # on its tolerance
        window, report = solve_lm(graph, start, self._lm_config, looks_off=never_off)
        values = self.values if adopt else gtsam.Values(self.values)
        values.update(window)
        values.update(self.chunks.back_substitute(values))
        return values, replace(report, passes=("window",) + report.passes)

    def estimate_of(self, values: gtsam.Values, report: SolveReport
                    ) -> Callable[[], MapEstimate]:
        """A function making the MapEstimate of the solution ``values`` (:meth:`to_estimate`,
        the landmarks out of reach left out), for :class:`ScheduledSolver`, which calls it
        only before the next step (so it sees the graph ``values`` solved)."""
        return lambda: self.to_estimate(values, report.as_info(), self.out_of_reach(values))

    def to_estimate(self, values: gtsam.Values, info: dict[str, Any],
                    leave_out: np.ndarray | None = None) -> MapEstimate:
        """The MapEstimate of ``values`` (:func:`estimate_from_values`), without the landmarks
        ``leave_out`` (recorded in ``info["out_of_reach"]``)."""
        if self._near.size:
            info = {**info, "near_bearings_left_out": int(self._near.size)}
        if self.chunks.marginal_failure:
            info = {**info, "window_marginal_failure": self.chunks.marginal_failure}
        est = estimate_from_values(self.problem, values, self.solved_graph, info,
                                   self.config.covariances)
        if leave_out is not None and leave_out.size:
            keep = ~np.isin(est.landmark_ids, leave_out)
            est = replace(est, landmark_ids=est.landmark_ids[keep],
                          landmarks_xy=est.landmarks_xy[keep],
                          landmark_cov=None if est.landmark_cov is None
                          else est.landmark_cov[keep],
                          info={**est.info, "out_of_reach": leave_out.tolist()})
        return est


def _locate(ids: np.ndarray, lid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where each of ``lid`` (k,) sits in the sorted, non-empty ``ids`` (n,), and whether it is
    there at all: ``(positions (k,), present (k,) bool)``."""
    pos = np.clip(np.searchsorted(ids, lid), 0, ids.size - 1)
    return pos, ids[pos] == lid


def never_off(values: gtsam.Values) -> bool:
    """A ``looks_off`` for :func:`solve_lm` that never says a solution looks off: the plain
    pass only (no Huber pass), a Gauss-Newton check only if LM did not stop on its tolerance."""
    return False


class ScheduledSolver:
    """The internal schedule of the LM mappers (issue 15: the map must not depend on how often
    the caller asks for it).

    ``step()`` feeds the step (:meth:`_feed`) and, every ``config.solve_every`` steps, admits
    landmarks and solves (:meth:`_update`, which returns the new :class:`MapEstimate`, or a
    function making it that runs only if the estimate is asked for).
    ``estimate()`` returns the estimate of the last update if it is of the current step, else
    catches up with one update now. Called every 10 steps (the paper) it therefore adds no
    solve; called only at the end it gets the same map as at the scheduled steps.
    ``finish()`` (called by :func:`bomgraph.mapper.run` after the last step) makes a long
    run's final map the whole graph's minimum (:meth:`finish`).
    """

    config: FactorGraphConfig
    state: BatchState
    _estimate: MapEstimate | Callable[[], MapEstimate] | None = None
    _estimate_n: int = -1
    _finished_n: int = -1

    def _feed(self, step: Step) -> None:
        self.state.add_step(step)

    def _update(self) -> MapEstimate | Callable[[], MapEstimate]:
        raise NotImplementedError

    def step(self, step: Step) -> None:
        self._feed(step)
        if step.t > 0 and step.t % self.config.solve_every == 0:
            self._refresh()

    def _refresh(self) -> None:
        self._estimate = self._update()
        self._estimate_n = self.state.problem.n_steps

    def finish(self) -> None:
        """The stream has ended (:func:`bomgraph.mapper.run` calls this after the last step).

        Past ``lag_after_steps`` the last solve was most likely a window's
        (:meth:`BatchState.solve`), whose older poses and landmarks are only back-substituted,
        and every whole-graph solve there leaves out the near bearings
        (:meth:`BatchState.without_near`). So the whole graph is solved once more, then, if
        bearings were left out, solved again from that solution with them back in
        (:meth:`BatchState.with_near_bearings`): the final map is the minimum of the whole
        graph with every bearing (``info["near_bearings_back"]``, the number put back). If
        that last solve does not converge the map stays the one without them and
        ``info["near_bearings_back"]`` says why. Before ``lag_after_steps``: nothing
        (:meth:`estimate` catches up; the paper runs are unchanged)."""
        state = self.state
        n = state.problem.n_steps
        if n <= self.config.lag_after_steps or self._finished_n == n:
            return
        if not (self._estimate_n == n and state._full_n == n and not state._window_b):
            state.whole_only = True
            try:
                self._refresh()
            finally:
                state.whole_only = False
        est = self.estimate()
        self._finished_n = n
        left_out = int(state._near.size)
        if not left_out:
            return
        values, report = state.with_near_bearings()
        if not report.converged:
            self._estimate = replace(est, info={
                **est.info, "near_bearings_back": f"not put back ({left_out}): the solve with "
                f"them did not converge ({report.message or report.stop})"})
            return
        info = {**est.info, **report.as_info(), "near_bearings_back": left_out}
        info.pop("near_bearings_left_out", None)
        info.pop("out_of_reach", None)   # to_estimate says it anew, for these values
        self._estimate = state.to_estimate(values, info, state.out_of_reach(values))

    def estimate(self) -> MapEstimate:
        if self.state.problem.n_steps == 0:
            return MapEstimate.empty(reason="no steps yet")
        if self._estimate is None or self._estimate_n != self.state.problem.n_steps:
            self._refresh()
        if callable(self._estimate):
            self._estimate = self._estimate()
        assert self._estimate is not None
        return self._estimate


class BatchMapper(ScheduledSolver):
    """``gtsam-batch``: Levenberg-Marquardt on the whole graph every ``solve_every`` steps.

    Warm-started from the previous solution; poses added since then are predicted by
    composing the odometry onto the last solved pose. A Huber pass on the bearings
    (``huber_k``) runs only when the plain solution :meth:`~BatchState.looks_off`; landmarks
    out of the sensor's reach of every pose are left out of the map (``info["out_of_reach"]``).

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

    def _update(self) -> Callable[[], MapEstimate]:
        self.state.absorb()
        values, report = self.state.solve(self.state.values, warm=True, adopt=True)
        self.state.set_values(values)
        return self.state.estimate_of(values, report)


class OracleMapper(ScheduledSolver):
    """``oracle``: LM started from the ground truth every ``solve_every`` steps (benchmarks
    only).

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
        s = self.state.problem.start_pose
        r = rotation(s[2] - p0[2])
        self._true_poses = np.column_stack([(truth.poses[:, :2] - p0[:2]) @ r.T + s[:2],
                                            truth.poses[:, 2] - p0[2] + s[2]])
        self._true_xy = {int(i): (xy - p0[:2]) @ r.T + s[:2]
                         for i, xy in zip(truth.landmark_ids, truth.landmarks_xy)}
        self._truth_values = gtsam.Values()

    def _feed(self, step: Step) -> None:
        t = step.t
        if t >= len(self._true_poses):
            raise ConfigError(f"the truth has {len(self._true_poses)} poses; step {t} "
                              f"has none")
        self.state.add_step(step)
        insert_pose(self._truth_values, t, self._true_poses[t],
                    self._true_poses[t - 1] if t else None)

    def _true_pose_at(self, ts: np.ndarray) -> np.ndarray:
        return self._true_poses[np.asarray(ts, dtype=np.int64)]

    def initial_values(self) -> gtsam.Values:
        """The truth in the map frame (landmarks without truth at their ray intersection)."""
        v = gtsam.Values(self._truth_values)
        for lid in self.state.problem.landmark_ids:
            xy = self._true_xy.get(lid)
            if xy is None:
                xy = self.state.values.atPoint2(landmark_key(lid))
            v.insert(landmark_key(lid), gtsam.Point2(float(xy[0]), float(xy[1])))
        return v

    def _update(self) -> Callable[[], MapEstimate]:
        self.state.absorb(self._true_pose_at)
        values, report = self.state.solve(self.initial_values(), adopt=True)
        self.state.set_values(values)
        return self.state.estimate_of(values, report)


__all__ = ["FactorGraphConfig", "SolveReport", "BatchState", "ScheduledSolver", "BatchMapper",
           "OracleMapper", "all_poses",
           "solve_lm", "lm_params", "gauss_newton_check", "marginal_covariances",
           "estimate_from_values", "GTSAM_ERRORS", "never_off"]
