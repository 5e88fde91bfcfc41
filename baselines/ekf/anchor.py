"""The anchor bearing of an inverse-depth candidate, tested once later sightings constrain it
(option ``anchor_test`` of ``ekf``; docs/measurements.md, "Re-testing the anchor bearing").

A feature's first bearing ``z_1`` sets its ``theta = psi_1 + z_1`` (:meth:`~baselines.ekf.
slam.EkfSlam._add_inverse_depth`); nothing predicts it, so no gate can test it, and an outlier
there goes, through the feature's later bearings, into the robot's heading. With the option
on, each new feature also gets one state, the anchor bearing's error ``e = theta - psi_1 - z_1
(+ b)`` (``b`` the coloured error, when modelled), added at the first sighting as that exact
linear function of the state (zero, variance ``sigma^2``, uncorrelated with everything but
``theta``): the anchor bearing is then the measurement ``0 = e + v``, ``v ~ N(0, sigma^2)``,
of a state no other bearing measures, and the filter carries ``e``'s posterior under every
later update, with all correlations (the poses, the other features). The marginal of the
other states is unchanged (no row of any update touches ``e``).

The test is the anchor's leave-one-out residual: with ``e_hat``, ``P_e`` its posterior, the
residual ``-e_hat`` of that measurement has variance ``sigma^2 - P_e``, and ``e_hat^2 /
(sigma^2 - P_e)`` is also the statistic of the anchor against the posterior of ``e`` without
it (residual ``-e_hat sigma^2 / (sigma^2 - P_e)``, variance ``sigma^4 / (sigma^2 - P_e)``):
chi-square with 1 dof when the anchor is as stated, tested at the filter's gate
(``gate_probability``). Each
anchor is tested once, at the first step after whose updates the rest of the filter knows
``e`` at least as well as the anchor alone does (``P_e <= sigma^2 / 2``: information from
elsewhere ``>= 1 / sigma^2``), whether the feature is still in inverse depth (then before
Bailey's test) or already a landmark (``e`` stays correlated with its ``[x, y]``); an anchor
never so constrained is never tested. Testing at every step from the second sighting on
instead dropped 1.4 % of the anchors of noise-only simulated streams against 0.1-0.5 %
(docs/measurements.md). The anchors that fail at one step are taken out of the filter
together (:meth:`~baselines.ekf.filter.BearingEkf.retract`, the inverse of their update:
the robot's heading and every correlated state get back what they pulled; as the gate tests
each bearing on its own); the feature keeps its later bearings. Every tested ``e`` is then
marginalised out. The robot's truth is never used. Counted in ``info["anchors_dropped"]``
(the ids in ``info["anchors_dropped_ids"]``; ``info["anchors_untested"]`` still in the
state).

What it cannot do: two anchors taken at one pose whose heading the filter knows poorly, one
of them an outlier, disagree through that heading, and their residuals are nearly
symmetric; the test then may drop the good one (MRCLAM6 robot 5, docs/measurements.md).
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from .filter import FilterNumericalError
from .slam import BLOCK_ANCHOR, BLOCK_BIAS, BLOCK_IDP, BLOCK_LM

#: The test is made once the rest of the filter holds at least this share of the anchor's own
#: information on its error (``P_e <= sigma^2 / (1 + share)``).
MIN_SHARE = 1.0


class AnchorTestMixin:
    """The ``anchor_test`` option, mixed into :class:`~baselines.ekf.mappers.EkfMapper` before
    :class:`~baselines.ekf.slam.EkfSlam`; off, every method is the next class's."""

    config: Any
    filter: Any
    _sizes: dict
    _offset: dict
    _gate: float
    _white_sigma: float
    _coloured: Any

    def _anchor_on(self) -> bool:
        return bool(getattr(self.config, "anchor_test", False))

    def _add_inverse_depth(self, ids: np.ndarray, z: np.ndarray) -> None:
        on = self._anchor_on() and ids.size
        if on:
            self._drop_orphans()           # a restarted feature's old error, before its new one
            per = 5 + bool(self._coloured.enabled)          # [x0, y0, theta, rho], (b,) e
            self.filter.check_room(per * ids.size, f"{ids.size} new landmark features")
        super()._add_inverse_depth(ids, z)                 # type: ignore[misc]
        if not on:
            return
        m = ids.size
        off = self._offset
        theta = [off[(BLOCK_IDP, i)] + 2 for i in ids.tolist()]
        bias = [off[(BLOCK_BIAS, i)] for i in ids.tolist() if (BLOCK_BIAS, i) in off]
        idx = np.array([2, *theta, *bias], np.int64)
        jac = np.zeros((m, idx.size))
        jac[:, 0] = -1.0                                    # e = theta - psi (- z: the value 0)
        jac[np.arange(m), 1 + np.arange(m)] = 1.0
        if bias:                                            # (+ b: theta = psi + z - b + e)
            jac[np.arange(m), 1 + m + np.arange(m)] = 1.0
        self._add_blocks([(BLOCK_ANCHOR, i) for i in ids.tolist()],  # type: ignore[attr-defined]
                         np.zeros(m), idx, jac, np.zeros(m))

    def _convert(self, ready: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> None:
        if self._anchor_on():
            self._test_anchors()
        super()._convert(ready)                            # type: ignore[misc]

    def _test_anchors(self) -> None:
        """Test, once, each anchor the rest of the filter now knows well enough, on its own (as
        the gate tests each bearing); retract all that fail at once; marginalise the errors
        of every anchor tested."""
        todo = [k for k in self._sizes if k[0] == BLOCK_ANCHOR]
        if not todo:
            return
        var = self._white_sigma ** 2
        o = np.array([self._offset[k] for k in todo], np.int64)
        e, pe = self.filter.x[o], self.filter.P[o, o]
        rest = var - pe                              # the residuals' variances
        ready = rest >= var * MIN_SHARE / (1.0 + MIN_SHARE)
        if not ready.any():
            return
        fail = ready & (e * e > self._gate * np.where(ready, rest, 1.0))
        if fail.any():
            try:        # S = var I - P_ee: positive definite unless the rest cannot separate
                self.filter.retract(o[fail], var)       # two failing anchors (then the worst)
            except FilterNumericalError:
                worst = int(np.argmax(np.where(fail, e * e / rest, -1.0)))
                fail[:] = False
                fail[worst] = True
                self.filter.retract(o[fail], var)       # its own rest >= var / 2 > 0
            self._dropped_anchors().extend(k[1] for k, f in zip(todo, fail.tolist()) if f)
        self._remove_blocks([k for k, r in zip(todo, ready.tolist()) if r])  # type: ignore

    def _dropped_anchors(self) -> list[int]:
        dropped = getattr(self, "_anchors_dropped", None)
        if dropped is None:
            dropped = self._anchors_dropped = []
        return dropped

    def _drop_orphans(self) -> None:
        """Marginalise the anchor errors of features restarted (neither a feature nor a
        landmark any more)."""
        gone = [k for k in self._sizes if k[0] == BLOCK_ANCHOR
                and (BLOCK_IDP, k[1]) not in self._sizes and (BLOCK_LM, k[1]) not in self._sizes]
        if gone:
            self._remove_blocks(gone)                      # type: ignore[attr-defined]

    def _anchor_info(self) -> dict[str, Any]:
        if not self._anchor_on():
            return {}
        dropped = self._dropped_anchors()
        return {"anchors_dropped": len(dropped), "anchors_dropped_ids": list(dropped),
                "anchors_untested": sum(k[0] == BLOCK_ANCHOR for k in self._sizes)}


__all__ = ["AnchorTestMixin", "MIN_SHARE"]
