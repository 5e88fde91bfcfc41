"""Sequential triangulation (paper section III-B, eq. 1-2) with degenerate-geometry gates.

Between two consecutive poses the robot reads odometry ``[dx, dy, dpsi]`` (the motion from pose
``t-1`` to pose ``t`` in the frame of pose ``t-1``) and a bearing to every landmark in view at
both steps. In the frame of pose ``t-1`` each landmark lies on two rays:

* ray 1 from the origin in direction ``a = theta_{t-1}``;
* ray 2 from ``o = (dx, dy)`` in direction ``b = dpsi + theta_t``.

Their intersection ``p = r1 [cos a, sin a] = o + r2 [cos b, sin b]`` has the signed depths

    r1 = (dx sin b - dy cos b) / sin(b - a),      r2 = (dx sin a - dy cos a) / sin(b - a).

With the paper's move-then-turn odometry ``[l, 0, phi]`` this is eq. 1,
``r1 = l sin(phi + theta_t) / sin(phi + theta_t - theta_{t-1})``.

For every pair of landmarks triangulated in the same step the instantaneous squared distance
``|p_i - p_j|^2`` is independent of the local frame; its first-order variance is
``J Sigma J^T`` (eq. 2) over the seven measurements involved
``[dx, dy, dpsi, theta_{i,t-1}, theta_{i,t}, theta_{j,t-1}, theta_{j,t}]`` with independent
odometry components (the step's sigmas) and bearings (``bearing_sigma_rad``). The Jacobians
are analytic and everything is vectorised over the landmarks and pairs of a step.

Gates (:func:`gate_points`, all configurable): a landmark is used only if the angle between its
two rays lies in ``[min_parallax, pi - min_parallax]`` (eq. 1 blows up at zero parallax, and at
``pi`` the rays are antiparallel), both depths are positive (the point is in front of both
rays), both depths are at most ``max_range_m`` (e.g. a multiple of the sensor range) and the
relative first-order std. dev. of its depth ``sigma_r1 / r1`` is at most
``max_relative_range_sigma``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..angles import wrap_angle
from ..errors import ConfigError

#: Column order of the per-landmark Jacobians.
POINT_MEASUREMENTS = ("dx_m", "dy_m", "dpsi_rad", "theta_prev_rad", "theta_now_rad")
#: Column order of the per-pair Jacobians.
PAIR_MEASUREMENTS = ("dx_m", "dy_m", "dpsi_rad", "theta_i_prev_rad", "theta_i_now_rad",
                     "theta_j_prev_rad", "theta_j_now_rad")

_TRIU_CACHE: dict[int, tuple[np.ndarray, np.ndarray]] = {}


def pair_indices(k: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.triu_indices(k, 1)`` (cached; read-only arrays): all pairs ``first < second``."""
    hit = _TRIU_CACHE.get(k)
    if hit is None:
        i, j = np.triu_indices(k, 1)
        i.setflags(write=False)
        j.setflags(write=False)
        hit = _TRIU_CACHE[k] = (i, j)
    return hit


@dataclass(frozen=True, eq=False)
class RayTriangulation:
    """Landmarks triangulated from two consecutive poses, in the frame of pose ``t-1``.

    Attributes
    ----------
    points_xy : ndarray of shape (k, 2)
        Intersections of the two rays (metres, frame of pose ``t-1``); inf/NaN where the rays
        are parallel.
    range_prev_m : ndarray of shape (k,)
        Signed depth ``r1`` along ray 1 (distance from pose ``t-1`` when positive).
    range_now_m : ndarray of shape (k,)
        Signed depth ``r2`` along ray 2 (distance from pose ``t`` when positive).
    parallax_rad : ndarray of shape (k,)
        Angle between the two rays, in ``[0, pi]``.
    jacobian : ndarray of shape (k, 2, 5)
        ``d points_xy / d [dx, dy, dpsi, theta_prev, theta_now]``.
    ray_prev : ndarray of shape (k, 2)
        Unit direction of ray 1.
    ray_now : ndarray of shape (k, 2)
        Unit direction of ray 2.
    """

    points_xy: np.ndarray
    range_prev_m: np.ndarray
    range_now_m: np.ndarray
    parallax_rad: np.ndarray
    jacobian: np.ndarray
    ray_prev: np.ndarray
    ray_now: np.ndarray

    def __len__(self) -> int:
        return len(self.points_xy)

    def subset(self, mask: np.ndarray) -> "RayTriangulation":
        """The landmarks selected by a boolean mask or an index array."""
        return RayTriangulation(self.points_xy[mask], self.range_prev_m[mask],
                                self.range_now_m[mask], self.parallax_rad[mask],
                                self.jacobian[mask], self.ray_prev[mask], self.ray_now[mask])


def triangulate_rays(odom: ArrayLike, bearing_prev_rad: ArrayLike,
                     bearing_now_rad: ArrayLike) -> RayTriangulation:
    """Intersect the two bearing rays of each landmark (general odometry, eq. 1).

    Parameters
    ----------
    odom : array of shape (3,)
        ``[dx_m, dy_m, dpsi_rad]`` from pose ``t-1`` to pose ``t`` in the frame of ``t-1``.
    bearing_prev_rad, bearing_now_rad : arrays of shape (k,)
        Bearings of the same ``k`` landmarks at ``t-1`` and at ``t`` (relative to the heading).

    Returns
    -------
    RayTriangulation
        Points, signed depths, parallax and the analytic Jacobian. Parallel rays give
        non-finite values (gate them with :func:`gate_points`); nothing raises.
    """
    dx, dy, dpsi = (float(v) for v in np.asarray(odom, dtype=float).reshape(3))
    a = np.asarray(bearing_prev_rad, dtype=float).reshape(-1)
    b = dpsi + np.asarray(bearing_now_rad, dtype=float).reshape(-1)
    if a.shape != b.shape:
        raise ConfigError(f"triangulate_rays: {a.size} bearings at t-1 but {b.size} at t")
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    s = sb * ca - cb * sa          # sin(b - a)
    c = cb * ca + sb * sa          # cos(b - a)
    n1 = dx * sb - dy * cb
    n2 = dx * sa - dy * ca
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_s = 1.0 / s
        r1 = n1 * inv_s
        r2 = n2 * inv_s
        dr1_db = (dx * cb + dy * sb - r1 * c) * inv_s
        dr1_da = r1 * c * inv_s
        k = a.size
        dr1 = np.empty((k, 5))
        dr1[:, 0] = sb * inv_s
        dr1[:, 1] = -cb * inv_s
        dr1[:, 2] = dr1_db
        dr1[:, 3] = dr1_da
        dr1[:, 4] = dr1_db
        jac = np.empty((k, 2, 5))
        jac[:, 0, :] = ca[:, None] * dr1
        jac[:, 1, :] = sa[:, None] * dr1
        jac[:, 0, 3] -= r1 * sa
        jac[:, 1, 3] += r1 * ca
        pts = np.empty((k, 2))
        pts[:, 0] = r1 * ca
        pts[:, 1] = r1 * sa
    parallax = np.abs(wrap_angle(b - a))
    return RayTriangulation(pts, r1, r2, parallax, jac, np.column_stack([ca, sa]),
                            np.column_stack([cb, sb]))


def odometry_covariance(odometry: ArrayLike) -> np.ndarray:
    """A ``(3, 3)`` odometry covariance from std. devs. ``(3,)`` (independent components) or
    from a ``(3, 3)`` covariance (returned as a float array)."""
    o = np.asarray(odometry, dtype=float)
    if o.shape == (3,):
        return np.diag(o * o)
    if o.shape == (3, 3):
        return o
    raise ConfigError(f"odometry uncertainty must be 3 sigmas or a 3x3 covariance, got shape "
                      f"{o.shape}")


def compose_odometry(odoms: ArrayLike, sigmas: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Chain ``K`` odometry increments into one, with its first-order covariance.

    Parameters
    ----------
    odoms : array of shape (K, 3)
        Increments ``[dx_m, dy_m, dpsi_rad]`` of consecutive steps.
    sigmas : array of shape (K, 3)
        Their independent std. devs.

    Returns
    -------
    increment : ndarray of shape (3,)
        The motion from the first pose to the last, in the frame of the first (heading not
        wrapped: it is only used through sines and cosines).
    covariance : ndarray of shape (3, 3)
    """
    u = np.asarray(odoms, dtype=float).reshape(-1, 3)
    sig = np.asarray(sigmas, dtype=float).reshape(-1, 3)
    psi = np.concatenate([[0.0], np.cumsum(u[:, 2])])
    c, s = np.cos(psi[:-1]), np.sin(psi[:-1])
    step = np.column_stack([c * u[:, 0] - s * u[:, 1], s * u[:, 0] + c * u[:, 1]])
    xy = np.concatenate([np.zeros((1, 2)), np.cumsum(step, axis=0)])
    k = len(u)
    lever = xy[-1] - xy[1:]                       # (K, 2): end minus pose after motion k
    jac = np.zeros((3, 3 * k))
    jac[0, 0::3], jac[0, 1::3], jac[0, 2::3] = c, -s, -lever[:, 1]
    jac[1, 0::3], jac[1, 1::3], jac[1, 2::3] = s, c, lever[:, 0]
    jac[2, 2::3] = 1.0
    jw = jac * sig.reshape(-1)
    return np.array([xy[-1, 0], xy[-1, 1], psi[-1]]), jw @ jw.T


def _covariance_5(odometry: ArrayLike, bearing_sigma_rad: float) -> np.ndarray:
    """Covariance ``(5, 5)`` of ``[dx, dy, dpsi, theta_prev, theta_now]``."""
    cov = np.zeros((5, 5))
    cov[:3, :3] = odometry_covariance(odometry)
    cov[3, 3] = cov[4, 4] = bearing_sigma_rad ** 2
    return cov


def point_covariance(tri: RayTriangulation, odometry: ArrayLike,
                     bearing_sigma_rad: float) -> np.ndarray:
    """First-order covariance ``J Sigma J^T`` of each triangulated point, shape ``(k, 2, 2)``.

    ``odometry`` is the odometry's 3 std. devs. or its 3x3 covariance. The points of one step
    share the odometry, so they are correlated with each other; this is each point's own
    (marginal) covariance, in the frame of pose ``t-1`` (m^2).
    """
    cov = _covariance_5(odometry, bearing_sigma_rad)
    with np.errstate(invalid="ignore", over="ignore"):
        return np.einsum("kaz,zy,kby->kab", tri.jacobian, cov, tri.jacobian)


def range_jacobians(tri: RayTriangulation) -> tuple[np.ndarray, np.ndarray]:
    """``d r1 / dz`` and ``d r2 / dz`` over ``[dx, dy, dpsi, theta_prev, theta_now]``, (k, 5) each.

    ``r1 = u_a . p`` (since ``du_a`` is normal to ``u_a``) and ``r2 = u_b . (p - o)``.
    """
    j1 = np.einsum("ka,kaz->kz", tri.ray_prev, tri.jacobian)
    j2 = np.einsum("ka,kaz->kz", tri.ray_now, tri.jacobian)
    j2[:, 0] -= tri.ray_now[:, 0]
    j2[:, 1] -= tri.ray_now[:, 1]
    return j1, j2


def range_variances(tri: RayTriangulation, odometry: ArrayLike,
                    bearing_sigma_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """First-order variances (m^2) of the depths ``r1`` (from pose t-1) and ``r2`` (from t).

    ``odometry`` is the odometry's 3 std. devs. or its 3x3 covariance.
    """
    cov = _covariance_5(odometry, bearing_sigma_rad)
    with np.errstate(invalid="ignore", over="ignore"):
        j1, j2 = range_jacobians(tri)
        return (np.einsum("kz,zy,ky->k", j1, cov, j1),
                np.einsum("kz,zy,ky->k", j2, cov, j2))


def gate_points(tri: RayTriangulation, range_var_m2: np.ndarray | None = None, *,
                min_parallax_rad: float = 0.0, max_range_m: float = np.inf,
                max_relative_range_sigma: float = np.inf) -> np.ndarray:
    """Which triangulated landmarks are usable (see the module docstring).

    Parameters
    ----------
    tri : RayTriangulation
    range_var_m2 : array of shape (k,), optional
        Variance of ``r1`` (from :func:`range_variances`); needed for the relative gate.
    min_parallax_rad : float
        Least angle between the two rays (and least distance of that angle from ``pi``).
    max_range_m : float
        Largest allowed depth along either ray.
    max_relative_range_sigma : float
        Largest allowed ``sqrt(var r1) / r1``.

    Returns
    -------
    ndarray of shape (k,), bool
    """
    par = tri.parallax_rad
    with np.errstate(invalid="ignore"):
        ok = (par >= min_parallax_rad) & (par <= np.pi - min_parallax_rad) & (par > 0)
        ok &= (tri.range_prev_m > 0) & (tri.range_now_m > 0)
        ok &= (tri.range_prev_m <= max_range_m) & (tri.range_now_m <= max_range_m)
        if np.isfinite(max_relative_range_sigma):
            if range_var_m2 is None:
                raise ConfigError("gate_points: the relative range gate needs range_var_m2")
            ok &= range_var_m2 <= (max_relative_range_sigma * tri.range_prev_m) ** 2
    return ok


@dataclass(frozen=True, eq=False)
class PairEstimates:
    """Instantaneous squared distances of all pairs of one step's triangulated landmarks.

    Attributes
    ----------
    first, second : ndarray of shape (P,), int64
        Indices into the step's landmarks (``first < second``).
    squared_distance_m2 : ndarray of shape (P,)
        ``|p_i - p_j|^2``.
    variance_m4 : ndarray of shape (P,)
        First-order variance ``J Sigma J^T`` of the squared distance (eq. 2).
    offset_trace_m2 : ndarray of shape (P,)
        ``trace Cov(p_i - p_j)``: the first-order bias of ``|p_i - p_j|^2``.
    translation_variance_m4 : ndarray of shape (P,)
        The part of ``variance_m4`` due to the odometry translation ``(dx, dy)`` alone (it
        scales like ``d^2`` under a change of scale; the rest, from the bearings and the
        turn, like ``d^4`` for the distance's variance).
    jacobian : ndarray of shape (P, 7) or None
        ``d |p_i - p_j|^2 / d [dx, dy, dpsi, theta_i_prev, theta_i_now, theta_j_prev,
        theta_j_now]`` (only when asked for).
    """

    first: np.ndarray
    second: np.ndarray
    squared_distance_m2: np.ndarray
    variance_m4: np.ndarray
    offset_trace_m2: np.ndarray
    translation_variance_m4: np.ndarray
    jacobian: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.first)


def pair_squared_distances(tri: RayTriangulation, odometry: ArrayLike,
                           bearing_sigma_rad: float, *,
                           with_jacobian: bool = False) -> PairEstimates:
    """Squared distance and its first-order variance for every pair of ``tri``'s landmarks.

    Parameters
    ----------
    tri : RayTriangulation
        The (gated) landmarks of one step, ``k`` of them.
    odometry : array of shape (3,) or (3, 3)
        Std. devs. of ``[dx_m, dy_m, dpsi_rad]`` for this step, or their covariance (e.g.
        from :func:`compose_odometry` for a baseline of several steps).
    bearing_sigma_rad : float
    with_jacobian : bool
        Also return the ``(P, 7)`` Jacobian (tests; the variance never needs it).

    Returns
    -------
    PairEstimates
        ``P = k (k - 1) / 2`` pairs, in ``np.triu_indices(k, 1)`` order.
    """
    first, second = pair_indices(len(tri))
    cov_odo = odometry_covariance(odometry)
    sb2 = float(bearing_sigma_rad) ** 2
    p = tri.points_xy
    jac = tri.jacobian
    e = p[first] - p[second]                                   # (P, 2)
    d2 = np.einsum("pa,pa->p", e, e)
    ji = jac[first]
    jj = jac[second]
    # d e / d odometry (shared by both landmarks) and / d own bearings.
    de_odo = ji[:, :, :3] - jj[:, :, :3]                        # (P, 2, 3)
    g_odo = 2.0 * np.einsum("pa,paz->pz", e, de_odo)            # (P, 3)
    g_i = 2.0 * np.einsum("pa,paz->pz", e, ji[:, :, 3:])        # (P, 2)
    g_j = -2.0 * np.einsum("pa,paz->pz", e, jj[:, :, 3:])       # (P, 2)
    var = np.einsum("pz,zy,py->p", g_odo, cov_odo, g_odo) \
        + sb2 * (np.einsum("pz,pz->p", g_i, g_i) + np.einsum("pz,pz->p", g_j, g_j))
    trace = (np.einsum("paz,zy,pay->p", de_odo, cov_odo, de_odo)
             + sb2 * (np.einsum("paz,paz->p", ji[:, :, 3:], ji[:, :, 3:])
                      + np.einsum("paz,paz->p", jj[:, :, 3:], jj[:, :, 3:])))
    g_t = g_odo[:, :2]
    tvar = np.einsum("pz,zy,py->p", g_t, cov_odo[:2, :2], g_t)
    full = np.concatenate([g_odo, g_i, g_j], axis=1) if with_jacobian else None
    return PairEstimates(first.astype(np.int64), second.astype(np.int64), d2, var, trace, tvar,
                         full)


__all__ = ["POINT_MEASUREMENTS", "PAIR_MEASUREMENTS", "RayTriangulation", "PairEstimates",
           "pair_indices", "triangulate_rays", "odometry_covariance", "compose_odometry",
           "point_covariance",
           "range_jacobians", "range_variances", "gate_points", "pair_squared_distances"]
