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

import itertools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..errors import ConfigError
from ..geometry import chain_odometry

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


def select_pairs(k: int, select: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """All pairs ``first < second`` of ``k`` items, or of the items ``select`` (index array)."""
    if select is None:
        return pair_indices(k)
    f, g = pair_indices(len(select))
    return select[f], select[g]


class TwoRayResult:
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
class RayTriangulation(TwoRayResult):
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
    odom : array of shape (3,) or (k, 3)
        ``[dx_m, dy_m, dpsi_rad]`` from pose ``t-1`` to pose ``t`` in the frame of ``t-1``; or
        one such row per landmark (the rays of several steps at once, the same numbers as one
        call per step).
    bearing_prev_rad, bearing_now_rad : arrays of shape (k,)
        Bearings of the same ``k`` landmarks at ``t-1`` and at ``t`` (relative to the heading).

    Returns
    -------
    RayTriangulation
        Points, signed depths, parallax and the analytic Jacobian of the depth. Parallel rays
        give non-finite values (gate them with :func:`gate_points`); nothing raises.
    """
    a = np.asarray(bearing_prev_rad, dtype=float).reshape(-1)
    b = np.asarray(bearing_now_rad, dtype=float).reshape(-1)
    if a.shape != b.shape:
        raise ConfigError(f"triangulate_rays: {a.size} bearings at t-1 but {b.size} at t")
    k = a.size
    u = np.asarray(odom, dtype=float)
    if u.ndim == 2 and u.shape == (k, 3):        # one odometry per ray
        dpsi = u[:, 2]
        # dx - i dy per ray (the conjugate negates dy exactly)
        o_conj: complex | np.ndarray = np.ascontiguousarray(u[:, :2]).view(
            np.complex128)[:, 0].conj()
    else:
        u = u.reshape(3)
        dx, dy, dpsi = float(u[0]), float(u[1]), float(u[2])
        o_conj = complex(dx, -dy)
    # Plane vectors as complex numbers (few, vectorised operations): u = exp(i angle),
    # u_b conj(u_a) = cos(b - a) + i sin(b - a), and Im(conj(o) u) = o x u.
    unit = np.exp(1j * np.concatenate((a, b + dpsi)))
    ua, ub = unit[:k], unit[k:]
    rel = ub * ua.conj()
    s, c = rel.imag, rel.real                    # sin(b - a), cos(b - a)
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
        r1c = r1 * c
        np.multiply(ob.real - r1c, inv_s, out=dr1[:, 2])             # d r1 / d b (= dpsi)
        np.multiply(r1c, inv_s, out=dr1[:, 3])                       # d r1 / d a
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
    xy, psi = chain_odometry(u)
    c, s = np.cos(psi[:-1]), np.sin(psi[:-1])
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
    ok = np.abs(tri.sin_parallax) >= max(math.sin(min_parallax_rad), 1e-15)
    # both depths in (0, max_range_m] (NaN depths fail: the extremes propagate NaN)
    r1, r2 = tri.range_prev_m, tri.range_now_m
    ok &= np.minimum(r1, r2) > 0
    if max_range_m < math.inf:
        ok &= np.maximum(r1, r2) <= max_range_m
    if math.isfinite(max_relative_range_sigma):
        if range_var_m2 is None:
            raise ConfigError("gate_points: the relative range gate needs range_var_m2")
        with np.errstate(invalid="ignore", over="ignore"):
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
    jacobian : ndarray of shape (P, 7) or None
        ``d |p_i - p_j|^2 / d [dx, dy, dpsi, theta_i_prev, theta_i_now, theta_j_prev,
        theta_j_now]`` (only when asked for).
    """

    first: np.ndarray
    second: np.ndarray
    squared_distance_m2: np.ndarray
    variance_m4: np.ndarray
    jacobian: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.first)


def pair_squared_distances(tri: RayTriangulation, odometry: ArrayLike,
                           bearing_sigma_rad: float, *, select: np.ndarray | None = None,
                           pairs: tuple[np.ndarray, np.ndarray] | np.ndarray | None = None,
                           pair_groups: np.ndarray | list[int] | None = None,
                           with_jacobian: bool = False) -> PairEstimates:
    """Squared distance and its first-order variance for every pair of ``tri``'s landmarks.

    Parameters
    ----------
    tri : RayTriangulation
        The landmarks of one step, ``k`` of them.
    odometry : array of shape (3,) or (3, 3)
        Std. devs. of ``[dx_m, dy_m, dpsi_rad]`` for this step, or their covariance (e.g.
        from :func:`compose_odometry` for a baseline of several steps); or, with
        ``pair_groups``, shape (G, 3): the std. devs. of each group of pairs (several steps).
    bearing_sigma_rad : float
    select : array of int, optional
        Only pairs among these landmarks (e.g. those that passed :func:`gate_points`).
    pairs : (first, second) int arrays of shape (P,), or an int array of shape (2, P), optional
        The pairs to take (indices into ``tri``), in place of all pairs of ``select``.
    pair_groups : ints (array or sequence) of length G, optional
        Numbers of consecutive pairs sharing each row of ``odometry`` (the steps of a batch;
        each group's variances are those of one call per group, bit for bit).
    with_jacobian : bool
        Also return the ``(P, 7)`` Jacobian (tests; the variance never needs it).

    Returns
    -------
    PairEstimates
        The pairs ``(first, second)`` index ``tri``; in ``np.triu_indices`` order of ``select``.
    """
    if pairs is None:
        idx2 = np.stack(select_pairs(len(tri), select))
    elif isinstance(pairs, np.ndarray) and pairs.ndim == 2:
        idx2 = pairs
    else:
        idx2 = np.stack(pairs)
    first, second = idx2[0], idx2[1]
    unc = np.asarray(odometry, dtype=float)
    sb2 = float(bearing_sigma_rad) ** 2
    # e . dp/dz = Re(e conj(dp/dz)) for the offset e = p_i - p_j (complex plane); both ends
    # of every pair at once, component-major (5, 2, P): long rows for the small arrays, and
    # one (P, 10)-sized temporary worked in place (large temporaries cost page faults)
    pts = np.ascontiguousarray(tri.points_xy).view(np.complex128)[:, 0]
    ends = pts[idx2]
    e = ends[0] - ends[1]
    d2 = (e * e.conj()).real
    g = np.take(np.ascontiguousarray(tri.jacobian_complex.T), idx2, axis=1)
    np.conjugate(g, out=g)
    np.multiply(e, g, out=g)
    g = g.real
    # d |e|^2 / dz = 2 e . de/dz: the odometry moves both points, each bearing one of them
    grad_t = np.empty((7, len(first)))
    np.subtract(g[:3, 0], g[:3, 1], out=grad_t[:3])
    grad_t[3:5] = g[3:, 0]
    grad_t[5:] = g[3:, 1]
    grad = np.ascontiguousarray(grad_t.T)                       # (P, 7)
    full = None
    if with_jacobian:
        full = 2.0 * grad
        full[:, 5:] *= -1.0
    if unc.shape == (3,):                                       # independent components
        var = np.multiply(grad, grad, out=grad) @ np.concatenate((4.0 * unc * unc,
                                                                 np.full(4, 4.0 * sb2)))
    elif pair_groups is not None:                               # rows of (G, 3) sigmas
        g2 = np.multiply(grad, grad, out=grad)
        var = np.empty(len(first))
        scale = np.empty((len(unc), 7))
        np.multiply(4.0 * unc, unc, out=scale[:, :3])
        scale[:, 3:] = 4.0 * sb2
        a = 0
        # one matrix-vector product per group, as one call per step (BLAS rounds a row
        # differently by its place in the call, so the groups are not merged)
        for row, b in zip(scale, itertools.accumulate(
                pair_groups.tolist() if isinstance(pair_groups, np.ndarray) else pair_groups)):
            if b > a:
                np.matmul(g2[a:b], row, out=var[a:b])
            a = b
    else:
        cov7 = np.zeros((7, 7))
        cov7[:3, :3] = odometry_covariance(unc)
        cov7.flat[24::8] = sb2                                  # the four bearings
        var = 4.0 * ((grad @ cov7) * grad).sum(axis=1)
    return PairEstimates(first, second, d2, var, full)


__all__ = ["POINT_MEASUREMENTS", "PAIR_MEASUREMENTS", "RayTriangulation", "PairEstimates",
           "pair_indices", "select_pairs", "triangulate_rays", "odometry_covariance", "compose_odometry",
           "point_covariance", "range_jacobians", "range_variances", "gate_points",
           "pair_squared_distances", "TwoRayResult"]
