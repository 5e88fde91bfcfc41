"""A window's pair variances with a systematic heading error (``tri_heading_bias_rad``).

A window bundle's covariance assumes independent bearing and odometry errors. A robot's
heading also errs systematically (a turn rate read a little wrong, the same way turn after
turn), and the depth of a landmark seen with small parallax is a ratio of the baseline to the
parallax: a heading error ``delta`` accumulated across the window moves a landmark at range
``r`` whose rays span ``gamma`` by about ``r delta / gamma`` along its rays, the same way in
every window that sees it so. Fusion by the covariance alone then averages same-signed errors
of the low-parallax windows as if they were independent, and a landmark whose only wide views
are few is pulled outward by many narrow ones. Here every landmark of a window gets the extra
variance ``(r delta / gamma)^2`` along its mean ray (independent between landmarks), added to
its pairs' squared-distance variances: a window that saw a landmark from a wide angle keeps
its weight, a narrow one loses it as the square of the angle. Range and span are geometry (the
bundle's poses and points), ``delta`` an angle: no keyframe count and no bearing-sigma
calibration enters.
"""

from __future__ import annotations

import math

import numpy as np

from ..angles import angle_residual
from ..geometry import direction_span
from .bundle import WindowBundle
from .triangulation import PairEstimates

#: Least span counted (radians): a landmark seen along one line is not infinitely uncertain
#: in a finite window, and the division stays finite.
MIN_SPAN_RAD = math.radians(1.0)


def landmark_geometry(bundle: WindowBundle, bearings_rad: np.ndarray,
                      max_residual_rad: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per landmark of a window: span of its rays' directions on the bundle's poses
    (radians), mean range from those poses (metres) and the unit vector of its mean ray,
    shapes ``(k,)``, ``(k,)``, ``(k, 2)``. Rays whose residual at the bundle's solution
    exceeds ``max_residual_rad`` (the outliers it dropped) are not counted."""
    brg = np.asarray(bearings_rad, float)[:, bundle.column]
    k, lm = np.nonzero(np.isfinite(brg))
    d = bundle.points_xy[lm] - bundle.poses[k, :2]
    toward = np.arctan2(d[:, 1], d[:, 0])
    direction = bundle.poses[k, 2] + brg[k, lm]
    ok = np.abs(angle_residual(toward, direction)) <= max_residual_rad
    k, lm, d, direction = k[ok], lm[ok], d[ok], direction[ok]
    n = len(bundle)
    span = direction_span(direction, lm, n)
    count = np.maximum(np.bincount(lm, minlength=n), 1)
    rng = np.bincount(lm, np.hypot(d[:, 0], d[:, 1]), n) / count
    ux = np.bincount(lm, np.cos(direction), n)
    uy = np.bincount(lm, np.sin(direction), n)
    norm = np.maximum(np.hypot(ux, uy), 1e-300)
    return span, rng, np.column_stack([ux / norm, uy / norm])


def heading_bias_pairs(pairs: PairEstimates, bundle: WindowBundle, bearings_rad: np.ndarray,
                       heading_bias_rad: float, max_residual_rad: float) -> PairEstimates:
    """``pairs`` (:func:`.bundle.bundle_pair_squared_distances` of ``bundle``) with each
    landmark's systematic depth variance ``(r delta / max(gamma, MIN_SPAN_RAD))^2`` along its
    mean ray added: ``var(d^2) += 4 (e.u_i)^2 s_i^2 + 4 (e.u_j)^2 s_j^2``, ``e = p_i - p_j``.

    Parameters
    ----------
    bearings_rad : array of shape (W, n)
        The window's bearing matrix (the bundle's ``column`` indexes it).
    heading_bias_rad : float
        ``delta``: the systematic heading error across a window (radians).
    max_residual_rad : float
        Rays further than this from the bundle's solution are outliers, not geometry.
    """
    span, rng, u = landmark_geometry(bundle, bearings_rad, max_residual_rad)
    s2 = (rng * heading_bias_rad / np.maximum(span, MIN_SPAN_RAD)) ** 2
    e = bundle.points_xy[pairs.first] - bundle.points_xy[pairs.second]
    ei = np.einsum("pa,pa->p", e, u[pairs.first])
    ej = np.einsum("pa,pa->p", e, u[pairs.second])
    extra = 4.0 * (ei * ei * s2[pairs.first] + ej * ej * s2[pairs.second])
    return PairEstimates(pairs.first, pairs.second, pairs.squared_distance_m2,
                         pairs.variance_m4 + extra, None)


__all__ = ["MIN_SPAN_RAD", "heading_bias_pairs", "landmark_geometry"]
