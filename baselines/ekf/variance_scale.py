"""The online bearing variance scale of the EKF baselines (``bearing_variance_scale=
"innovation"``, :class:`~baselines.ekf.config.BearingEkfConfig`): covariance matching on the
normalised innovation squared (NIS) of the bearings seen so far."""

from __future__ import annotations

import numpy as np
from scipy.stats import chi2

#: The median of a chi-square 1-dof variable, the median NIS of a consistent bearing.
NIS_MEDIAN = float(chi2.ppf(0.5, 1))


class InnovationVarianceScale:
    """``lambda >= 1``, the factor on the bearing variance ``sigma^2`` (rad^2) for which the
    median NIS of every bearing so far is the chi-square median.

    Each bearing ``k`` keeps its squared innovation ``y_k^2`` and ``a_k = H_k P H_k^T + var_k
    - sigma^2`` (rad^2, the parts the scale leaves alone) from its own update, in a buffer of
    shape ``(2, n)`` that doubles when full. At each update ``lambda`` takes one fixed-point
    step of ``median_k(y_k^2 / (a_k + lambda sigma^2)) = NIS_MEDIAN``: ``lambda <- max(1,
    lambda * median / NIS_MEDIAN)``, from 1 (exact in one step when every ``a_k = 0``; the
    map ``lambda -> lambda median(lambda)`` grows more slowly than ``lambda``, so the steps
    approach the root). ``O(n)`` per update, deterministic, causal.
    """

    def __init__(self, sigma_rad: float) -> None:
        self.sigma2 = float(sigma_rad) ** 2
        self._buf = np.empty((2, 256))
        self._n = 0
        self.value = 1.0
        self.max_value = 1.0

    def scaled(self, innovation: np.ndarray, hph: np.ndarray, var: np.ndarray,
               usable: np.ndarray) -> np.ndarray:
        """Add a step's bearings, update ``lambda``, return the step's scaled variances.

        Parameters
        ----------
        innovation, hph, var : arrays of shape (k,)
            The wrapped innovations (rad), ``H_i P H_i^T`` and the variances with
            ``lambda = 1`` (``sigma^2`` plus the second-order term), rad^2.
        usable : array of shape (k,), bool
            The bearings within ``max_bearing_nonlinearity`` (before the gate); only they are
            added.

        Returns
        -------
        ndarray of shape (k,)
            ``var + (lambda - 1) sigma^2`` with this step's ``lambda`` (this step included).
        """
        s2 = self.sigma2
        y2, rest = (innovation * innovation)[usable], (hph + var - s2)[usable]
        ok = np.isfinite(y2) & np.isfinite(rest)
        y2, rest = y2[ok], np.maximum(rest[ok], 0.0)
        n, m = self._n, len(y2)
        if m:
            if n + m > self._buf.shape[1]:
                grown = np.empty((2, max(2 * self._buf.shape[1], n + m)))
                grown[:, :n] = self._buf[:, :n]
                self._buf = grown
            self._buf[0, n:n + m], self._buf[1, n:n + m] = y2, rest
            self._n = n = n + m
        if n:
            lam = self.value
            med = float(np.median(self._buf[0, :n] / (self._buf[1, :n] + lam * s2)))
            self.value = max(1.0, lam * med / NIS_MEDIAN)
            self.max_value = max(self.max_value, self.value)
        return var + (self.value - 1.0) * s2


__all__ = ["InnovationVarianceScale", "NIS_MEDIAN"]
