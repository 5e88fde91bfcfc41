"""The normal mode's map and its check, and the restart where a check fails, for
``gtsam-isam2`` (a mixin of :class:`baselines.isam2.Isam2Mapper`; its state: ``config``,
``accepted``, ``estimate_values``, the buffer, ``_gaussian``, ``_polished``, ``_checked`` and
``_dims`` set in its ``__init__``).

The polish ``estimate()`` makes is computed once for a state of the solver and the buffer
(:meth:`NormalModeCheck._polish`): the whole-graph check at a scheduled update and an
``estimate()`` right after it (the paper maps every 10 steps, at the updates) share it. A check
that left the state as it was (no restart) is not made again on that state
(:meth:`NormalModeCheck._checked_here`): its LM would give the same values.
"""

from __future__ import annotations

import math
from typing import Any

import gtsam

from .lm_report import GTSAM_ERRORS, gtsam_error_line, polish, solve_lm


class NormalModeCheck:
    """The normal mode's polish and its check (module docstring)."""

    config: Any            # Isam2Config
    accepted: gtsam.NonlinearFactorGraph
    estimate_values: gtsam.Values
    _buffer: gtsam.NonlinearFactorGraph
    _buffer_values: gtsam.Values
    _gaussian: bool
    _polished: tuple[tuple[Any, ...], Any, Any, dict[str, Any]] | None
    _checked: tuple[Any, ...] | None
    _dims: tuple[int, int]
    _isam: gtsam.ISAM2
    failures: list[str]
    lm_restarts: int

    def current_values(self) -> gtsam.Values:   # WindowLongMode's, first in the MRO
        raise NotImplementedError

    def _new_isam(self) -> gtsam.ISAM2:   # Isam2Mapper's
        raise NotImplementedError

    def _state(self) -> tuple[Any, ...]:
        """What the normal mode's map is computed from: the solver's estimate (the object:
        every update, recovery and restart assigns a new one), the accepted graph's and the
        buffer's sizes (they only grow), and whether every factor is plain Gaussian."""
        return (self.estimate_values, self.accepted.size(), self._buffer.size(),
                self._buffer_values.size(), self._gaussian)

    @staticmethod
    def _same_state(a: tuple[Any, ...] | None, b: tuple[Any, ...]) -> bool:
        return a is not None and a[0] is b[0] and a[1:] == b[1:]

    def _checked_here(self) -> bool:
        """Whether :meth:`_restart_if_stuck` already checked this very state and left it as it
        was (converged, under the cost gate, an LM that did not lower the error, a rebuild that
        failed): the same check would make the same LM solve again."""
        return self._same_state(self._checked, self._state())

    def _with_buffer(self) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
        """The accepted graph and the solver's estimate, with the buffered steps if any."""
        graph = self.accepted
        values = self.current_values()
        if self._buffer.size() or self._buffer_values.size():
            graph = gtsam.NonlinearFactorGraph(self.accepted)
            graph.push_back(self._buffer)
            values = gtsam.Values(values)
            values.insert(self._buffer_values)
        return graph, values

    def _expected_cost(self) -> float:
        """The cost at the minimum with exact noise models: the chi-square mean, half the
        residual dimensions less the variables' (what ``Isam2Config.restart_cost_ratio``
        multiplies). The residuals are counted once each."""
        n0, dims = self._dims
        for i in range(n0, self.accepted.size()):
            f = self.accepted.at(i)
            dims += f.dim() if f is not None else 0
        self._dims = (self.accepted.size(), dims)
        return max(dims - self.estimate_values.dim(), 1) / 2

    def _polish_check(self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values
                      ) -> tuple[gtsam.Values, dict[str, Any]]:
        """Up to ``isam2_polish`` Gauss-Newton steps and the check (:func:`polish`)."""
        values, step, decrease, cost = polish(graph, values, self.config.isam2_polish,
                                              self.config.decrease_tol, gaussian=self._gaussian)
        return values, {"converged": bool(decrease <= self.config.decrease_tol
                                          and math.isfinite(step)),
                        "cost": cost, "gn_step": step, "predicted_decrease": decrease}

    def _polish(self) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values, dict[str, Any]]:
        """The normal mode's map and its check (:meth:`_polish_check` on :meth:`_with_buffer`),
        computed once per state: a scheduled update's check and the ``estimate()`` after it
        (the paper's cadence) share it."""
        key = self._state()
        c = self._polished
        if c is None or not self._same_state(c[0], key):
            graph, values = self._with_buffer()
            values, check = self._polish_check(graph, values)
            c = self._polished = (key, graph, values, check)
        return c[1], c[2], dict(c[3])

    def _restart_if_stuck(self, normal: bool) -> dict[str, Any]:
        """The whole-graph check (long mode: Gauss-Newton, no step taken; ``normal``: the
        normal mode's :meth:`_polish`, and only where the cost is also above
        ``restart_cost_ratio`` x :meth:`_expected_cost`); where it fails, LM and iSAM2 rebuilt
        there if LM lowered the error (``info["lm_restarts"]``; MRCLAM6 r3 at 0.5 m / 0.5 rad:
        59 cm, 10 of 15 landmarks without). Returns the check's dict."""
        if normal:
            state = self._state()
            _, values, c = self._polish()
            step, decrease, cost = c["gn_step"], c["predicted_decrease"], c["cost"]
        else:
            values, step, decrease, cost = polish(self.accepted, self.estimate_values, 0,
                                                  self.config.decrease_tol,
                                                  gaussian=self._gaussian)
        converged = decrease <= self.config.decrease_tol and math.isfinite(step)
        ratio = self.config.restart_cost_ratio
        if not converged and (not normal or (ratio is not None
                                             and cost > ratio * self._expected_cost())):
            values, report = solve_lm(self.accepted, values, self.config)
            if report.final_error < cost:
                isam = self._new_isam()
                try:
                    isam.update(self.accepted, values)
                    self._isam = isam
                    self.estimate_values = self._isam.calculateEstimate()
                    self.lm_restarts += 1
                    if normal:
                        return self._polish()[2]
                    _, step, decrease, cost = polish(self.accepted, self.estimate_values, 0,
                                                     self.config.decrease_tol,
                                                     gaussian=self._gaussian)
                    converged = decrease <= self.config.decrease_tol and math.isfinite(step)
                except GTSAM_ERRORS as exc:   # the old solver is still usable
                    self.failures.append(gtsam_error_line(exc))
        if normal:   # left as it was: the same check would make the same LM solve
            self._checked = state
        return {"converged": bool(converged), "cost": cost, "gn_step": step,
                "predicted_decrease": decrease}
