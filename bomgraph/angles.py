"""Angle wrapping: the only place in bomgraph where 2*pi appears.

Every comparison of bearings or headings goes through :func:`angle_residual`, which is also
the ``residual`` handed to filterpy's EKF update.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

TWO_PI = 2.0 * np.pi
_SCALARS = (float, np.float64)


def wrap_angle(angle_rad: ArrayLike) -> np.ndarray:
    """Wrap angles to the half-open interval (-pi, pi], element-wise like a numpy ufunc.

    Parameters
    ----------
    angle_rad : float or array
        Angles in radians, any real value.

    Returns
    -------
    ndarray or numpy float
        Same shape as the input; ``-pi`` maps to ``+pi``. An angle already in (-pi, pi] is
        returned exactly: ``pi - mod(pi - a, 2 pi)`` rounds it by up to an ulp (0.31 gave
        0.31000000000000005), which changed a fifth of the bearings a stream file holds.
    """
    if type(angle_rad) in _SCALARS and math.isfinite(angle_rad):
        # one float (Python's or numpy's float64): the same IEEE operations without numpy's
        # per-call cost
        x = float(angle_rad)
        if -math.pi < x <= math.pi:
            return np.float64(x)
        w = math.pi - (math.pi - x) % TWO_PI
        return np.float64(w + TWO_PI if w <= -math.pi else w)
    a = np.asarray(angle_rad, dtype=float)
    inside = (a > -np.pi) & (a <= np.pi)
    if inside.all():   # the usual case (bearings, residuals): a copy, never the input itself
        return a.copy()[()]
    w = np.pi - np.mod(np.pi - a, TWO_PI)
    # rounding can land exactly on -pi (e.g. just above +pi); the interval is (-pi, pi]
    w = np.where(w <= -np.pi, w + TWO_PI, w)
    return np.where(inside, a, w)[()]


def angle_residual(a_rad: ArrayLike, b_rad: ArrayLike) -> np.ndarray:
    """The wrapped difference ``a - b`` in (-pi, pi], element-wise.

    This is the ``residual`` passed to filterpy's ``ExtendedKalmanFilter.update``.
    """
    return wrap_angle(np.subtract(a_rad, b_rad, dtype=float))
