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

Windowed triangulation (:func:`triangulate_window`, :func:`window_pair_squared_distances`,
issue 8). A window holds ``W`` consecutive poses and the ``W - 1`` odometry increments between
them. Every landmark seen from at least two of its poses is triangulated from the pair of its
rays furthest apart in the window (the longest baseline), if that pair passes the gates, in the frame of the window's first pose
(dead-reckoned from the increments). Two landmarks triangulated in the same window share the
odometry chain, so the first-order variance of their squared distance is taken over all
``3 (W - 1)`` increments (each with its own independent sigmas) and the four bearings used.
The Jacobians are analytic (complex plane): with ``p = z_a + r1 u_a`` the intersection of the
rays from poses ``a < b`` (positions ``z``, directions ``u = exp(i alpha)``), an increment
``m`` (pose ``m-1`` to ``m``) moves the point rigidly (translation, or rotation about ``z_m``)
when ``m <= a``, moves only the second ray when ``a < m <= b``, and does nothing after ``b``.
With ``W = 2`` this is exactly eq. 1-2 above.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..angles import angle_residual
from ..errors import ConfigError
from ..geometry import effective_parallax

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


class _TwoRayResult:
    """What the two-ray triangulation results share: length and parallax."""

    points_xy: np.ndarray
    sin_parallax: np.ndarray
    cos_parallax: np.ndarray

    def __len__(self) -> int:
        return len(self.points_xy)

    @property
    def parallax_rad(self) -> np.ndarray:
        """Angle between the two rays used, in ``[0, pi]``."""
        return np.abs(np.arctan2(self.sin_parallax, self.cos_parallax))


@dataclass(frozen=True, eq=False)
class RayTriangulation(_TwoRayResult):
    """Landmarks triangulated from two poses, in the frame of the first (pose ``t-1``).

    Attributes
    ----------
    points_xy : ndarray of shape (k, 2)
        Intersections of the two rays (metres, frame of pose ``t-1``); inf/NaN where the rays
        are parallel.
    range_prev_m : ndarray of shape (k,)
        Signed depth ``r1`` along ray 1 (distance from pose ``t-1`` when positive).
    range_now_m : ndarray of shape (k,)
        Signed depth ``r2`` along ray 2 (distance from pose ``t`` when positive).
    sin_parallax, cos_parallax : ndarrays of shape (k,)
        ``sin(b - a)`` and ``cos(b - a)`` of the angle from ray 1 to ray 2.
    range_jacobian : ndarray of shape (k, 5)
        ``d r1 / d [dx, dy, dpsi, theta_prev, theta_now]``.
    ray_prev : ndarray of shape (k, 2)
        Unit direction ``u_a`` of ray 1.
    ray_now : ndarray of shape (k, 2)
        Unit direction ``u_b`` of ray 2.
    jacobian_complex : ndarray of shape (k, 5), complex
        ``d (x + i y) / d [dx, dy, dpsi, theta_prev, theta_now]``: the point Jacobian with the
        plane written as complex numbers (``jacobian`` gives it as real ``(k, 2, 5)``).
    """

    points_xy: np.ndarray
    range_prev_m: np.ndarray
    range_now_m: np.ndarray
    sin_parallax: np.ndarray
    cos_parallax: np.ndarray
    range_jacobian: np.ndarray
    ray_prev: np.ndarray
    ray_now: np.ndarray
    jacobian_complex: np.ndarray


    @property
    def jacobian(self) -> np.ndarray:
        """``d points_xy / d [dx, dy, dpsi, theta_prev, theta_now]``, shape ``(k, 2, 5)``.

        ``p = r1 u_a`` so ``dp = u_a dr1 + r1 u_a_perp da``.
        """
        return np.stack([self.jacobian_complex.real, self.jacobian_complex.imag], axis=1)

    def subset(self, mask: np.ndarray) -> "RayTriangulation":
        """The landmarks selected by a boolean mask or an index array."""
        return RayTriangulation(self.points_xy[mask], self.range_prev_m[mask],
                                self.range_now_m[mask], self.sin_parallax[mask],
                                self.cos_parallax[mask], self.range_jacobian[mask],
                                self.ray_prev[mask], self.ray_now[mask],
                                self.jacobian_complex[mask])


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
        Points, signed depths, parallax and the analytic Jacobian of the depth. Parallel rays
        give non-finite values (gate them with :func:`gate_points`); nothing raises.
    """
    u = np.asarray(odom, dtype=float).reshape(3)
    dx, dy, dpsi = float(u[0]), float(u[1]), float(u[2])
    a = np.asarray(bearing_prev_rad, dtype=float).reshape(-1)
    b = np.asarray(bearing_now_rad, dtype=float).reshape(-1)
    if a.shape != b.shape:
        raise ConfigError(f"triangulate_rays: {a.size} bearings at t-1 but {b.size} at t")
    k = a.size
    # Plane vectors as complex numbers (few, vectorised operations): u = exp(i angle),
    # u_b conj(u_a) = cos(b - a) + i sin(b - a), and Im(conj(o) u) = o x u.
    unit = np.exp(1j * np.concatenate((a, b + dpsi)))
    ua, ub = unit[:k], unit[k:]
    rel = ub * ua.conj()
    s, c = rel.imag, rel.real                    # sin(b - a), cos(b - a)
    o_conj = complex(dx, -dy)
    ob = ub * o_conj                             # Im: dx sb - dy cb ; Re: dx cb + dy sb
    # dp/dz = u_a (d r1/dz + i r1 [z = theta_prev]) as a complex number; its real factor is dr1
    jac = np.zeros((k, 5), np.complex128)
    dr1 = jac.real
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        inv_s = 1.0 / s
        r1 = ob.imag * inv_s
        r2 = (ua * o_conj).imag * inv_s
        np.multiply(ub.imag, inv_s, out=dr1[:, 0])                   # d r1 / d dx
        np.multiply(ub.real, -inv_s, out=dr1[:, 1])                  # d r1 / d dy
        np.multiply(ob.real - r1 * c, inv_s, out=dr1[:, 2])          # d r1 / d b (= dpsi)
        np.multiply(r1 * c, inv_s, out=dr1[:, 3])                    # d r1 / d a
        dr1[:, 4] = dr1[:, 2]                                        # b = dpsi + theta_now
        dr1 = dr1.copy()
        jac.imag[:, 3] = r1
        jac *= ua[:, None]
        pts = ua * r1
    return RayTriangulation(pts.view(np.float64).reshape(k, 2), r1, r2, s, c, dr1,
                            ua.view(np.float64).reshape(k, 2), ub.view(np.float64).reshape(k, 2),
                            jac)


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

    ``r1`` is computed directly; ``r2 = u_b . (p - o)``, and ``(p - o) . du_b = 0`` because
    ``p - o`` is parallel to ``u_b``.
    """
    j1 = tri.range_jacobian.copy()
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
    # parallax in [min, pi - min]  <=>  sin(parallax) >= sin(min) (and > 0)
    sin_par = np.abs(tri.sin_parallax)
    with np.errstate(invalid="ignore"):
        ok = sin_par >= max(math.sin(min_parallax_rad), 1e-15)
        r1, r2 = tri.range_prev_m, tri.range_now_m
        ok &= (r1 > 0) & (r2 > 0) & (r1 <= max_range_m) & (r2 <= max_range_m)
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
    translation_variance_m4 : ndarray of shape (P,) or None
        (When asked for.) The part of ``variance_m4`` due to the odometry translation
        ``(dx, dy)`` alone (it
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
    translation_variance_m4: np.ndarray | None = None
    jacobian: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.first)


def pair_squared_distances(tri: RayTriangulation, odometry: ArrayLike,
                           bearing_sigma_rad: float, *, select: np.ndarray | None = None,
                           with_translation: bool = False,
                           with_jacobian: bool = False) -> PairEstimates:
    """Squared distance and its first-order variance for every pair of ``tri``'s landmarks.

    Parameters
    ----------
    tri : RayTriangulation
        The landmarks of one step, ``k`` of them.
    odometry : array of shape (3,) or (3, 3)
        Std. devs. of ``[dx_m, dy_m, dpsi_rad]`` for this step, or their covariance (e.g.
        from :func:`compose_odometry` for a baseline of several steps).
    bearing_sigma_rad : float
    select : array of int, optional
        Only pairs among these landmarks (e.g. those that passed :func:`gate_points`).
    with_translation : bool
        Also return the part of the variance due to the odometry translation.
    with_jacobian : bool
        Also return the ``(P, 7)`` Jacobian (tests; the variance never needs it).

    Returns
    -------
    PairEstimates
        The pairs ``(first, second)`` index ``tri``; in ``np.triu_indices`` order of ``select``.
    """
    if select is None:
        first, second = pair_indices(len(tri))
    else:
        f, g = pair_indices(len(select))
        first, second = select[f], select[g]
    unc = np.asarray(odometry, dtype=float)
    sb2 = float(bearing_sigma_rad) ** 2
    # e . dp/dz = Re(e conj(dp/dz)) for the offset e = p_i - p_j (complex plane)
    pts = np.ascontiguousarray(tri.points_xy).view(np.complex128)[:, 0]
    jac_conj = tri.jacobian_complex.conj()                      # (k, 5)
    e = pts[first] - pts[second]
    d2 = (e * e.conj()).real
    gi = (e[:, None] * jac_conj[first]).real                    # e . dp_i/dz, (P, 5)
    gj = (e[:, None] * jac_conj[second]).real                   # e . dp_j/dz
    # d |e|^2 / dz = 2 e . de/dz: the odometry moves both points, each bearing one of them
    grad = np.concatenate((gi[:, :3] - gj[:, :3], gi[:, 3:], gj[:, 3:]), axis=1)
    if unc.shape == (3,):                                       # independent components
        var = (grad * grad) @ np.concatenate((4.0 * unc * unc, np.full(4, 4.0 * sb2)))
        cov_odo = np.diag(unc * unc)
    else:
        cov7 = np.zeros((7, 7))
        cov7[:3, :3] = cov_odo = odometry_covariance(unc)
        cov7.flat[24::8] = sb2                                  # the four bearings
        var = 4.0 * ((grad @ cov7) * grad).sum(axis=1)
    tvar = None
    if with_translation:
        g_t = grad[:, :2]
        tvar = 4.0 * ((g_t @ cov_odo[:2, :2]) * g_t).sum(axis=1)
    full = None
    if with_jacobian:
        full = 2.0 * grad
        full[:, 5:] *= -1.0
    return PairEstimates(first, second, d2, var, tvar, full)


@dataclass(frozen=True, eq=False)
class WindowTriangulation(_TwoRayResult):
    """Landmarks triangulated inside a window of ``W`` poses, in the frame of its first pose.

    Attributes
    ----------
    column : ndarray of shape (k,), int64
        Column of each landmark in the ``bearings_rad`` matrix given to
        :func:`triangulate_window`.
    pose_first, pose_second : ndarrays of shape (k,), int64
        Window poses ``a < b`` of the two rays used (the pair with the best parallax).
    points_xy : ndarray of shape (k, 2)
        Intersections (metres, frame of window pose 0).
    range_prev_m, range_now_m : ndarrays of shape (k,)
        Depths ``r1`` from pose ``a`` and ``r2`` from pose ``b``.
    sin_parallax, cos_parallax : ndarrays of shape (k,)
        ``sin`` and ``cos`` of the angle from ray ``a`` to ray ``b``.
    jacobian_odometry : ndarray of shape (k, W - 1, 3), complex
        ``d (x + i y) / d [dx, dy, dpsi]_m`` for the increments ``m = 1 .. W-1``.
    jacobian_bearing : ndarray of shape (k, 2) or (k, W), complex
        ``d (x + i y) / d [theta_a, theta_b]`` (:func:`triangulate_window`), or wrt the
        bearing from every window pose, 0 where not seen (:func:`triangulate_window_lsq`).
    """

    column: np.ndarray
    pose_first: np.ndarray
    pose_second: np.ndarray
    points_xy: np.ndarray
    range_prev_m: np.ndarray
    range_now_m: np.ndarray
    sin_parallax: np.ndarray
    cos_parallax: np.ndarray
    jacobian_odometry: np.ndarray
    jacobian_bearing: np.ndarray



def _ray_intersections(z_a: np.ndarray, z_b: np.ndarray, ua: np.ndarray, ub: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Depths ``r1, r2`` and ``sin, cos`` of the parallax of rays ``z_a + r1 ua``, ``z_b + r2 ub``
    (complex arrays of one shape)."""
    rel = ub * ua.conj()
    s, c = rel.imag, rel.real
    dconj = (z_b - z_a).conj()
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        inv_s = 1.0 / s
        r1 = (dconj * ub).imag * inv_s
        r2 = (dconj * ua).imag * inv_s
    return r1, r2, s, c


def triangulate_window(odoms: ArrayLike, bearings_rad: ArrayLike, *,
                       min_parallax_rad: float = 0.0,
                       max_range_m: float = np.inf) -> tuple[WindowTriangulation, int]:
    """Triangulate every landmark of a window from its best-parallax pair of rays.

    Parameters
    ----------
    odoms : array of shape (W - 1, 3)
        Increments ``[dx_m, dy_m, dpsi_rad]`` between the window's consecutive poses.
    bearings_rad : array of shape (W, n)
        Bearing of landmark (column) ``j`` from window pose ``k``; NaN where not seen.
    min_parallax_rad, max_range_m : float
        The gates of :func:`gate_points` (parallax in ``[min, pi - min]``, both depths
        positive and at most ``max_range_m``), applied to every candidate pair of rays.

    Returns
    -------
    WindowTriangulation
        The landmarks whose pair of rays furthest apart in the window (largest ``b - a``,
        ties: the earliest pair; chosen by which poses saw the landmark, not by the measured
        values) passes the gates, in increasing column order. Choosing by the measured
        parallax, or falling back to another pair when the gates refuse the first choice,
        would pick the pairs whose noise widened the angle: depths biased short (measured:
        Method 2 MPE about 3x worse with the largest measured parallax).
    n_gated : int
        Landmarks seen from two poses or more with no passing pair.
    """
    u = np.asarray(odoms, dtype=float).reshape(-1, 3)
    brg = np.asarray(bearings_rad, dtype=float)
    w = len(u) + 1
    if brg.ndim != 2 or brg.shape[0] != w:
        raise ConfigError(f"triangulate_window: bearings must be ({w}, n) for {w - 1} "
                          f"increments, got shape {brg.shape}")
    psi = np.concatenate([[0.0], np.cumsum(u[:, 2])])
    heading = np.exp(1j * psi)
    z = np.concatenate([[0.0], np.cumsum(heading[:-1] * (u[:, 0] + 1j * u[:, 1]))])
    seen = np.isfinite(brg)
    cand = np.flatnonzero(seen.sum(axis=0) >= 2)
    a_all, b_all = np.triu_indices(w, 1)
    ray = heading[:, None] * np.exp(1j * np.where(seen[:, cand], brg[:, cand], 0.0))
    r1, r2, s, _ = _ray_intersections(z[a_all][:, None], z[b_all][:, None], ray[a_all],
                                      ray[b_all])                    # (pairs of poses, n)
    both = seen[a_all][:, cand] & seen[b_all][:, cand]
    # the pair furthest apart by visibility alone (ties: the earliest), then the gates
    score = np.where(both, (b_all - a_all)[:, None] * float(w)
                     + np.arange(len(a_all))[::-1, None] / len(a_all), -1.0)
    best = np.argmax(score, axis=0)
    at = (best, np.arange(cand.size))
    with np.errstate(invalid="ignore"):
        good = np.abs(s[at]) >= max(math.sin(min_parallax_rad), 1e-15)
        good &= (r1[at] > 0) & (r2[at] > 0) & (r1[at] <= max_range_m) & (r2[at] <= max_range_m)
    col = cand[good]
    pick = best[good]
    a, b = a_all[pick], b_all[pick]
    tri = _window_points(u, psi, z, heading, a, b, brg[a, col], brg[b, col])
    return WindowTriangulation(col, a, b, *tri), int(cand.size - col.size)


def _window_points(u: np.ndarray, psi: np.ndarray, z: np.ndarray, heading: np.ndarray,
                   a: np.ndarray, b: np.ndarray, theta_a: np.ndarray, theta_b: np.ndarray
                   ) -> tuple[np.ndarray, ...]:
    """Points, depths, parallax and analytic Jacobians for rays from poses ``a < b``."""
    k, w1 = a.size, len(u)
    ua = np.exp(1j * (psi[a] + theta_a))
    ub = np.exp(1j * (psi[b] + theta_b))
    za, zb = z[a], z[b]
    r1, r2, s, c = _ray_intersections(za, zb, ua, ub)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        inv_s = 1.0 / s
        p = za + r1 * ua
        d_alpha = ua * (r1 * c * inv_s + 1j * r1)                       # dp / d alpha
        d_beta = ua * (((zb - za).conj() * ub).real - r1 * c) * inv_s   # dp / d beta
        # g(v) = d r1 / d z_b . v = Im(conj(v) ub) / s, for v of shape (k, W-1)
        m = np.arange(1, w1 + 1)
        before = m[None, :] <= a[:, None]
        mid = ~before & (m[None, :] <= b[:, None])
        e = heading[:-1][None, :]                                       # R(psi_{m-1})
        lever_b = zb[:, None] - z[1:][None, :]                          # z_b - z_m

        def second_ray(v: np.ndarray) -> np.ndarray:
            return ua[:, None] * ((v.conj() * ub[:, None]).imag * inv_s[:, None])

        jac = np.zeros((k, w1, 3), np.complex128)
        ex = np.broadcast_to(e, (k, w1))
        jac[:, :, 0] = np.where(before, ex, np.where(mid, second_ray(ex), 0.0))
        jac[:, :, 1] = np.where(before, 1j * ex, np.where(mid, second_ray(1j * ex), 0.0))
        turn_before = 1j * (p[:, None] - z[1:][None, :])
        turn_mid = second_ray(1j * lever_b) + d_beta[:, None]
        jac[:, :, 2] = np.where(before, turn_before, np.where(mid, turn_mid, 0.0))
    pts = np.column_stack([p.real, p.imag])
    return (pts, r1, r2, s, c, jac, np.column_stack([d_alpha, d_beta]))


def _window_chain_jacobians(u: np.ndarray, z: np.ndarray, heading: np.ndarray
                            ) -> tuple[np.ndarray, np.ndarray]:
    """``d z_k / d [dx, dy, dpsi]_m`` (complex, shape ``(W, W-1, 3)``) and ``d psi_k / d ...``
    (real, same shape) of the dead-reckoned window poses ``k`` wrt the increments ``m``."""
    w1 = len(u)
    w = w1 + 1
    k = np.arange(w)[:, None]
    m = np.arange(1, w1 + 1)[None, :]
    upto = m <= k                                                    # increment m moves pose k
    dz = np.zeros((w, w1, 3), np.complex128)
    dz[:, :, 0] = np.where(upto, heading[:-1][None, :], 0.0)
    dz[:, :, 1] = np.where(upto, 1j * heading[:-1][None, :], 0.0)
    dz[:, :, 2] = np.where(upto, 1j * (z[:, None] - z[1:][None, :]), 0.0)
    dpsi = np.zeros((w, w1, 3))
    dpsi[:, :, 2] = upto
    return dz, dpsi


def triangulate_window_lsq(odoms: ArrayLike, bearings_rad: ArrayLike, *,
                           min_parallax_rad: float = 0.0, max_range_m: float = np.inf,
                           max_iter: int = 20, tol_m: float = 1e-13
                           ) -> tuple[WindowTriangulation, int]:
    """Triangulate every landmark of a window from ALL its rays (least squares on the bearings).

    The window's poses are dead-reckoned from its first one (``z_k``, heading ``psi_k``); a
    landmark seen from poses ``K`` is the point ``p`` minimising
    ``sum_{k in K} angle_residual(atan2(p - z_k), psi_k + theta_k)^2`` (maximum likelihood for
    equal, independent bearing noise with the poses held at the odometry chain), started from
    the linear intersection (normals weighted by ``1 / range^2``) and refined by Gauss-Newton.
    The Jacobian of the estimate wrt every increment and every bearing of the landmark comes
    from the stationarity condition ``g = sum_k res_k q_k = 0`` (``q_k`` the gradient of the
    ray's angle) by the implicit function theorem, with the full Hessian
    ``H = sum_k (q_k q_k^T + res_k D q_k)``:
    ``dp = H^-1 sum_k (H_k dz_k + q_k d alpha_k)``, ``alpha_k = psi_k + theta_k``. It is
    exact at the computed optimum (noisy rays included), and with two rays the estimate and its
    Jacobian are those of :func:`triangulate_window`.

    Parameters
    ----------
    odoms : array of shape (W - 1, 3)
        Increments ``[dx_m, dy_m, dpsi_rad]`` between the window's consecutive poses.
    bearings_rad : array of shape (W, n)
        Bearing of landmark (column) ``j`` from window pose ``k``; NaN where not seen.
    min_parallax_rad, max_range_m : float
        Gates: the landmark's :func:`effective_parallax` must be at least ``min_parallax``
        (for two rays: the angle between them in ``[min_parallax, pi - min_parallax]``) and
        the point must be in front of every ray at a depth of at most ``max_range_m``.
    max_iter : int
        Gauss-Newton iterations at most.
    tol_m : float
        Stop when every step is below ``tol_m`` times the point's distance (relative).

    Returns
    -------
    WindowTriangulation
        ``pose_first`` / ``pose_second`` are the first and last poses that saw the landmark,
        ``range_prev_m`` / ``range_now_m`` the depths from them, ``sin_parallax`` /
        ``cos_parallax`` those of the angular span of its rays; ``jacobian_bearing`` has shape
        ``(k, W)``: ``d (x + i y) / d theta`` of the bearing from each window pose (0 where the
        landmark was not seen).
    n_gated : int
        Landmarks seen from two poses or more that failed a gate (or did not converge).
    """
    u = np.asarray(odoms, dtype=float).reshape(-1, 3)
    brg = np.asarray(bearings_rad, dtype=float)
    w = len(u) + 1
    if brg.ndim != 2 or brg.shape[0] != w:
        raise ConfigError(f"triangulate_window_lsq: bearings must be ({w}, n) for {w - 1} "
                          f"increments, got shape {brg.shape}")
    psi = np.concatenate([[0.0], np.cumsum(u[:, 2])])
    heading = np.exp(1j * psi)
    z = np.concatenate([[0.0], np.cumsum(heading[:-1] * (u[:, 0] + 1j * u[:, 1]))])
    seen = np.isfinite(brg)
    cand = np.flatnonzero(seen.sum(axis=0) >= 2)
    nc = cand.size
    # the rays, grouped by landmark (owner-major order), poses increasing within a landmark
    owner, pose = np.nonzero(seen[:, cand].T)
    start = np.flatnonzero(np.r_[True, owner[1:] != owner[:-1]]) if owner.size else \
        np.zeros(0, np.int64)
    alpha = psi[pose] + brg[pose, cand[owner]]
    ray = np.exp(1j * alpha)
    zr = z[pose]

    def bsum(x: np.ndarray) -> np.ndarray:
        return np.add.reduceat(x, start, axis=0) if x.size else np.zeros((0,) + x.shape[1:])

    # linear intersection: sum w (I - u u^T)(p - z) = 0, first unweighted, then w = 1 / r^2
    nxx, nxy, nyy = ray.imag ** 2, -ray.real * ray.imag, ray.real ** 2
    wgt = np.ones(owner.size)
    p = np.full(nc, np.nan + 0j)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for _ in range(2):
            axx, axy, ayy = bsum(wgt * nxx), bsum(wgt * nxy), bsum(wgt * nyy)
            bx = bsum(wgt * (nxx * zr.real + nxy * zr.imag))
            by = bsum(wgt * (nxy * zr.real + nyy * zr.imag))
            det = axx * ayy - axy * axy
            p = ((ayy * bx - axy * by) + 1j * (axx * by - axy * bx)) / det
            wgt = 1.0 / np.maximum(np.abs(p[owner] - zr) ** 2, 1e-12)
        # Gauss-Newton on the bearing residuals
        done = ~np.isfinite(p)
        for _ in range(max_iter):
            d = p[owner] - zr
            rho2 = (d * d.conj()).real
            q = 1j * d / rho2                               # gradient of the ray's angle
            res = angle_residual(np.angle(d), alpha)
            nxx, nxy, nyy = bsum(q.real ** 2), bsum(q.real * q.imag), bsum(q.imag ** 2)
            gx, gy = bsum(res * q.real), bsum(res * q.imag)
            det = nxx * nyy - nxy * nxy
            step = -((nyy * gx - nxy * gy) + 1j * (nxx * gy - nxy * gx)) / det
            step[done] = 0.0
            p = p + step
            small = np.abs(step) <= tol_m * np.maximum(np.abs(p), 1.0)
            done |= small | ~np.isfinite(step)
            if done.all():
                break
        # gates: parallax of the ray directions, in front of every ray, depth
        d = p[owner] - zr
        span = effective_parallax(alpha, owner, nc)
        depth = (d * ray.conj()).real
        bad_ray = ~((depth > 0) & (depth <= max_range_m))
        good = np.isfinite(p) & (np.add.reduceat(bad_ray.astype(np.int64), start) == 0 if nc
                                 else np.zeros(0, bool))
        lo = max(min_parallax_rad, 1e-15)
        good &= span >= lo
        converged = small if max_iter > 0 else np.ones(nc, bool)
        good &= converged
    keep = good[owner]
    # Jacobians at the optimum (implicit function theorem), rays of the kept landmarks only
    kept = np.flatnonzero(good)
    remap = np.full(nc, -1, np.int64)
    remap[kept] = np.arange(kept.size)
    o, k_pose, d, a_ray = remap[owner[keep]], pose[keep], d[keep], alpha[keep]
    st = np.flatnonzero(np.r_[True, o[1:] != o[:-1]]) if o.size else np.zeros(0, np.int64)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        rho2 = (d * d.conj()).real
        q = 1j * d / rho2
        res = angle_residual(np.angle(d), a_ray)
        x, y = d.real, d.imag
        rho4 = rho2 * rho2
        hk = np.empty((o.size, 2, 2))                       # per ray: q q^T + res D q
        hk[:, 0, 0] = q.real ** 2 + res * 2 * x * y / rho4
        hk[:, 1, 1] = q.imag ** 2 - res * 2 * x * y / rho4
        hk[:, 0, 1] = hk[:, 1, 0] = q.real * q.imag + res * (y * y - x * x) / rho4
        h = np.add.reduceat(hk, st, axis=0) if o.size else np.zeros((0, 2, 2))
        hinv = np.linalg.inv(h) if len(h) else h
        dz, dpsi = _window_chain_jacobians(u, z, heading)
        c = 3 * (w - 1)
        dz_r = np.stack([dz.real.reshape(w, c), dz.imag.reshape(w, c)], axis=1)  # (W, 2, C)
        qv = np.column_stack([q.real, q.imag])
        m_ray = hk @ dz_r[k_pose] + qv[:, :, None] * dpsi.reshape(w, c)[k_pose][:, None, :]
        m_sum = np.add.reduceat(m_ray, st, axis=0) if o.size else np.zeros((0, 2, c))
        j_odo = hinv @ m_sum                                                # (k, 2, C)
        j_b = np.einsum("rab,rb->ra", hinv[o], qv)                          # (R, 2)
    jac_odo = (j_odo[:, 0, :] + 1j * j_odo[:, 1, :]).reshape(kept.size, w - 1, 3)
    jac_b = np.zeros((kept.size, w), np.complex128)
    jac_b[o, k_pose] = j_b[:, 0] + 1j * j_b[:, 1]
    # first and last ray of each kept landmark
    last = np.append(st[1:], o.size) - 1 if st.size else st
    a_idx, b_idx = k_pose[st], k_pose[last]
    pk = p[kept]
    depth_k = (d * np.exp(-1j * a_ray)).real
    span_k = span[kept]
    tri = WindowTriangulation(cand[kept], a_idx, b_idx, np.column_stack([pk.real, pk.imag]),
                              depth_k[st], depth_k[last], np.sin(span_k), np.cos(span_k),
                              jac_odo, jac_b)
    return tri, int(nc - kept.size)


def window_pair_squared_distances(tri: WindowTriangulation, odometry_sigmas: ArrayLike,
                                  bearing_sigma_rad: float, *, select: np.ndarray | None = None,
                                  with_jacobian: bool = False) -> PairEstimates:
    """Squared distance and first-order variance of every pair of a window's landmarks.

    Parameters
    ----------
    tri : WindowTriangulation
    odometry_sigmas : array of shape (W - 1, 3)
        Independent std. devs. of each increment's ``[dx_m, dy_m, dpsi_rad]``.
    bearing_sigma_rad : float
    select : array of int, optional
        Only pairs among these landmarks of ``tri``.
    with_jacobian : bool
        Also return the ``(P, 3 (W-1) + 2 V)`` Jacobian over the increments (row-major by
        increment) and the bearings of ``i`` then of ``j``: ``V = 2``,
        ``[theta_i_a, theta_i_b, theta_j_a, theta_j_b]`` for :func:`triangulate_window`;
        ``V = W``, the bearing from every window pose (0 where not seen), for
        :func:`triangulate_window_lsq`.

    Returns
    -------
    PairEstimates
        As :func:`pair_squared_distances` (no translation part).
    """
    if select is None:
        first, second = pair_indices(len(tri))
    else:
        f, g = pair_indices(len(select))
        first, second = select[f], select[g]
    sig = np.asarray(odometry_sigmas, dtype=float).reshape(-1, 3)
    pts = np.ascontiguousarray(tri.points_xy).view(np.complex128)[:, 0]
    e = pts[first] - pts[second]
    d2 = (e * e.conj()).real
    ec = e.conj()
    # d |e|^2 / dz = 2 Re(conj(e) de/dz): the increments move both points, each bearing one
    g_odo = (ec[:, None, None] * (tri.jacobian_odometry[first]
                                  - tri.jacobian_odometry[second])).real      # (P, W-1, 3)
    g_i = (ec[:, None] * tri.jacobian_bearing[first]).real                   # (P, 2)
    g_j = -(ec[:, None] * tri.jacobian_bearing[second]).real
    var = 4.0 * (np.einsum("pmc,mc->p", g_odo * g_odo, sig * sig)
                 + float(bearing_sigma_rad) ** 2 * ((g_i * g_i).sum(1) + (g_j * g_j).sum(1)))
    full = None
    if with_jacobian:
        full = 2.0 * np.concatenate([g_odo.reshape(len(e), -1), g_i, g_j], axis=1)
    return PairEstimates(first, second, d2, var, None, full)


__all__ = ["POINT_MEASUREMENTS", "PAIR_MEASUREMENTS", "RayTriangulation", "PairEstimates",
           "pair_indices", "triangulate_rays", "odometry_covariance", "compose_odometry",
           "point_covariance",
           "range_jacobians", "range_variances", "gate_points", "pair_squared_distances",
           "WindowTriangulation", "triangulate_window", "triangulate_window_lsq",
           "window_pair_squared_distances"]
