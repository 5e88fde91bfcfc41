"""The robust (M-estimation) bearing update of the EKF baselines (``robust_update="huber"``,
:class:`~baselines.ekf.config.BearingEkfConfig`): a bearing whose normalised innovation
exceeds ``robust_k`` has its variance inflated so that its step follows Huber's psi.

With ``S_i = H_i P H_i^T + var_i`` (rad^2, the bearing's own innovation variance) and the
normalised innovation ``y_n = y_i / sqrt(S_i)``, Huber's weight is ``w = min(1, k / |y_n|)``
and the bearing's variance becomes ``var_i + (1 / w - 1) S_i``, so that its innovation
variance is ``S_i / w = S_i |y_n| / k`` (a bearing with ``|y_n| <= k`` keeps ``var_i``
exactly). Alone in an update its correction is then ``P H^T y / S_eff = P H^T / sqrt(S_i)
psi(y_n)`` with Huber's ``psi(u) = u`` for ``|u| <= k``, ``k sign(u)`` beyond: one step of
iteratively reweighted least squares on the prior and the bearing, the weight taken at the
prior (Karlgaard and Schaub's Huber-based filter, written as a variance inflation). In a
batch each bearing is weighted on its own marginal ``S_i``, as the gate is. The gate stays
the last line and decides as before: a bearing past it on ``S_i`` (``y^2 > g S_i``) keeps
``var_i``, so it is still gated (inflating it would widen the gate to ``|y_n| > g / k``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .variance_scale import InnovationVarianceScale

#: The choices of :attr:`~baselines.ekf.config.BearingEkfConfig.robust_update`.
ROBUST_UPDATES = ("none", "huber")


def huber_variance(innovation: np.ndarray, hph: np.ndarray, var: np.ndarray,
                   k: float, gate: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
    """The bearing variances with Huber's weight, and which bearings were inflated.

    Parameters
    ----------
    innovation, hph, var : arrays of shape (m,)
        The wrapped innovations ``y`` (rad), ``H_i P H_i^T`` and the variances (rad^2).
    k : float
        The threshold on ``|y| / sqrt(H_i P H_i^T + var_i)``.
    gate : float
        The gate's NIS threshold ``g`` (``inf``: no gate): bearings with ``y^2 > g S_i`` are
        left as they are (the gate drops them).

    Returns
    -------
    var_eff : ndarray of shape (m,)
        ``var_i`` where ``|y_n| <= k`` or ``y^2 > g S_i`` (the same floats), else ``var_i +
        (|y_n| / k - 1) S_i``, i.e. an innovation variance ``S_i |y_n| / k``.
    inflated : ndarray of shape (m,), bool
        ``k < |y_n|`` and ``y^2 <= g S_i``.
    """
    s = hph + var
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.abs(innovation) / (k * np.sqrt(s))          # |y_n| / k
    inflated = (ratio > 1.0) & ~(innovation * innovation > gate * s)
    if not inflated.any():
        return var, inflated
    return np.where(inflated, var + (ratio - 1.0) * s, var), inflated


class BearingVariances:
    """The variances of a step's bearings in the gate and the update (called by
    :class:`~baselines.ekf.slam.EkfSlam` on both update paths): ``var_i`` scaled online
    (``bearing_variance_scale="innovation"``, when ``scale`` is given), then Huber's inflation
    (``robust_update="huber"``); with both off, ``var_i`` itself.

    Parameters
    ----------
    scale : InnovationVarianceScale or None
    robust_update : str
        One of :data:`ROBUST_UPDATES`.
    robust_k : float
        Huber's threshold on the normalised innovation.
    gate : float
        The gate's NIS threshold (bearings past it keep their variance).
    """

    def __init__(self, scale: InnovationVarianceScale | None, robust_update: str,
                 robust_k: float, gate: float) -> None:
        self.scale = scale
        self.k = float(robust_k) if robust_update == "huber" else None
        self.gate = gate
        self.n_downweighted = 0

    def __call__(self, innovation: np.ndarray, hph: np.ndarray, var: np.ndarray,
                 usable: np.ndarray) -> np.ndarray:
        """The variances ``(m,)`` of the step's bearings (arguments as in
        :meth:`InnovationVarianceScale.scaled`)."""
        if self.scale is not None:
            var = self.scale.scaled(innovation, hph, var, usable)
        if self.k is None:
            return var
        var, inflated = huber_variance(innovation, hph, var, self.k, self.gate)
        self.n_downweighted += int(np.count_nonzero(inflated & usable))
        return var

    def info(self) -> dict[str, Any]:
        """The estimate's entries: the scale's last and largest value, the count of bearings
        used with an inflated variance (each only when its option is on)."""
        out: dict[str, Any] = {}
        if self.scale is not None:
            out.update(bearing_variance_scale=self.scale.value,
                       bearing_variance_scale_max=self.scale.max_value)
        if self.k is not None:
            out["robust_downweighted"] = self.n_downweighted
        return out


__all__ = ["BearingVariances", "ROBUST_UPDATES", "huber_variance"]
