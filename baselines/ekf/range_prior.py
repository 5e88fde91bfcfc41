"""The prior on the inverse depth of a new feature (option ``rho_prior``).

``"range"`` (every preset): ``rho ~ N(2/R, (1/R)^2)`` from the stream header's sensor range
``R`` (Civera's ``0.1 +- 0.5`` per m without one; :class:`~baselines.ekf.slam.EkfSlam`).
The maps then follow the stated range: a range stated twice too long puts the prior's mean at
twice the depth and its 2-sigma near bound beyond the near landmarks, whose bearings are gated;
no range leaves the depth to the parallax alone (docs/measurements.md, "The inverse-depth
prior and the stated sensor range").

``"empirical"``: the header's range is not read. The first features start from Civera's range-
free ``0.1 +- 0.5`` per m (or the options ``rho_init_per_m``, ``rho_sigma_per_m``); once
``EMPIRICAL_MIN`` (1, chosen on MRCLAM6) features have become Euclidean points in this run
(their depths set by the bearings: Bailey's or Civera's test passed), the prior is estimated
from the inverse depths they had when they were converted (empirical Bayes): mean ``m =
median(rho_k)``, std. dev. ``max(m / 2, 1.4826 MAD(rho_k))`` (the ``"range"`` prior's shape,
``sigma = mean / 2``, with the scene's depths in place of the stated range). Features still in
inverse depth then get the difference as a pseudo-measurement of ``rho`` (information
``1/s_new^2 - 1/s_old^2`` at the value that makes their prior the new one, the exact change of
prior of a linear Gaussian model), when the new prior is the narrower; later features start from
it.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

_log = logging.getLogger(__name__)

#: The choices of :attr:`~baselines.ekf.config.BearingEkfConfig.rho_prior`.
RHO_PRIORS = ("range", "empirical")

#: Features converted before the empirical prior replaces the range-free start.
EMPIRICAL_MIN = 1

_CIVERA = (0.1, 0.5)                   # rho_init, rho_sigma per m: range-free (Civera et al.)


class RhoPriorMixin:
    """The ``rho_prior`` option, mixed into :class:`~baselines.ekf.slam.EkfSlam`'s mappers
    before it (``class M(RhoPriorMixin, EkfSlam)``); with ``"range"`` every method is the
    base class's own."""

    config: Any
    filter: Any
    rho_init: float
    rho_sigma: float
    header_range_m: float | None
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
            self._rho_state = st
        return st

    def _add_inverse_depth(self, ids: np.ndarray, z: np.ndarray) -> None:
        st = self._empirical()
        if st is not None:
            self.rho_init, self.rho_sigma = st["prior"]
            for i in ids.tolist():
                st["feature"][i] = st["prior"]
        super()._add_inverse_depth(ids, z)             # type: ignore[misc]

    def _convert(self, ready: Any) -> None:
        if _log.isEnabledFor(logging.DEBUG):     # to trace a feature from its first sighting
            ready = self._logged(ready)
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
        for i, (m0, s0) in st["feature"].items():
            j0 = 1.0 / (s0 * s0)
            if j1 <= j0 * 1.000001 or ("idp", i) not in self._offset:
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

    def _rho_prior_info(self) -> dict[str, Any]:
        """The estimate's entries on the inverse-depth prior in use, ``[rho, sd]`` per m, and
        where it came from (none for the clone candidates, which have no inverse depth): with
        ``"range"`` the header's ``sensor_range_m``, the options, or Civera's default when the
        stream states no range (the maps follow the stated range: docs/measurements.md); with
        ``"empirical"`` the features it was estimated from and the pending features moved to
        it."""
        if not self._uses_inverse_depth(self.config):     # type: ignore[attr-defined]
            return {}
        st = self._empirical()
        if st is None:
            c = self.config
            source = ("options" if c.rho_init_per_m or c.rho_sigma_per_m else
                      "sensor_range_m" if self.header_range_m else
                      "Civera's default: the stream states no sensor_range_m")
            return {"rho_prior_per_m": [float(self.rho_init), float(self.rho_sigma)],
                    "rho_prior_from": source}
        return {"rho_prior_per_m": [float(v) for v in st["prior"]],
                "rho_prior_from": "empirical",
                "rho_prior_from_features": len(st["converted"]),
                "rho_prior_moved_features": int(st["tightened"])}

    def _logged(self, ready: Any) -> Any:
        """``ready`` that also logs (DEBUG) the features it makes Euclidean, with their
        ``sigma_rho / rho``."""
        def logged(features: np.ndarray, covs: np.ndarray) -> np.ndarray:
            sel = np.asarray(ready(features, covs), bool) & (features[:, 3] > 0)
            if sel.any():
                keys = self._idp_blocks()[0]           # type: ignore[attr-defined]
                t = self._t                            # type: ignore[attr-defined]
                rel = np.sqrt(covs[sel, 3, 3]) / features[sel, 3]
                _log.debug("step %d: features %s made Euclidean at sigma_rho/rho %s", t,
                           [keys[i][1] for i in np.flatnonzero(sel)], np.round(rel, 3).tolist())
            return sel
        return logged

    def _rho_prior(self, keys: list[tuple[str, int]]) -> tuple[Any, Any]:
        """The prior mean and std. dev. of ``rho`` of the features ``keys`` (scalars with
        ``"range"``)."""
        st = self._empirical()
        if st is None:
            return self.rho_init, self.rho_sigma
        prior = np.array([st["feature"].get(k[1], st["prior"]) for k in keys], float)
        return prior[:, 0], prior[:, 1]


__all__ = ["EMPIRICAL_MIN", "RHO_PRIORS", "RhoPriorMixin"]
