"""The normal mode's map and its check, for ``gtsam-isam2`` (a mixin of
:class:`baselines.isam2.Isam2Mapper`; its state: ``config``, ``accepted``, ``estimate_values``,
the buffer, ``_gaussian``, ``_polished`` and ``_dims`` set in its ``__init__``).

The polish ``estimate()`` makes is computed once for a state of the solver and the buffer
(:meth:`NormalModeCheck._polish`): the whole-graph check at a scheduled update and an
``estimate()`` right after it (the paper maps every 10 steps, at the updates) share it.
"""

from __future__ import annotations

import math
from typing import Any

import gtsam

from .lm_report import polish


class NormalModeCheck:
    """The normal mode's polish and its check (module docstring)."""

    config: Any            # Isam2Config
    accepted: gtsam.NonlinearFactorGraph
    estimate_values: gtsam.Values
    _buffer: gtsam.NonlinearFactorGraph
    _buffer_values: gtsam.Values
    _gaussian: bool
    _polished: tuple[tuple[Any, ...], Any, Any, dict[str, Any]] | None
    _dims: tuple[int, int]

    def current_values(self) -> gtsam.Values:   # WindowLongMode's, first in the MRO
        raise NotImplementedError

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
        key = (self.estimate_values, self.accepted.size(), self._buffer.size(),
               self._buffer_values.size(), self._gaussian)
        c = self._polished
        if c is None or c[0][0] is not key[0] or c[0][1:] != key[1:]:
            graph, values = self._with_buffer()
            values, check = self._polish_check(graph, values)
            c = self._polished = (key, graph, values, check)
        return c[1], c[2], dict(c[3])
