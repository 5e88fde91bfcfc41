"""The prior on the inverse depth of a new feature (option ``rho_prior``).

``"range"`` (every preset): ``rho ~ N(2/R, (1/R)^2)`` from the stream header's sensor range
``R`` (Civera's ``0.1 +- 0.5`` per m without one; :class:`~baselines.ekf.slam.EkfSlam`).
The maps then follow the stated range: a range stated twice too long puts the prior's mean at
twice the depth and its 2-sigma near bound beyond the near landmarks, whose bearings are gated;
no range leaves the depth to the parallax alone (docs/measurements.md, "The inverse-depth
prior and the stated sensor range").

``"empirical"``: the header's range is not read. The first features start from Civera's
range-free ``0.1 +- 0.5`` per m (or the options ``rho_init_per_m``, ``rho_sigma_per_m``);
once ``EMPIRICAL_MIN`` (1, chosen on MRCLAM6) features have become Euclidean points in this run (their depths set by
the bearings: Bailey's or Civera's test passed), the prior is estimated from the inverse
depths they had when they were converted (empirical Bayes): mean ``m = median(rho_k)``, std.
dev. ``max(m / 2, 1.4826 MAD(rho_k))`` (the ``"range"`` prior's shape, ``sigma = mean / 2``,
with the scene's depths in place of the stated range). Features still in inverse depth then
get the difference as a pseudo-measurement of ``rho`` (information ``1/s_new^2 - 1/s_old^2``
at the value that makes their prior the new one, the exact change of prior of a linear
Gaussian model), when the new prior is the narrower; later features start from it.

``"empirical-start"``: ``"empirical"`` with a scale from the robot's own motion for the
features that start before any is converted (Civera's start is a 10 m mean depth whatever
the scene). On the dead-reckoned path (odometry alone, as the filter has it before its
features carry depth), each landmark's first ray and its latest ray give an inverse depth on
the first ray, ``sin(alpha) / (b x u2)`` (``alpha`` the angle between the rays, ``b`` the
baseline, ``u2`` the latest ray), linear in the angle's noise (no selection by parallax,
which would favour the draws that overstate it), with variance ``(2 sigma_b^2 + accumulated
heading variance) / (b x u2)^2``. Once ``START_MIN`` landmarks have one and the weighted mean
``m`` is positive with std. error at most ``START_REL_SD m``, the prior becomes ``N(m,
(m/2)^2)`` (the ``"range"`` prior's shape) and later features start from it; converted
features update the prior as in ``"empirical"``, before and after. Each change of prior moves
the pending features to it exactly, in both directions: the pseudo-measurement above when it
is narrower; when it is wider (a scene nearer than Civera's 10 m: on a 1 m world the scale's
``2 +- 1`` per m is wider than ``0.1 +- 0.5``) the prior's information ``1/s0^2 - 1/s1^2`` is
taken out of the state (:meth:`RhoPriorMixin._widen`), which ``"empirical"`` does not do. The search stops after
``START_MAX_STEPS`` steps (a robot that does not move, or only turns, gives no scale).
"""

from __future__ import annotations

from typing import Any

import math

import numpy as np

from bomgraph.angles import wrap_angle
from bomgraph.geometry import compose

#: The choices of :attr:`~baselines.ekf.config.BearingEkfConfig.rho_prior`.
RHO_PRIORS = ("range", "empirical", "empirical-start")

#: Features converted before the empirical prior replaces the range-free start.
EMPIRICAL_MIN = 1

#: ``"empirical-start"``: landmarks with a two-ray depth before the first features start.
START_MIN = 3

#: ``"empirical-start"``: the largest std. error of the scale, relative (chosen on MRCLAM6).
START_REL_SD = 0.2

#: ``"empirical-start"``: steps after which no scale is sought any more.
START_MAX_STEPS = 100

_CIVERA = (0.1, 0.5)                   # rho_init, rho_sigma per m: range-free (Civera et al.)


class RhoPriorMixin:
    """The ``rho_prior`` option, mixed into :class:`~baselines.ekf.slam.EkfSlam`'s mappers
    before it (``class M(RhoPriorMixin, EkfSlam)``); with ``"range"`` every method is the
    base class's own."""

    config: Any
    filter: Any
    rho_init: float
    rho_sigma: float
    _sizes: dict
    _offset: dict

    def _empirical(self) -> dict[str, Any] | None:
        if self.config.rho_prior == "range":
            return None
        st = getattr(self, "_rho_state", None)
        if st is None:
            c = self.config
            st = {"prior": (c.rho_init_per_m or _CIVERA[0], c.rho_sigma_per_m or _CIVERA[1]),
                  "feature": {}, "converted": [], "tightened": 0}
            if c.rho_prior == "empirical-start":
                st.update(scaled=False, pose=np.zeros(3), var=0.0, steps=0, first={}, two_ray={},
                          widened=0)
            self._rho_state = st
        return st

    def step(self, step: Any) -> None:
        st = self._empirical()
        if st is not None and st.get("scaled") is False:
            self._start_scale(st, step)
        super().step(step)                             # type: ignore[misc]

    def _start_scale(self, st: dict[str, Any], step: Any) -> None:
        """``"empirical-start"``: the two-ray inverse depths on the dead-reckoned path, and the
        prior from them once their weighted mean is known to ``START_REL_SD``."""
        if step.odom is not None:
            st["pose"] = compose(st["pose"], np.asarray(step.odom, float))
            st["var"] += float(np.ravel(step.odometry_sigma(self._header))[2]) ** 2
        st["steps"] += 1
        x, y, psi = st["pose"].tolist()
        b2 = 2.0 * self._header.bearing_sigma_rad ** 2
        for i, zi in zip(step.landmark_ids.tolist(), step.bearings_rad.tolist()):
            th = psi + zi
            f = st["first"].get(i)
            if f is None:
                st["first"][i] = (x, y, th, st["var"])
                continue
            across = (x - f[0]) * math.sin(th) - (y - f[1]) * math.cos(th)    # b x u2
            if abs(across) > 1e-9:             # inverse depth on the first ray, its variance
                st["two_ray"][i] = (math.sin(float(wrap_angle(th - f[2]))) / across,
                                  (b2 + st["var"] - f[3]) / across ** 2)
        if len(st["two_ray"]) >= START_MIN:
            r, v = np.array(list(st["two_ray"].values())).T
            w = 1.0 / v
            m = float(np.sum(w * r) / np.sum(w))
            if m > 0 and 1.0 / math.sqrt(float(np.sum(w))) <= START_REL_SD * m:
                st["prior"], st["scaled"] = (m, 0.5 * m), True
                st["start_depth_m"], st["start_step"] = 1.0 / m, st["steps"]
                self._tighten(st)
                return
        if st["steps"] >= START_MAX_STEPS:
            st["scaled"] = None

    def _add_inverse_depth(self, ids: np.ndarray, z: np.ndarray) -> None:
        st = self._empirical()
        if st is not None:
            self.rho_init, self.rho_sigma = st["prior"]
            for i in ids.tolist():
                st["feature"][i] = st["prior"]
        super()._add_inverse_depth(ids, z)             # type: ignore[misc]

    def _convert(self, ready: Any) -> None:
        st = self._empirical()
        if st is None:
            super()._convert(ready)                    # type: ignore[misc]
            return
        keys, bi = self._idp_blocks()                  # type: ignore[attr-defined]
        rho = self.filter.x[bi[:, 3]].copy() if keys else np.zeros(0)
        super()._convert(ready)                        # type: ignore[misc]
        new = [r for k, r in zip(keys, rho.tolist()) if ("lm", k[1]) in self._sizes]
        if new:
            for k in keys:
                if ("lm", k[1]) in self._sizes:
                    st["feature"].pop(k[1], None)
            st["converted"].extend(new)
            if len(st["converted"]) >= EMPIRICAL_MIN:
                r = np.asarray(st["converted"])
                m = float(np.median(r))
                mad = 1.4826 * float(np.median(np.abs(r - m)))
                if m > 0:
                    st["prior"] = (m, max(0.5 * m, mad))
                    self._tighten(st)

    def _tighten(self, st: dict[str, Any]) -> None:
        """The pseudo-measurements of ``rho`` that move the pending features to the prior."""
        m1, s1 = st["prior"]
        j1 = 1.0 / (s1 * s1)
        cols, ys, vs, ids = [], [], [], []
        x = self.filter.x
        widen = self.config.rho_prior == "empirical-start"
        for i, (m0, s0) in st["feature"].items():
            j0 = 1.0 / (s0 * s0)
            if ("idp", i) not in self._offset:
                continue
            if j1 <= j0 * 1.000001:
                if widen and j1 < j0 * 0.999999:
                    self._widen(self._offset[("idp", i)] + 3, j0, m0, j1, m1)
                    st["feature"][i] = (m1, s1)
                    st["widened"] += 1
                continue
            c = self._offset[("idp", i)] + 3
            cols.append(c)
            ys.append((j1 * m1 - j0 * m0) / (j1 - j0) - x[c])
            vs.append(1.0 / (j1 - j0))
            ids.append(i)
        if cols:
            self.filter.update_rows(np.array(cols, np.int64)[:, None], np.ones((len(cols), 1)),
                                    np.array(ys), np.array(vs))
            for i in ids:
                st["feature"][i] = (m1, s1)
            st["tightened"] += len(ids)

    def _widen(self, c: int, j0: float, m0: float, j1: float, m1: float) -> None:
        """The exact change of a feature's ``rho`` prior from ``N(m0, 1/j0)`` to the wider
        ``N(m1, 1/j1)`` (information ``j0 - j1`` taken away, Woodbury; the state's other
        information is kept): ``P' = P + P e (1/(j0 - j1) - P_cc)^-1 e^T P``,
        ``x' = x + P' e (j1 (m1 - x_c) - j0 (m0 - x_c))``. ``P_cc <= 1/j0`` (the prior is part
        of it) keeps ``P'`` positive definite."""
        f = self.filter
        P, x = f.P, f.x
        pe = P[:, c].copy()
        P += np.outer(pe, pe) / (1.0 / (j0 - j1) - pe[c])
        x += P[:, c] * (j1 * (m1 - x[c]) - j0 * (m0 - x[c]))
        x[f._angle_index] = wrap_angle(x[f._angle_index])
        f.version += 1

    def _rho_prior_sd(self, keys: list[tuple[str, int]]) -> Any:
        """The prior std. dev. of ``rho`` of the features ``keys`` (a scalar with
        ``"range"``)."""
        st = self._empirical()
        if st is None:
            return self.rho_sigma
        return np.array([st["feature"].get(k[1], st["prior"])[1] for k in keys])


__all__ = ["EMPIRICAL_MIN", "RHO_PRIORS", "RhoPriorMixin", "START_MAX_STEPS", "START_MIN",
           "START_REL_SD"]
