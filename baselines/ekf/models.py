"""The bearing-only EKF's models and their analytic Jacobians (paper section IV, Exp. 2).

Vectorised kernels on arrays; nothing here holds state.

- Motion: ``pose_t = pose_{t-1} ⊕ u`` (:func:`bomgraph.geometry.compose`), ``u = [dx_m,
  dy_m, dpsi_rad]``; :func:`motion_jacobians` gives ``dF/dx`` and the input Jacobian
  ``G = d(pose ⊕ u)/du = blockdiag(R(psi), 1)``; :func:`path_heading_noise` the translation
  noise of a heading error accumulated along the step.
- Bearing to a Euclidean landmark ``[x_m, y_m]``: ``h = wrap(atan2(ly - y, lx - x) - psi)``
  (:func:`bearing_and_jacobian`); to an inverse-depth feature ``[x0_m, y0_m, theta_rad,
  rho_per_m]`` (Civera, Davison and Montiel, IEEE T-RO 2008, in the plane):
  :func:`invdepth_bearing_and_jacobian`, converted to ``[x, y]`` by :func:`invdepth_to_xy`.
- The second-order variance of a bearing and its nonlinearity index
  (:func:`second_order_variance`), from the landmark's covariance in the robot's ray frame
  (:func:`ray_covariance`).
- Bailey's Gaussianity test (T. Bailey, "Constrained initialisation for bearing-only SLAM",
  ICRA 2003): the Kullback-Leibler divergence (:func:`gaussian_kl_2d`) between the unscented
  and the linearised Gaussian of a landmark made from two rays (:func:`triangulation_kl`,
  :func:`triangulate_two_bearings`) or from an inverse-depth feature
  (:func:`invdepth_conversion_kl`).
"""

from __future__ import annotations

import math

import numpy as np

from bomgraph.angles import wrap_angle
from bomgraph.geometry import bearing_offsets


def motion_jacobians(pose: np.ndarray, odom: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians of ``pose ⊕ odom`` with respect to the pose and to the odometry.

    Parameters
    ----------
    pose : array of shape (3,)
        ``[x_m, y_m, psi_rad]`` before the move.
    odom : array of shape (3,)
        ``[dx_m, dy_m, dpsi_rad]`` in the frame of ``pose``.

    Returns
    -------
    f_pose : ndarray of shape (3, 3)
    g_odom : ndarray of shape (3, 3)
        ``blockdiag(R(psi), 1)``.
    """
    c, s = math.cos(float(pose[2])), math.sin(float(pose[2]))
    dx, dy = float(odom[0]), float(odom[1])
    f_pose = np.array([[1.0, 0.0, -s * dx - c * dy],
                       [0.0, 1.0, c * dx - s * dy],
                       [0.0, 0.0, 1.0]])
    g_odom = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return f_pose, g_odom


def path_heading_noise(odom: np.ndarray, sigma_psi_rad: float) -> np.ndarray:
    """The covariance a step's heading noise adds to its own translation when it accumulates
    along the path instead of all at its end.

    The step's heading error is taken as a random walk along its chord (length ``l``,
    unit direction ``c``, left normal ``n = J c``) reaching ``sigma_psi_rad**2`` at the end:
    an increment ``dW`` at arc length ``s`` rotates the rest of the path about that point, so
    the end position moves by ``(l - s) n dW``. Over the step this adds
    ``sigma_psi^2 [[l^2/3 n n^T, l/2 n], [l/2 n^T, 0]]`` to ``Cov(u)`` (the heading's own
    variance stays ``sigma_psi^2``): the limit of predicting the chord in many sub-steps with
    the heading noise split among them.

    Parameters
    ----------
    odom : array of shape (3,)
        ``[dx_m, dy_m, dpsi_rad]`` (only the translation is used: the chord).
    sigma_psi_rad : float
        The std. dev. of the step's heading.

    Returns
    -------
    ndarray of shape (3, 3)
        In the odometry frame (``[dx, dy, dpsi]``); zeros for a turn on the spot.
    """
    dx, dy = float(odom[0]), float(odom[1])
    length = math.hypot(dx, dy)
    out = np.zeros((3, 3))
    if length == 0.0:
        return out
    var = float(sigma_psi_rad) ** 2
    nx, ny = -dy / length, dx / length
    out[:2, :2] = (var * length * length / 3.0) * np.array([[nx * nx, nx * ny],
                                                             [nx * ny, ny * ny]])
    out[0, 2] = out[2, 0] = 0.5 * var * length * nx
    out[1, 2] = out[2, 1] = 0.5 * var * length * ny
    return out


def bearing_and_jacobian(poses: np.ndarray, points_xy: np.ndarray) -> tuple[np.ndarray,
                                                                             np.ndarray]:
    """Bearings from poses to points and their Jacobians.

    Parameters
    ----------
    poses : array of shape (k, 3)
    points_xy : array of shape (k, 2)

    Returns
    -------
    bearing_rad : ndarray of shape (k,)
        ``wrap(atan2(ly - y, lx - x) - psi)``.
    jac : ndarray of shape (k, 5)
        Derivatives with respect to ``[x, y, psi, lx, ly]``.
    """
    pred, d, q = bearing_offsets(poses, points_xy)
    b = wrap_angle(pred)
    jac = np.empty((len(q), 5))
    gx = np.divide(-d[:, 1], q, out=jac[:, 3])
    gy = np.divide(d[:, 0], q, out=jac[:, 4])
    np.negative(gx, out=jac[:, 0])
    np.negative(gy, out=jac[:, 1])
    jac[:, 2] = -1.0
    return np.asarray(b).reshape(-1), jac


def invdepth_bearing_and_jacobian(poses: np.ndarray,
                                  features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bearings from poses to inverse-depth features and their Jacobians.

    Parameters
    ----------
    poses : array of shape (k, 3)
    features : array of shape (k, 4)
        ``[x0_m, y0_m, theta_rad, rho_per_m]``: anchor, world azimuth, inverse depth.

    Returns
    -------
    bearing_rad : ndarray of shape (k,)
        ``wrap(atan2(v_y, v_x) - psi)`` with ``v = rho (a - p) + [cos theta, sin theta]``
        (the direction to ``a + m / rho`` scaled by ``rho > 0``).
    jac : ndarray of shape (k, 7)
        Derivatives with respect to ``[x, y, psi, x0, y0, theta, rho]``.
    """
    a_minus_p = features[:, :2] - poses[:, :2]
    rho = features[:, 3]
    th = features[:, 2]
    v = rho[:, None] * a_minus_p + np.column_stack([np.cos(th), np.sin(th)])
    q = np.einsum("ki,ki->k", v, v)
    g = np.column_stack([-v[:, 1], v[:, 0]]) / q[:, None]
    b = wrap_angle(np.arctan2(v[:, 1], v[:, 0]) - poses[:, 2])
    jac = np.empty((len(q), 7))
    jac[:, 0:2] = -rho[:, None] * g
    jac[:, 2] = -1.0
    jac[:, 3:5] = rho[:, None] * g
    jac[:, 5] = -g[:, 0] * np.sin(th) + g[:, 1] * np.cos(th)
    jac[:, 6] = np.einsum("ki,ki->k", g, a_minus_p)
    return np.asarray(b).reshape(-1), jac


def invdepth_to_xy(features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Euclidean points of inverse-depth features and the Jacobians of the conversion.

    Parameters
    ----------
    features : array of shape (k, 4)
        ``[x0_m, y0_m, theta_rad, rho_per_m]`` with ``rho != 0``.

    Returns
    -------
    points_xy : ndarray of shape (k, 2)
        ``a + [cos theta, sin theta] / rho``.
    jac : ndarray of shape (k, 2, 4)
    """
    th, rho = features[:, 2], features[:, 3]
    m = np.column_stack([np.cos(th), np.sin(th)])
    pts = features[:, :2] + m / rho[:, None]
    jac = np.zeros((len(rho), 2, 4))
    jac[:, 0, 0] = jac[:, 1, 1] = 1.0
    jac[:, :, 2] = np.column_stack([-np.sin(th), np.cos(th)]) / rho[:, None]
    jac[:, :, 3] = -m / (rho * rho)[:, None]
    return pts, jac


def _two_ray_point(pose_a: np.ndarray, pose_b: np.ndarray, bearing_a: np.ndarray,
                   bearing_b: np.ndarray) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
    """Intersection of two bearing rays, broadcasting over leading axes.

    The one place of the two-ray arithmetic (:func:`triangulate_two_bearings` and the sigma
    points of :func:`triangulation_kl`). It is not :func:`bomgraph.geometry.intersect_rays`:
    that solves the least-squares normal equations, which for two rays gives the same point
    in other floating-point operations (different last bits), and it has no Jacobian.

    Returns the point ``(..., 2)`` (infinite or NaN for parallel rays) and the terms
    ``(c1, s1, c2, s2, dx, dy, s, n, r1)`` the Jacobian reuses: the world directions' cosines
    and sines, ``p_b - p_a``, ``s = sin(a2 - a1)``, ``n = (p_b - p_a) x d2`` and the depth
    ``r1 = n / s`` along ray a.
    """
    a1 = pose_a[..., 2] + bearing_a
    a2 = pose_b[..., 2] + bearing_b
    c1, s1, c2, s2 = np.cos(a1), np.sin(a1), np.cos(a2), np.sin(a2)
    dx = pose_b[..., 0] - pose_a[..., 0]
    dy = pose_b[..., 1] - pose_a[..., 1]
    s = c1 * s2 - s1 * c2            # sin(a2 - a1)
    n = dx * s2 - dy * c2            # (p_b - p_a) x d2
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        r1 = n / s
        pt = np.stack([pose_a[..., 0] + r1 * c1, pose_a[..., 1] + r1 * s1], -1)
    return pt, (c1, s1, c2, s2, dx, dy, s, n, r1)


def triangulate_two_bearings(pose_a: np.ndarray, pose_b: np.ndarray, bearing_a: np.ndarray,
                             bearing_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The point seen at ``bearing_a`` from ``pose_a`` and at ``bearing_b`` from ``pose_b``.

    The rays are ``p_a + r_a d(a_a)`` with world angles ``a_a = psi_a + bearing_a`` (same for
    b); the point is ``p_a + r_a d(a_a)`` with ``r_a = ((p_b - p_a) x d(a_b)) / sin(a_b - a_a)``.

    Parameters
    ----------
    pose_a, pose_b : arrays of shape (m, 3)
    bearing_a, bearing_b : arrays of shape (m,), radians relative to the headings

    Returns
    -------
    points_xy : ndarray of shape (m, 2)
        Infinite or NaN for parallel rays.
    jac : ndarray of shape (m, 2, 8)
        Derivatives with respect to ``[x_a, y_a, psi_a, x_b, y_b, psi_b, bearing_a,
        bearing_b]``.
    """
    pts, (c1, s1, c2, s2, dx, dy, s, n, r1) = _two_ray_point(pose_a, pose_b, bearing_a,
                                                             bearing_b)
    cd = c1 * c2 + s1 * s2           # cos(a2 - a1)
    jac = np.zeros((len(s), 2, 8))
    # parallel rays (s = 0) give infinite or NaN entries, as the point: no warning
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        d1 = np.stack([c1, s1], -1)
        w = np.stack([s2, -c2], -1) / s[:, None]
        dr_da1 = n * cd / (s * s)
        dr_da2 = (dx * c2 + dy * s2) / s - n * cd / (s * s)
        outer = d1[:, :, None] * w[:, None, :]
        jac[:, :, 0:2] = np.eye(2) - outer
        jac[:, :, 3:5] = outer
        j_a1 = dr_da1[:, None] * d1 + r1[:, None] * np.stack([-s1, c1], -1)
        j_a2 = dr_da2[:, None] * d1
    jac[:, :, 2] = jac[:, :, 6] = j_a1
    jac[:, :, 5] = jac[:, :, 7] = j_a2
    return pts, jac


def _sigma_points(mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """The ``2 d`` symmetric sigma points ``mean +- sqrt(d) (columns of cov^(1/2))`` of m
    Gaussians of dimension d (equal weights), shape ``(m, 2 d, d)``."""
    w, v = np.linalg.eigh(cov)
    sq = (v * np.sqrt(float(mean.shape[1]) * np.clip(w, 0.0, None))[:, None, :]
          ).transpose(0, 2, 1)                                           # rows
    return np.concatenate([mean[:, None, :] + sq, mean[:, None, :] - sq], 1)


def _sample_moments(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean ``(m, 2)`` and covariance ``(m, 2, 2)`` of equally weighted points ``(m, s, 2)``."""
    mean = points.sum(1) / points.shape[1]
    dev = points - mean[:, None, :]
    return mean, np.einsum("msi,msj->mij", dev, dev) / points.shape[1]


def triangulation_kl(inputs: np.ndarray, cov: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bailey's Gaussianity test of the landmark triangulated from two rays.

    ``KL(N_ut || N_lin)`` between the unscented estimate of the distribution of
    :func:`triangulate_two_bearings` (16 symmetric sigma points, equal weights) and its
    linearisation ``N(g(mu), J cov J^T)``.

    Parameters
    ----------
    inputs : array of shape (m, 8)
        ``[x_a, y_a, psi_a, x_b, y_b, psi_b, bearing_a, bearing_b]`` (m, rad).
    cov : array of shape (m, 8, 8)
        Their covariance.

    Returns
    -------
    points_xy : ndarray of shape (m, 2)
    jac : ndarray of shape (m, 2, 8)
    kl : ndarray of shape (m,), nats
        ``inf`` where it is not finite.
    """
    pts, jac = triangulate_two_bearings(inputs[:, 0:3], inputs[:, 3:6], inputs[:, 6],
                                        inputs[:, 7])
    with np.errstate(invalid="ignore", over="ignore"):       # parallel rays: kl = inf below
        cov_lin = jac @ cov @ jac.transpose(0, 2, 1)
    sig = _sigma_points(inputs, cov)                                      # (m, 16, 8)
    sp, _ = _two_ray_point(sig[..., 0:3], sig[..., 3:6], sig[..., 6], sig[..., 7])
    with np.errstate(invalid="ignore", over="ignore"):
        mean_u, cov_ut = _sample_moments(sp)
        kl = gaussian_kl_2d(mean_u, cov_ut, pts, cov_lin)
    kl[~np.isfinite(kl)] = np.inf
    return pts, jac, kl


def invdepth_conversion_kl(features: np.ndarray, covs: np.ndarray) -> np.ndarray:
    """Bailey's Gaussianity test for the Euclidean form of inverse-depth features.

    ``KL(N_ut || N_lin)`` between the unscented estimate of the distribution of
    ``invdepth_to_xy(f)`` for ``f ~ N(features, covs)`` (8 symmetric sigma points, equal
    weights) and its linearisation ``N(g(f), J covs J^T)``.

    Parameters
    ----------
    features : array of shape (m, 4)
        ``[x0_m, y0_m, theta_rad, rho_per_m]``.
    covs : array of shape (m, 4, 4)

    Returns
    -------
    ndarray of shape (m,), nats
        ``inf`` where a sigma point has ``rho <= 0`` (the distribution reaches infinity).
    """
    m = len(features)
    pts, jac = invdepth_to_xy(features)
    cov_lin = jac @ covs @ jac.transpose(0, 2, 1)
    sig = _sigma_points(features, covs)                                   # (m, 8, 4)
    out = np.full(m, np.inf)
    ok = np.all(sig[:, :, 3] > 0, axis=1)
    if np.any(ok):
        sp = invdepth_to_xy(sig[ok].reshape(-1, 4))[0].reshape(-1, 8, 2)
        mean_u, cov_ut = _sample_moments(sp)
        out[ok] = gaussian_kl_2d(mean_u, cov_ut, pts[ok], cov_lin[ok])
    return out


def ray_covariance(values: np.ndarray, block: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Covariance of a landmark as the robot sees it, in the frame of the ray between them.

    The covariance of ``R(psi)^T r`` for ``r = l - p``: its perpendicular part
    ``w.(l - p) - |r| psi`` also varies with the heading, so a rotation of the map and the
    robot together (which leaves every bearing unchanged) does not count.

    Parameters
    ----------
    values : array of shape (m, 5)
        ``[x_m, y_m, psi_rad, lx_m, ly_m]``: pose and landmark.
    block : array of shape (m, 5, 5)
        Their joint covariance.

    Returns
    -------
    d2 : ndarray of shape (m,)
        ``|r|^2``, m^2.
    c_rr, c_pp, c_rp : ndarrays of shape (m,)
        Radial and perpendicular variances and their covariance, m^2.
    """
    r = values[:, 3:5] - values[:, 0:2]
    d2 = r[:, 0] * r[:, 0] + r[:, 1] * r[:, 1]
    dist = np.sqrt(d2)
    ux, uy = r[:, 0] / dist, r[:, 1] / dist          # radial unit vector; w = [-uy, ux]
    j = np.zeros((len(d2), 2, 5))                    # rows: radial, perpendicular
    j[:, 0, 0], j[:, 0, 1], j[:, 0, 3], j[:, 0, 4] = -ux, -uy, ux, uy
    j[:, 1, 0], j[:, 1, 1], j[:, 1, 2], j[:, 1, 3], j[:, 1, 4] = uy, -ux, -dist, -uy, ux
    c = j @ block @ j.transpose(0, 2, 1)
    c_rr, c_pp, c_rp = c[:, 0, 0], c[:, 1, 1], c[:, 0, 1]
    return d2, c_rr, c_pp, c_rp


def second_order_variance(values: np.ndarray, block: np.ndarray, bearing_sigma_rad: float
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Bearing variances with the second-order linearisation error; nonlinearity index.

    Euclidean landmark: for ``r = l - p`` with covariance ``C`` (``C_rr``, ``C_pp``, ``C_rp``
    in the robot's ray frame, :func:`ray_covariance`) the second-order term of ``atan2`` is
    ``-d_r d_p / |r|^2``, of variance ``(C_rr C_pp + C_rp^2) / |r|^4``; the index
    ``(C_rr C_pp)^(1/4) / |r|`` measures how far the linearisation is to be trusted.
    Inverse-depth feature: the second-order term in ``rho``, ``h_rho_rho d_rho^2 / 2`` with
    ``h_rho_rho = -2 (v x d)(v . d) / |v|^4`` (``d = a - p``, ``v = rho d + m``), of variance
    ``(h_rho_rho var_rho)^2 / 2``; index 0. The variance is added to ``sigma^2``; the mean of
    the term is not (it would move a filter fed noise-free data off the truth).

    Parameters
    ----------
    values : array of shape (m, 5) or (m, 7)
        Pose ``[x, y, psi]`` then the landmark (``[lx, ly]``) or feature block.
    block : array of shape (m, s, s)
        Their covariance.
    bearing_sigma_rad : float

    Returns
    -------
    var_rad2 : ndarray of shape (m,)
    nonlinearity : ndarray of shape (m,)
    """
    m = len(values)
    var = np.full(m, bearing_sigma_rad ** 2)
    if values.shape[1] == 7:
        dvec = values[:, 3:5] - values[:, 0:2]
        rho, th = values[:, 6], values[:, 5]
        v = rho[:, None] * dvec + np.stack([np.cos(th), np.sin(th)], 1)
        vv = np.einsum("ki,ki->k", v, v)
        cross = v[:, 0] * dvec[:, 1] - v[:, 1] * dvec[:, 0]
        h_rr = -2.0 * cross * np.einsum("ki,ki->k", v, dvec) / (vv * vv)
        var += 0.5 * (h_rr * block[:, 6, 6]) ** 2
        return var, np.zeros(m)
    d2, c_rr, c_pp, c_rp = ray_covariance(values, block)
    prod = np.maximum(c_rr * c_pp, 0.0)
    var += (prod + c_rp ** 2) / (d2 * d2)
    return var, prod ** 0.25 / np.sqrt(d2)


def gaussian_kl_2d(mean_p: np.ndarray, cov_p: np.ndarray, mean_q: np.ndarray,
                   cov_q: np.ndarray) -> np.ndarray:
    """``KL(N_p || N_q)`` for 2-D Gaussians, vectorised; ``inf`` where a covariance is singular.

    Parameters
    ----------
    mean_p, mean_q : arrays of shape (m, 2)
    cov_p, cov_q : arrays of shape (m, 2, 2)

    Returns
    -------
    ndarray of shape (m,), nats
    """
    p00, p01, p10, p11 = cov_p[:, 0, 0], cov_p[:, 0, 1], cov_p[:, 1, 0], cov_p[:, 1, 1]
    q00, q01, q10, q11 = cov_q[:, 0, 0], cov_q[:, 0, 1], cov_q[:, 1, 0], cov_q[:, 1, 1]
    det_p = p00 * p11 - p01 * p10
    det_q = q00 * q11 - q01 * q10
    d = mean_q - mean_p
    d0, d1 = d[:, 0], d[:, 1]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        # tr(Q^-1 C_p) + d^T Q^-1 d = tr(adj(Q) (C_p + d d^T)) / det(Q)
        t = (q11 * (p00 + d0 * d0) - q01 * (p10 + d1 * d0) - q10 * (p01 + d0 * d1)
             + q00 * (p11 + d1 * d1)) / det_q
        kl = 0.5 * (t - 2.0 + np.log(det_q / det_p))
    ok = (det_p > 0) & (det_q > 0) & np.isfinite(d0) & np.isfinite(d1)
    return np.where(ok, kl, np.inf)


__all__ = ["bearing_and_jacobian", "gaussian_kl_2d", "invdepth_bearing_and_jacobian",
           "invdepth_conversion_kl", "invdepth_to_xy", "motion_jacobians", "path_heading_noise",
           "ray_covariance",
           "second_order_variance", "triangulate_two_bearings", "triangulation_kl"]
