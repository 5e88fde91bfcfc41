"""Window pair estimates that disagree with the other windows of their pair (``fuse_outlier_sigma``).

Inverse-variance fusion (III-C) trusts each window's first-order variance. A window bundle can
land in a wrong minimum that its covariance does not know about: a distant landmark seen from
three poses in a turn slides onto the robot's path, where a bearing-only point looks well
determined, and its pair estimates carry a small variance and a distance metres off. Every
pair seen by several windows has a majority to test a window against: an estimate whose
deviation from the median of its pair's estimates exceeds ``k`` of its own std. devs. is left
out of the fusion. A test in the estimates' own units: no count of keyframes and no
bearing-sigma calibration enters it beyond the variances themselves.
"""

from __future__ import annotations

import numpy as np

#: Fewest estimates of a pair for a median to test them against.
MIN_ESTIMATES = 3


def consistent_estimates(first: np.ndarray, second: np.ndarray, squared_distance_m2: np.ndarray,
                         variance_m4: np.ndarray, k: float) -> np.ndarray:
    """Mask of the pair estimates within ``k`` std. devs. of their pair's median.

    Parameters
    ----------
    first, second : int arrays of shape (P,)
        Landmark indices of each estimate (either order).
    squared_distance_m2, variance_m4 : arrays of shape (P,)
        The estimates (every window's, in any order) and their variances.
    k : float
        Largest ``|d2 - median| / sqrt(var)`` kept. Pairs with fewer than
        :data:`MIN_ESTIMATES` estimates keep them all.

    Returns
    -------
    ndarray of shape (P,), bool
    """
    d2 = np.asarray(squared_distance_m2, float)
    var = np.asarray(variance_m4, float)
    keep = np.ones(d2.size, bool)
    if d2.size == 0:
        return keep
    lo, hi = np.minimum(first, second), np.maximum(first, second)
    order = np.lexsort((d2, hi, lo))               # by pair, then by value
    lo_s, hi_s, d_s = lo[order], hi[order], d2[order]
    start = np.flatnonzero(np.r_[True, (lo_s[1:] != lo_s[:-1]) | (hi_s[1:] != hi_s[:-1])])
    count = np.diff(np.r_[start, d2.size])
    group = np.repeat(np.arange(start.size), count)
    # the median of each pair's sorted values
    mid_lo = start + (count - 1) // 2
    mid_hi = start + count // 2
    median = 0.5 * (d_s[mid_lo] + d_s[mid_hi])
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.abs(d_s - median[group]) / np.sqrt(var[order])
    bad = (count[group] >= MIN_ESTIMATES) & ~(z <= k)
    keep[order[bad]] = False
    return keep


__all__ = ["MIN_ESTIMATES", "consistent_estimates"]
