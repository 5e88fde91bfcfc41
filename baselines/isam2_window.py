"""The bounded window of ``gtsam-isam2``'s long mode (``Isam2Config.long_window``).

A mixin of :class:`baselines.isam2.Isam2Mapper` (its state: ``config``, ``problem``,
``accepted``, ``estimate_values``, ``_isam``, the window fields set in its ``__init__``):
every step's factors filed by step in a :class:`baselines.lm_window.StepChunks` (the fixed-lag
machinery of ``gtsam-batch``), iSAM2 holding only the window over the chunks' marginal of the
older steps, rebuilt when the window moves, the whole-graph polish and check each time the
graph has grown ``long_growth``x, and the older poses back-substituted from the window's
solution (:meth:`WindowLongMode.current_values`).
"""

from __future__ import annotations

import math
from typing import Any

import gtsam
import numpy as np

from bomgraph.stream import Step

from .bearing_graph import BearingLog, poses_from_values
from .lm_report import GTSAM_ERRORS, gtsam_error_line, solve_lm
from .lm_report import polish
from .lm_window import StepChunks


class WindowLongMode:
    """The window methods of :class:`baselines.isam2.Isam2Mapper` (module docstring)."""

    config: Any            # Isam2Config
    problem: Any           # BearingGraph
    accepted: gtsam.NonlinearFactorGraph
    estimate_values: gtsam.Values
    _chunks: StepChunks | None
    _gaussian: bool        # every factor plain Gaussian (lm_report.plain_gaussian)

    def _file(self, step: Step | None, core: gtsam.NonlinearFactorGraph,
              weak: gtsam.NonlinearFactorGraph, entered: list[int]) -> None:
        """File step ``step``'s factors for long mode's window (``long_window``): its core
        factors and weak landmark priors as the chunk of its step, the buffered bearings of the
        landmarks that entered in their steps' chunks (:meth:`StepChunks.add`), its bearings in
        the arrays of :meth:`_bearings`. ``step`` None: landmarks let in after the last step
        (:meth:`Isam2Mapper.finish`), filed with the last step's chunk."""
        assert self._chunks is not None
        chunk = gtsam.NonlinearFactorGraph(core)
        chunk.push_back(weak)
        t = self.problem.n_steps - 1 if step is None else step.t
        self._chunks.add(t, chunk, self.problem.entered_last())
        if step is not None:
            self._log.add(step)
        self._window_fresh += list(entered)

    def _bearings(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every bearing so far: owner step, landmark id, bearing (rad), each (J,)."""
        return self._log.arrays()

    def _update_window(self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values,
                       extra: bool) -> None:
        """One update of the window iSAM2 with the new factors and values, or a rebuild on the
        window ending now if the window is full or a factor reaches a variable iSAM2 does not
        hold; the whole-graph polish and check when the graph has grown ``long_growth``x."""
        cfg = self.config
        n = self.problem.n_steps
        held = all(self._isam.valueExists(k) or values.exists(k) for k in graph.keyVector())
        self.estimate_values.insert(values)
        self._at_check = False
        if held and n - self._window_b <= cfg.long_lag_steps + cfg.long_shift_steps:
            self._isam.update(graph, values)
            for _ in range(cfg.long_checkpoint_updates if extra else 0):
                self._isam.update(gtsam.NonlinearFactorGraph(), gtsam.Values())
            self.estimate_values.update(self._isam.calculateEstimate())
        else:
            self._rebuild_window(take_estimate=True)
        self.updates += 1
        self.accepted.push_back(graph)
        if n >= cfg.long_growth * self._long_full:
            try:
                self._check_window()
            except GTSAM_ERRORS as exc:   # the whole graph from here on
                self.failures.append(gtsam_error_line(exc))
                self._leave_window()
                self._recover(gtsam.NonlinearFactorGraph(), gtsam.Values(self.estimate_values))

    def _rebuild_window(self, take_estimate: bool) -> None:
        """A new iSAM2 on the window ending at the newest step (:meth:`StepChunks.window`:
        its chunks, the marginal of the older ones at the current estimate, the folds),
        started at the current estimate; with ``take_estimate`` its solution is taken at once
        (else at the next update: the estimate stays the one just checked)."""
        assert self._chunks is not None
        cfg = self.config
        n = self.problem.n_steps
        b = self._chunks.boundary(n, cfg.long_lag_steps)
        if b is None:
            raise RuntimeError(f"no window of {cfg.long_lag_steps} steps at step {n}")
        ids = np.array(sorted(self.problem.landmark_ids), dtype=np.int64)
        current = self.estimate_values
        graph, start = self._chunks.window(
            b, n, current, current, lambda ts: poses_from_values(current, ts),
            self._bearings(), ids, self._window_fresh)
        isam = self._new_isam()
        isam.update(graph, start)
        for _ in range(cfg.long_checkpoint_updates):
            isam.update(gtsam.NonlinearFactorGraph(), gtsam.Values())
        self._isam, self._window_b, self._window_fresh = isam, b, []
        self.window_rebuilds += 1
        if take_estimate:
            self.estimate_values.update(isam.calculateEstimate())

    def _check_window(self) -> None:
        """The whole-graph work of long mode with a window: up to ``isam2_polish``
        Gauss-Newton steps on the whole graph (each kept only if it lowers the error), the
        convergence check, Levenberg-Marquardt on the whole graph if the check fails (kept if
        lower, ``info["lm_restarts"]``), then the marginal rebuilt at the result and the window
        iSAM2 on it. The estimate is the checked one until the next update."""
        assert self._chunks is not None
        cfg = self.config
        self._long_full = self.problem.n_steps
        values, step, decrease, cost = polish(self.accepted, self.current_values(),
                                              cfg.isam2_polish, cfg.decrease_tol,
                                              gaussian=self._gaussian)
        converged = decrease <= cfg.decrease_tol and math.isfinite(step)
        if not converged:
            lm, report = solve_lm(self.accepted, values, cfg)
            if report.final_error < cost:
                self.lm_restarts += 1
                values = lm
                _, step, decrease, cost = polish(self.accepted, values, 0, cfg.decrease_tol,
                                                 gaussian=self._gaussian)
                converged = decrease <= cfg.decrease_tol and math.isfinite(step)
        self.estimate_values = values
        self._chunks.reset_folds()
        self._rebuild_window(take_estimate=False)
        self._at_check = True
        self._long_check = {"converged": bool(converged), "cost": cost, "gn_step": step,
                            "predicted_decrease": decrease,
                            "checked_at_step": self.problem.n_steps}

    def current_values(self) -> gtsam.Values:
        """The solver's estimate of every variable: with the window (``long_window``), the
        window's solution and the poses before it back-substituted through the conditionals
        they were eliminated into (:meth:`StepChunks.back_substitute`; a new Values), except
        right after a whole-graph check (the checked estimate)."""
        if not (self._long and self._window_b and self._chunks is not None) or self._at_check:
            return self.estimate_values
        values = gtsam.Values(self.estimate_values)
        values.update(self._chunks.back_substitute(values))
        return values

    def _leave_window(self) -> None:
        """Give the window up for the rest of the run (after a failure): long mode goes on
        with one iSAM2 over the whole graph (``long_window`` False)."""
        self._window_b = 0
        self._chunks = None
        self._log = BearingLog()


__all__ = ["WindowLongMode"]
