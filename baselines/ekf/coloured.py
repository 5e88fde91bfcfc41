"""Serially correlated bearing errors as a state of the filter (issue 15 item 5).

On recordings the error of a bearing is not white: two sightings of one landmark from nearly the
same viewing geometry err alike (a camera's error depends on where the landmark sits in the
image and from which side it is seen), and the correlation falls as the geometry changes, not
as time or keyframes pass. A filter that takes the sightings as independent gains information
in proportion to how densely the stream is keyframed and becomes overconfident on a dense one.

The model: the bearing to landmark ``i`` is ``z = h(x) + b_i + w`` with ``w`` white, of variance
``(1 - c) sigma^2``, and ``b_i`` a per-landmark coloured error of variance ``c sigma^2``
(``c`` = ``correlated_fraction``, ``sigma`` the stream's bearing sigma, so the total variance
stays ``sigma^2``). ``b_i`` is a first-order Gauss-Markov process in the *viewing geometry*:
between two sightings

    ``b_i <- a b_i + n``,  ``a = exp(-dg / L)``,  ``n ~ N(0, (1 - a^2) c sigma^2)``,

with ``dg = |change of the ray's world direction| + |change of the robot's heading|`` (the
parallax at the landmark plus the robot's turn, radians, from the filter's estimate) and
``L`` = ``correlation_length_rad``. So two sightings correlate at ``c exp(-dg / L)`` whatever the
keyframing: a second look from the same place adds only the white part's information, a look
from new geometry adds nearly all of it. ``b_i`` is augmented into the filter (one state per
landmark, :data:`~baselines.ekf.slam` kind ``"bias"``); it is invariant under the global
translation and rotation, so its rows of the OC-EKF nullspace are zero.

``c = 0`` (the ``paper`` defaults) is the white-noise filter, unchanged.
"""

from __future__ import annotations

import math

import numpy as np

from bomgraph.angles import angle_residual


def ray_directions(x: np.ndarray, kinds: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """World direction (rad) of the ray from the robot (``x[:3]``) to each landmark block.

    Parameters
    ----------
    x : array of shape (n,)
    kinds : int array of shape (k,)
        Block sizes: 2 (Euclidean ``[x, y]``) or 4 (inverse depth ``[x0, y0, theta, rho]``).
    offsets : int array of shape (k,)

    Returns
    -------
    ndarray of shape (k,)
        ``atan2`` of ``l - p`` (Euclidean) or of ``rho (a - p) + [cos theta, sin theta]``
        (inverse depth, the same direction for ``rho > 0``).
    """
    out = np.empty(len(offsets))
    p = x[:2]
    e = kinds == 2
    if e.any():
        d = x[offsets[e, None] + np.arange(2)] - p
        out[e] = np.arctan2(d[:, 1], d[:, 0])
    if (~e).any():
        f = x[offsets[~e, None] + np.arange(4)]
        v = f[:, 3:4] * (f[:, :2] - p) + np.column_stack([np.cos(f[:, 2]), np.sin(f[:, 2])])
        out[~e] = np.arctan2(v[:, 1], v[:, 0])
    return out


class ColouredBearingError:
    """The bookkeeping of the per-landmark coloured bearing error (see the module docstring).

    Parameters
    ----------
    bearing_sigma_rad : float
        The stream's sigma of one bearing (white and coloured parts together).
    fraction : float
        ``c`` in ``[0, 1)``: the share of the variance that is coloured (0: off).
    length_rad : float
        ``L`` > 0, the geometry change over which the correlation falls by ``e``.
    """

    def __init__(self, bearing_sigma_rad: float, fraction: float, length_rad: float) -> None:
        self.enabled = fraction > 0
        self.white_sigma_rad = math.sqrt(1.0 - fraction) * bearing_sigma_rad
        self.bias_var_rad2 = fraction * bearing_sigma_rad ** 2
        self.length_rad = float(length_rad)
        self._last: dict[int, tuple[float, float]] = {}   # id -> (ray direction, heading)

    def remember(self, ids: list[int], directions: np.ndarray, heading_rad: float) -> None:
        """Record the geometry of a sighting of each of ``ids`` (ray directions ``(k,)``)."""
        for i, d in zip(ids, directions.tolist()):
            self._last[i] = (d, heading_rad)

    def forget(self, ids: list[int]) -> None:
        for i in ids:
            self._last.pop(i, None)

    def factors(self, ids: list[int], directions: np.ndarray, heading_rad: float) -> np.ndarray:
        """``a = exp(-dg / L)`` since each landmark's last sighting (1 for a first one), and
        the current geometry recorded as the new last one."""
        last = np.array([self._last.get(i, (d, heading_rad))
                         for i, d in zip(ids, directions.tolist())]).reshape(-1, 2)
        dg = (np.abs(angle_residual(directions, last[:, 0]))
              + np.abs(angle_residual(heading_rad, last[:, 1])))
        self.remember(ids, directions, heading_rad)
        return np.exp(-dg / self.length_rad)


__all__ = ["ColouredBearingError", "ray_directions"]
