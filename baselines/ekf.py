"""Bearing-only EKF-SLAM on filterpy: the paper's BOSLAM-EKF baseline (section IV, Exp. 2).

The paper compares BOM-STMDS with "BOSLAM-EKF" whose new landmarks are initialised by Bailey's
*constrained initialisation* (T. Bailey, "Constrained initialisation for bearing-only SLAM",
ICRA 2003). This module implements that filter, ``ekf``, and an undelayed alternative,
``ekf-invdepth`` (Civera, Davison and Montiel, "Inverse depth parametrization for monocular
SLAM", IEEE T-RO 2008, reduced to the plane).

The filter
    :class:`BearingEkf` wraps ``filterpy.kalman.ExtendedKalmanFilter``: filterpy runs every
    predict and update; the wrapper builds it complete and resizes all its state-sized arrays
    together. The state is ``[x_m, y_m, psi_rad]`` of the robot followed by blocks (landmarks
    ``[x_m, y_m]``, pose clones ``[x_m, y_m, psi_rad]``, inverse-depth features
    ``[x0_m, y0_m, theta_rad, rho_per_m]``). The state vector is 1-D, shape ``(n,)``.

Motion (predict)
    ``pose_t = pose_{t-1} ⊕ u`` with ``u = [dx, dy, dpsi]`` (:func:`bomgraph.geometry.compose`).
    filterpy's ``predict`` is linear, so :class:`_OdometryEkf` overrides ``predict_x`` with the
    nonlinear composition and ``F`` is set to its Jacobian ``dF/dx`` (identity outside the
    pose). The odometry noise ``Sigma_u = diag(sigma_u**2)`` (``step.odometry_sigma``) enters
    as ``Q = G Sigma_u G^T`` with the input Jacobian ``G = d(pose ⊕ u)/du = blockdiag(R(psi), 1)``.

Bearing update
    ``h = wrap(atan2(ly - y, lx - x) - psi)``, ``residual=bomgraph.angles.angle_residual``
    (innovations straddling +-pi are small, never 2 pi). filterpy's ``update`` applies the
    Joseph form ``P = (I-KH) P (I-KH)^T + K R K^T``. All bearings of one step to mapped
    landmarks are **batched into one update**. Before it, each bearing is gated on its own
    (individual compatibility): ``y_i^2 / (H_i P H_i^T + var_i)`` against the chi-square
    1-dof quantile ``gate_probability``; rejected bearings are left out of the batch, so a
    gated outlier leaves the state exactly as if it had not been measured.

Three measures against linearisation error (landmarks are 0-1 m away and the odometry noise is
15-30 % of a step, so a plain EKF is far from consistent; robot-pose NEES, 25 paper runs):

* second-order variance: ``var_i = sigma^2 + (C_rr C_pp + C_rp^2) / |r|^4`` for the relative
  position ``r = l - p`` with covariance ``C`` in the ray frame (the variance of the
  second-order term of ``atan2``); bearings whose index ``(C_rr C_pp)^(1/4) / |r|`` exceeds
  ``max_bearing_nonlinearity`` are not used. With a known map this alone takes the
  localisation NEES from about 100 to 3.1. ``C`` is taken in the robot's frame, heading
  included (:func:`ray_covariance`, ``nonlinearity_frame="robot"``): a rotation of the map and
  the robot together changes no bearing, so an uncertain global heading must not count as
  nonlinearity. (In world axes it did: on MRCLAM6 after a blind turn every bearing to a mapped
  landmark was refused and the filter never recovered. Paper setup: MPE 3.46 -> 3.34 cm at
  t = 50, 1.83 -> 1.80 cm at t = 300, robot NEES 4.9 -> 4.7.)
* observability constraints (OC-EKF, Huang, Mourikis and Roumeliotis, IJRR 2010): the
  nullspace ``N`` of global translation and rotation is carried with the state, the
  propagation Jacobian keeps ``F N_k = N_{k+1}`` and every measurement row is linearised at
  the closest point with ``h N = 0`` (:meth:`_EkfSlam._constrain`); SLAM NEES 6.3 -> 4.9 and
  landmark MPE at t = 300 2.5 -> 1.8 cm. (First-estimates Jacobians were tried and dropped:
  the first estimates of landmarks 0.1-1 m away are too poor; the MPE rose.)
* intermediate bearings: see below.

Constrained (delayed) initialisation, ``ekf``
    A landmark seen for the first time is a *candidate*: its bearing ``z1`` is kept and the
    current pose is cloned into the state (stochastic cloning: the clone is perfectly
    correlated with the pose when made; all candidates seen at one step share one clone).
    At each later sighting ``z2`` the landmark is triangulated from the anchor clone and the
    current pose, ``l = g(pose_c, pose_r, z1, z2)`` (:func:`triangulate_two_bearings`), and
    Bailey's Gaussianity test is applied: the linearised Gaussian ``N(g(mu), J Sigma J^T)`` is
    compared with the unscented estimate of the same distribution by their Kullback-Leibler
    divergence; below ``init_kl_max`` (and in front of both rays) the landmark enters the state
    with ``P_lx = J_x P[x_c, r, :]``, ``P_ll = J_x P_cr J_x^T + J_z diag(sigma^2) J_z^T``. As in
    Bailey's method, the bearings taken between the two (each with a clone of its pose) are then
    applied in one batched, gated update (``use_intermediate_bearings``; without it the MPE
    rises from 3.5 to 4.4 cm at t = 50 and from 1.8 to 2.3 cm at t = 300), and clones no
    candidate needs are removed. A
    candidate whose rays cross behind the robot at clear parallax, or that waited
    ``max_pending_steps``, is re-anchored at the current sighting. Why candidates seen again
    are not initialised is counted in ``info`` (``init_rejected_behind``, ``init_rejected_kl``).

Inverse-depth candidates, ``ekf`` with ``candidates="inverse-depth"`` (preset ``"real"``)
    On MRCLAM6 (keyframes 0.3 m / 0.3 rad apart, landmarks 3-5 m away in a +-0.6 rad view,
    2.5 per keyframe) the clone candidates above map 0-3 of the 15 landmarks on robots 1-5.
    Measured on the imported streams, robot by robot: the two-ray KL divergence has a median
    of 1.3-3.6 nats (threshold 0.01); the heading uncertainty between the anchor clone and the
    robot (median 6.5-11.6 deg) is as large as the parallax gained (median 7.8-9.8 deg), and
    in 24-41 % of the tests the two rays cross behind the robot. No bearing constrains the
    heading while every landmark waits (the odometry heading sigma is 0.045-0.06 rad per
    keyframe, up to 0.87 rad for a blind turn, biased by +0.1 to +0.4 sigma per step), so the
    heading drifts (its sigma 49-85 deg by the end) and no candidate becomes well
    conditioned; the few that are initialised have bearings refused as nonlinear. Larger
    ``init_kl_max`` (0.2, 1) mapped 7-15 landmarks 1.3-8.9 m off (MPE); pairing every kept
    sighting with the current one, or judging the Gauss-Newton estimate from all kept bearings
    instead of two rays, mapped every landmark on some robots (5-20 cm) and none on others,
    depending on thresholds. So with ``candidates="inverse-depth"`` a first sighting
    enters the state at once as an inverse-depth feature (as in ``ekf-invdepth``, below), and
    its bearings keep the heading in check from the start; it joins the map as ``[x, y]``
    when Bailey's test passes on that conversion (:func:`invdepth_conversion_kl`: the KL
    divergence between the unscented and the linearised Gaussian of ``invdepth_to_xy``, below
    ``init_kl_max``). Features not yet converted are not on the map (``info["pending"]``).
    A feature whose bearings fail the gate ``restart_after_gated`` times in a row started
    from an outlier and is started again (``info["restarted"]``).

Iterated update (``iterations > 1``)
    Gauss-Newton on the prior and the step's bearings (:meth:`BearingEkf.update`); the iterates
    use the model's own Jacobians, the last step the observability-constrained ones. It helps
    after a long blind turn, when one update has to move the heading by tens of degrees
    (``ekf``, real preset, MRCLAM6 robots 1-5 keyframed at 0.25, 0.3, 0.35, 0.4 m: mean MPE
    20.6 -> 17.9 cm, worst 41 -> 35 cm). On the paper setup it hurts ``ekf`` (MPE at t = 300
    2.74 -> 4.98 cm with the real preset, robot NEES 15 -> 28), not ``ekf-invdepth`` (its
    real preset: 2.61 cm, the defaults 2.67 cm); localisation in a known map is unchanged
    (NEES 3.2 -> 3.1, OC off).

Presets (:data:`EKF_PRESETS`, :data:`INVDEPTH_PRESETS`; ``preset="real"`` as a factory option)
    ``"paper"``: the defaults. ``"real"``: inverse-depth candidates (``ekf``), every bearing
    used whatever its nonlinearity index (``max_bearing_nonlinearity=inf``: after a blind turn
    the bearings to mapped landmarks are the ones that bring the heading back), two
    iterations, restarts after three gated bearings in a row. Landmark MPE in cm (landmarks
    mapped) on MRCLAM6 robots 1-5 and the g2o set, final map: ``ekf`` 22.8 (15), 28.3 (15),
    7.2 (15), 15.0 (13), 8.9 (15), 3.5 (125 of 141); ``ekf-invdepth`` 21.4, 30.5, 6.7, 27.1,
    7.1 (all 15), 21.7 (141); robot-pose NEES about 3 (``ekf`` with the paper preset: no map
    on four robots, NEES 22). Paper setup, t = 300: ``ekf`` 4.98 cm, ``ekf-invdepth`` 2.61 cm.
    Inflating the calibrated odometry sigma (``odometry_sigma_scale`` 1.5) did not help on
    MRCLAM6 (better on some robots, worse on others) and is not in the preset.

Inverse depth, ``ekf-invdepth``
    A first sighting enters the state at once as ``[x0, y0, theta, rho]`` (anchor = robot
    position, ``theta = psi + z``, ``rho ~ N(rho_init, rho_sigma^2)``); it is converted to a
    Euclidean ``[x, y]`` block once Civera's linearity index ``4 sigma_d / d |cos alpha|``
    falls below ``linearity_max``. Features still in inverse depth are reported through the
    same conversion by ``estimate()`` (those with ``rho <= 0`` are left out). The prior on
    ``rho`` makes it inexact on noise-free data (about 1 cm) and it is less consistent than
    ``ekf``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter
from scipy.stats import chi2

from bomgraph.angles import angle_residual, wrap_angle
from bomgraph.errors import ConfigError
from bomgraph.geometry import compose
from bomgraph.mapper import MapEstimate
from bomgraph.stream import Step, StreamHeader

# --------------------------------------------------------------------------------------------
# Models and their analytic Jacobians (vectorised kernels)
# --------------------------------------------------------------------------------------------


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
    c, s = math.cos(pose[2]), math.sin(pose[2])
    dx, dy = float(odom[0]), float(odom[1])
    f_pose = np.array([[1.0, 0.0, -s * dx - c * dy],
                       [0.0, 1.0, c * dx - s * dy],
                       [0.0, 0.0, 1.0]])
    g_odom = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return f_pose, g_odom


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
    d = points_xy - poses[:, :2]
    q = np.einsum("ki,ki->k", d, d)
    b = wrap_angle(np.arctan2(d[:, 1], d[:, 0]) - poses[:, 2])
    gx, gy = -d[:, 1] / q, d[:, 0] / q
    jac = np.column_stack([-gx, -gy, -np.ones(len(q)), gx, gy])
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


def _triangulate_point(pose_a: np.ndarray, pose_b: np.ndarray, bearing_a: np.ndarray,
                       bearing_b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Intersection of two bearing rays, broadcasting over leading axes.

    Returns the point ``(..., 2)``, the depth along ray a ``(...,)`` and ``sin(a_b - a_a)``.
    """
    a1 = pose_a[..., 2] + bearing_a
    a2 = pose_b[..., 2] + bearing_b
    c1, s1, c2, s2 = np.cos(a1), np.sin(a1), np.cos(a2), np.sin(a2)
    dx = pose_b[..., 0] - pose_a[..., 0]
    dy = pose_b[..., 1] - pose_a[..., 1]
    s = c1 * s2 - s1 * c2
    n = dx * s2 - dy * c2
    with np.errstate(divide="ignore", invalid="ignore"):
        r1 = n / s
    pt = np.stack([pose_a[..., 0] + r1 * c1, pose_a[..., 1] + r1 * s1], -1)
    return pt, r1, s


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
    a1 = pose_a[:, 2] + bearing_a
    a2 = pose_b[:, 2] + bearing_b
    c1, s1, c2, s2 = np.cos(a1), np.sin(a1), np.cos(a2), np.sin(a2)
    dx = pose_b[:, 0] - pose_a[:, 0]
    dy = pose_b[:, 1] - pose_a[:, 1]
    s = c1 * s2 - s1 * c2            # sin(a2 - a1)
    cd = c1 * c2 + s1 * s2           # cos(a2 - a1)
    n = dx * s2 - dy * c2            # (p_b - p_a) x d2
    with np.errstate(divide="ignore", invalid="ignore"):
        r1 = n / s
        d1 = np.stack([c1, s1], -1)
        w = np.stack([s2, -c2], -1) / s[:, None]
        dr_da1 = n * cd / (s * s)
        dr_da2 = (dx * c2 + dy * s2) / s - n * cd / (s * s)
    pts = pose_a[:, :2] + r1[:, None] * d1
    jac = np.zeros((len(s), 2, 8))
    outer = d1[:, :, None] * w[:, None, :]
    jac[:, :, 0:2] = np.eye(2) - outer
    jac[:, :, 3:5] = outer
    j_a1 = dr_da1[:, None] * d1 + r1[:, None] * np.stack([-s1, c1], -1)
    j_a2 = dr_da2[:, None] * d1
    jac[:, :, 2] = jac[:, :, 6] = j_a1
    jac[:, :, 5] = jac[:, :, 7] = j_a2
    return pts, jac


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
    w, v = np.linalg.eigh(covs)
    sq = (v * np.sqrt(4.0 * np.clip(w, 0.0, None))[:, None, :]).transpose(0, 2, 1)   # rows
    sig = np.concatenate([features[:, None, :] + sq, features[:, None, :] - sq], 1)  # (m, 8, 4)
    out = np.full(m, np.inf)
    ok = np.all(sig[:, :, 3] > 0, axis=1)
    if np.any(ok):
        sp = invdepth_to_xy(sig[ok].reshape(-1, 4))[0].reshape(-1, 8, 2)
        mean_u = sp.mean(1)
        dev = sp - mean_u[:, None, :]
        cov_ut = np.einsum("msi,msj->mij", dev, dev) / 8.0
        out[ok] = gaussian_kl_2d(mean_u, cov_ut, pts[ok], cov_lin[ok])
    return out


def ray_covariance(values: np.ndarray, block: np.ndarray, robot_frame: bool = False
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Covariance of a landmark relative to a pose, in the frame of the ray between them.

    Parameters
    ----------
    values : array of shape (m, 5)
        ``[x_m, y_m, psi_rad, lx_m, ly_m]``: pose and landmark.
    block : array of shape (m, 5, 5)
        Their joint covariance.
    robot_frame : bool
        False: of ``r = l - p`` (world axes). True: of ``R(psi)^T r``, the landmark as the
        robot sees it; its perpendicular part ``w.(l - p) - |r| psi`` also varies with the
        heading, and a rotation of the map and the robot together (which leaves every
        bearing unchanged) does not count.

    Returns
    -------
    d2 : ndarray of shape (m,)
        ``|r|^2``, m^2.
    c_rr, c_pp, c_rp : ndarrays of shape (m,)
        Radial and perpendicular variances and their covariance, m^2.
    """
    r = values[:, 3:5] - values[:, 0:2]
    d2 = np.einsum("ki,ki->k", r, r)
    u = r / np.sqrt(d2)[:, None]                      # radial unit vector
    w = np.stack([-u[:, 1], u[:, 0]], 1)               # perpendicular
    zero = np.zeros((len(d2), 1))
    j_r = np.concatenate([-u, zero, u], 1)
    j_p = np.concatenate([-w, -np.sqrt(d2)[:, None] if robot_frame else zero, w], 1)
    c_rr = np.einsum("ki,kij,kj->k", j_r, block, j_r)
    c_pp = np.einsum("ki,kij,kj->k", j_p, block, j_p)
    c_rp = np.einsum("ki,kij,kj->k", j_r, block, j_p)
    return d2, c_rr, c_pp, c_rp


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
    det_p = cov_p[:, 0, 0] * cov_p[:, 1, 1] - cov_p[:, 0, 1] * cov_p[:, 1, 0]
    det_q = cov_q[:, 0, 0] * cov_q[:, 1, 1] - cov_q[:, 0, 1] * cov_q[:, 1, 0]
    out = np.full(len(det_p), np.inf)
    ok = (det_p > 0) & (det_q > 0) & np.all(np.isfinite(mean_p), 1) \
        & np.all(np.isfinite(mean_q), 1)
    if np.any(ok):
        q = cov_q[ok]
        inv_q = np.stack([np.stack([q[:, 1, 1], -q[:, 0, 1]], -1),
                          np.stack([-q[:, 1, 0], q[:, 0, 0]], -1)], -2) / det_q[ok, None, None]
        d = mean_q[ok] - mean_p[ok]
        tr = np.einsum("kij,kji->k", inv_q, cov_p[ok])
        maha = np.einsum("ki,kij,kj->k", d, inv_q, d)
        out[ok] = 0.5 * (tr + maha - 2.0 + np.log(det_q[ok] / det_p[ok]))
    return out


# --------------------------------------------------------------------------------------------
# The filter: filterpy's EKF, wrapped so that it is built complete and resized consistently
# --------------------------------------------------------------------------------------------


class _OdometryEkf(ExtendedKalmanFilter):
    """filterpy's EKF whose state prediction is the nonlinear odometry composition.

    ``predict(u)`` calls :meth:`predict_x` (here: ``pose ⊕ u`` on ``x[:3]``, the rest of the
    state is static) and then ``P = F P F^T + Q`` with ``F`` and ``Q`` set by the caller.
    """

    def predict_x(self, u: Any = 0) -> None:
        x = self.x.copy()
        x[:3] = compose(x[:3], u)
        self.x = x


class BearingEkf:
    """A planar bearing-only EKF on filterpy with a state that grows and shrinks.

    Parameters
    ----------
    pose0 : array of shape (3,)
        Initial robot pose ``[x_m, y_m, psi_rad]``.
    pose_cov0 : array of shape (3, 3)
        Its covariance (zeros: the map frame is the first pose).
    bearing_sigma_rad : float
        Std. dev. of one bearing.

    Notes
    -----
    filterpy's arrays whose size follows the state (``x``, ``P``, ``F``, ``Q``, ``_I``, ``K``,
    ``x_prior``, ``x_post``, ``P_prior``, ``P_post``, ``dim_x``) are all resized together in
    :meth:`_set_state`. ``B`` stays filterpy's scalar 0: the control enters through
    ``predict_x``, not through a linear ``B u``. ``dim_z``, ``y``, ``S``, ``SI`` follow the
    size of the last batch of bearings.
    """

    def __init__(self, pose0: np.ndarray, pose_cov0: np.ndarray,
                 bearing_sigma_rad: float, observability_constrained: bool = False) -> None:
        pose0 = np.asarray(pose0, dtype=float).reshape(3)
        pose_cov0 = np.asarray(pose_cov0, dtype=float).reshape(3, 3)
        if not (np.all(np.isfinite(pose0)) and np.all(np.isfinite(pose_cov0))):
            raise ConfigError("BearingEkf: the initial pose and its covariance must be finite")
        if not (math.isfinite(bearing_sigma_rad) and bearing_sigma_rad > 0):
            raise ConfigError(f"BearingEkf: bearing_sigma_rad must be > 0, got "
                              f"{bearing_sigma_rad}")
        self.bearing_sigma_rad = float(bearing_sigma_rad)
        self.kf = _OdometryEkf(dim_x=3, dim_z=1, dim_u=3)
        self.kf.R = np.eye(1) * self.bearing_sigma_rad ** 2
        self._is_angle = np.array([False, False, True])
        self.observability_constrained = bool(observability_constrained)
        # the unobservable directions of the linearised system (global translation and
        # rotation), one row per state: [[1, 0, -y], [0, 1, x], [0, 0, 1]] for a pose
        self.nullspace = np.array([[1.0, 0.0, -pose0[1]], [0.0, 1.0, pose0[0]], [0, 0, 1.0]])
        self._set_state(np.array([pose0[0], pose0[1], float(wrap_angle(pose0[2]))]),
                        0.5 * (pose_cov0 + pose_cov0.T))

    # -- read access ------------------------------------------------------------------------
    @property
    def x(self) -> np.ndarray:
        """The state, shape ``(n,)`` (a view of filterpy's; do not modify)."""
        return self.kf.x

    @property
    def P(self) -> np.ndarray:  # noqa: N802 (the filter's own name)
        """The covariance, shape ``(n, n)``."""
        return self.kf.P

    @property
    def dim(self) -> int:
        return int(self.kf.dim_x)

    # -- structure --------------------------------------------------------------------------
    def _set_state(self, x: np.ndarray, P: np.ndarray) -> None:  # noqa: N803
        kf = self.kf
        n = len(x)
        kf.dim_x = n
        kf.x = x
        kf.P = P
        kf.F = np.eye(n)
        kf.Q = np.zeros((n, n))
        kf._I = np.eye(n)
        kf.K = np.zeros((n, kf.dim_z))
        kf.x_prior = x.copy()
        kf.x_post = x.copy()
        kf.P_prior = P.copy()
        kf.P_post = P.copy()

    def _wrap(self) -> None:
        x = self.kf.x
        x[self._is_angle] = wrap_angle(x[self._is_angle])

    def _difference(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """``a - b`` with the angle states differenced by ``angle_residual``."""
        d = a - b
        d[self._is_angle] = angle_residual(a[self._is_angle], b[self._is_angle])
        return d

    def augment(self, value: np.ndarray, idx: np.ndarray, jac: np.ndarray,
                noise_cov: np.ndarray, is_angle: np.ndarray) -> int:
        """Append ``m`` states ``value = g(x[idx], w)`` with ``w`` independent of the state.

        Parameters
        ----------
        value : array of shape (m,)
        idx : int array of shape (k,)
            The existing states ``g`` depends on.
        jac : array of shape (m, k)
            ``dg/dx[idx]``.
        noise_cov : array of shape (m, m)
            ``(dg/dw) Cov(w) (dg/dw)^T``.
        is_angle : bool array of shape (m,)
            Which new states are angles (wrapped after every update).

        Returns
        -------
        int
            The index of the first new state.
        """
        P = self.kf.P
        n, m = self.dim, len(value)
        cross = P[:, idx] @ jac.T
        new_p = np.empty((n + m, n + m))
        new_p[:n, :n] = P
        new_p[:n, n:] = cross
        new_p[n:, :n] = cross.T
        blk = jac @ cross[idx] + noise_cov
        new_p[n:, n:] = 0.5 * (blk + blk.T)
        self._is_angle = np.concatenate([self._is_angle, np.asarray(is_angle, bool)])
        self.nullspace = np.concatenate([self.nullspace, jac @ self.nullspace[idx]])
        self._set_state(np.concatenate([self.kf.x, np.asarray(value, float)]), new_p)
        self._wrap()
        return n

    def remove(self, idx: np.ndarray) -> None:
        """Marginalise the states ``idx`` out (drop their rows and columns)."""
        keep = np.ones(self.dim, bool)
        keep[np.asarray(idx, dtype=np.int64)] = False
        if np.any(~keep[:3]):
            raise ConfigError("BearingEkf.remove: the robot pose (states 0..2) cannot be removed")
        self._is_angle = self._is_angle[keep]
        self.nullspace = self.nullspace[keep]
        self._set_state(self.kf.x[keep], self.kf.P[np.ix_(keep, keep)])

    # -- filtering --------------------------------------------------------------------------
    def predict(self, odom: np.ndarray, odom_sigma: np.ndarray) -> None:
        """filterpy's predict with the odometry model: ``F = dF/dx``, ``Q = G Sigma_u G^T``.

        With ``observability_constrained`` the heading column of ``F`` is
        ``J (p_{k+1|k} - a_k)`` where ``a_k`` is the position the nullspace's rotation
        direction is anchored at (the previous prior, as in the first-estimates Jacobian),
        so that ``F N_k`` is again the nullspace of a rigid motion at the new prior position.
        ``N`` is propagated with the same ``F``.
        """
        kf = self.kf
        odom = np.asarray(odom, float)
        f_pose, g_odom = motion_jacobians(kf.x[:3], odom)
        if self.observability_constrained:
            anchor = np.array([self.nullspace[1, 2], -self.nullspace[0, 2]])
            d = compose(kf.x[:3], odom)[:2] - anchor
            f_pose[0, 2], f_pose[1, 2] = -d[1], d[0]
        self.nullspace[:3] = f_pose @ self.nullspace[:3]
        # F = I and Q = 0 outside the pose block (as _set_state made them; filterpy keeps them)
        kf.F[:3, :3] = f_pose
        kf.Q[:3, :3] = (g_odom * np.asarray(odom_sigma, float) ** 2) @ g_odom.T
        kf.predict(u=odom)
        self._wrap()

    def update(self, z_rad: np.ndarray, hx: Callable[[np.ndarray], np.ndarray],
               jac: Callable[[np.ndarray], np.ndarray],
               var_rad2: np.ndarray | None = None, iterations: int = 1,
               jac_iterate: Callable[[np.ndarray], np.ndarray] | None = None) -> None:
        """One batched bearing update by filterpy (Joseph form, wrapped residual).

        Parameters
        ----------
        z_rad : array of shape (k,)
        hx : callable ``x (n,) -> (k,)`` predicted bearings
        jac : callable ``x (n,) -> (k, n)`` their Jacobian
        var_rad2 : array of shape (k,), optional
            Variance of each bearing (default ``bearing_sigma_rad**2``); ``R = diag(var)``.
        iterations : int
            1: the EKF update. More: the iterated EKF (Gauss-Newton on the prior and the
            bearings; Bell and Cathey 1993): ``x_{i+1} = x_0 + K_i (z - h(x_i) - H_i (x_0 -
            x_i))`` with ``H_i``, ``K_i`` at ``x_i``. filterpy makes the last step, given the
            model linearised at the last iterate, ``h(x_i) + H_i (x - x_i)``, so ``P`` is
            ``(I - K_i H_i) P_0`` in Joseph form. Stops early once an iterate moves less
            than 1e-10.
        jac_iterate : callable, optional
            The Jacobian for the iterates (default ``jac``); ``jac`` is used for the last
            step. (The mappers iterate with the model's own Jacobian and make the last step
            with the observability-constrained one.)
        """
        kf = self.kf
        k = len(z_rad)
        z = np.asarray(z_rad, float)
        if var_rad2 is None:
            var_rad2 = np.full(k, self.bearing_sigma_rad ** 2)
        kf.dim_z = k
        r = np.diag(np.asarray(var_rad2, float))
        kf.R = r
        x0 = kf.x.copy()
        xi = x0
        jac_it = jac if jac_iterate is None else jac_iterate
        for _ in range(int(iterations) - 1):
            H = jac_it(xi)
            dx = self._difference(x0, xi)
            y = np.asarray(angle_residual(z, hx(xi))) - H @ dx
            s = H @ kf.P @ H.T + r
            step = kf.P @ H.T @ np.linalg.solve(s, y)
            x_next = x0 + step
            x_next[self._is_angle] = wrap_angle(x_next[self._is_angle])
            converged = np.max(np.abs(self._difference(x_next, xi))) < 1e-10
            xi = x_next
            if converged:
                break
        if xi is x0:
            kf.update(z, HJacobian=jac, Hx=hx, R=r, residual=angle_residual)
        else:
            h_i, H_i = hx(xi), jac(xi)
            kf.update(z, HJacobian=lambda x: H_i,
                      Hx=lambda x: h_i + H_i @ self._difference(x, xi), R=r,
                      residual=angle_residual)
        kf.P = 0.5 * (kf.P + kf.P.T)
        kf.P_post = kf.P.copy()
        self._wrap()
        kf.x_post = kf.x.copy()


# --------------------------------------------------------------------------------------------
# Mappers
# --------------------------------------------------------------------------------------------

_LM, _CLONE, _IDP = "lm", "clone", "idp"
_SIZE = {_LM: 2, _CLONE: 3, _IDP: 4}


def _check_common(config: "EkfConfig | InverseDepthConfig") -> None:
    """Validate the fields both configs share."""
    if not 0 < config.gate_probability <= 1:
        raise ConfigError(f"gate_probability must be in (0, 1] (1 disables the gate), got "
                          f"{config.gate_probability}")
    if len(config.initial_pose_sigma) != 3 or not all(
            math.isfinite(s) and s >= 0 for s in config.initial_pose_sigma):
        raise ConfigError("initial_pose_sigma must be 3 finite numbers >= 0 "
                          "(sigma_x_m, sigma_y_m, sigma_psi_rad)")
    if not config.max_bearing_nonlinearity > 0:
        raise ConfigError(f"max_bearing_nonlinearity must be > 0 (inf: no limit), got "
                          f"{config.max_bearing_nonlinearity}")
    if config.nonlinearity_frame not in ("world", "robot"):
        raise ConfigError(f"nonlinearity_frame must be 'world' or 'robot', got "
                          f"{config.nonlinearity_frame!r}")
    for name in ("rho_init_per_m", "rho_sigma_per_m"):
        value = getattr(config, name)
        if value is not None and not (math.isfinite(value) and value > 0):
            raise ConfigError(f"{name} must be a finite number > 0 or None (from the sensor "
                              f"range), got {value}")
    for name in ("iterations", "restart_after_gated"):
        value = getattr(config, name)
        if not ((value is None and name == "restart_after_gated")
                or (isinstance(value, (int, np.integer)) and value >= 1)):
            raise ConfigError(f"{name} must be an integer >= 1, got {value!r}")
    if not (math.isfinite(config.odometry_sigma_scale) and config.odometry_sigma_scale > 0):
        raise ConfigError(f"odometry_sigma_scale must be a finite number > 0, got "
                          f"{config.odometry_sigma_scale}")


def _from_preset(cls: type, presets: dict[str, dict[str, Any]], name: str,
                 options: dict[str, Any]) -> Any:
    if name not in presets:
        raise ConfigError(f"unknown {cls.__name__} preset {name!r}; choose one of "
                          f"{sorted(presets)}")
    return cls(**{**presets[name], **options})


@dataclass(frozen=True)
class EkfConfig:
    """Options of ``ekf`` (constrained initialisation). The defaults are the paper's setup.

    gate_probability : chi-square 1-dof probability of the per-bearing Mahalanobis gate
        (threshold ``chi2.ppf(p, 1)``; 1 disables the gate). Gated bearings are counted in
        ``info["gated_bearings"]``.
    init_kl_max : a candidate is initialised when the KL divergence (nats) between the
        unscented and the linearised Gaussian of its Euclidean estimate is below this
        (Bailey's test: of the two-ray triangulation, or with ``candidates="inverse-depth"``
        of the feature's conversion to ``[x, y]``).
    inconsistent_parallax_rad : rays crossing behind the robot at more than this parallax
        make the candidate restart from the current sighting (an outlier anchor).
    max_pending_steps : a candidate still not initialised after this many steps restarts.
    initial_pose_sigma : std. dev. of the first pose (zeros anchor the map frame to it).
    second_order : add the second-order variance of the bearing model to ``sigma^2``.
    max_bearing_nonlinearity : bearings with a larger nonlinearity index
        ``(C_rr C_pp)^(1/4) / |r|`` are not used (``inf``: all are); counted in
        ``info["nonlinear_bearings"]``.
    nonlinearity_frame : ``"robot"`` (default): ``C`` is the covariance of the landmark as the
        robot sees it, heading included (:func:`ray_covariance`), so an uncertain heading of
        the whole map, which leaves every bearing unchanged, does not count; ``"world"``: of
        ``l - p`` in world axes, as before (paper setup: MPE 1.83 -> 1.80 cm at t = 300, 3.46
        -> 3.34 cm at t = 50, robot NEES 4.9 -> 4.7 with "robot").
    observability_constrained : OC-EKF Jacobians (module docstring).
    use_intermediate_bearings : keep every sighting of a candidate (with a pose clone) and
        apply them once it is initialised (Bailey); False keeps only the first sighting.
    candidates : ``"clones"`` (Bailey: a pose clone per sighting, the bearings wait until the
        candidate is initialised) or ``"inverse-depth"`` (the candidate is an inverse-depth
        feature, as in ``ekf-invdepth``, updated by every bearing at once; it joins the map
        as ``[x, y]`` when Bailey's test passes on its conversion). See the module docstring.
    rho_init_per_m, rho_sigma_per_m : the inverse-depth prior of ``candidates="inverse-depth"``,
        as in :class:`InverseDepthConfig`.
    iterations : 1: the EKF update; more: the iterated EKF (:meth:`BearingEkf.update`).
    odometry_sigma_scale : multiplies every step's odometry sigma (process noise inflation).
    restart_after_gated : an inverse-depth feature whose bearings fail the gate this many
        times in a row is dropped and started again from the current sighting (its first
        bearing was an outlier); counted in ``info["restarted"]``. None: never.
    """

    gate_probability: float = 0.999
    init_kl_max: float = 0.01
    inconsistent_parallax_rad: float = math.radians(15.0)
    max_pending_steps: int = 30
    initial_pose_sigma: tuple[float, float, float] = (0.0, 0.0, 0.0)
    second_order: bool = True
    max_bearing_nonlinearity: float = 0.2
    nonlinearity_frame: str = "robot"
    observability_constrained: bool = True
    use_intermediate_bearings: bool = True
    candidates: str = "clones"
    rho_init_per_m: float | None = None
    rho_sigma_per_m: float | None = None
    iterations: int = 1
    odometry_sigma_scale: float = 1.0
    restart_after_gated: int | None = None

    def __post_init__(self) -> None:
        _check_common(self)
        if not (self.init_kl_max > 0):
            raise ConfigError(f"init_kl_max must be > 0, got {self.init_kl_max}")
        if not 0 < self.inconsistent_parallax_rad < math.pi:
            raise ConfigError("inconsistent_parallax_rad must be in (0, pi)")
        if self.max_pending_steps < 1:
            raise ConfigError(f"max_pending_steps must be >= 1, got {self.max_pending_steps}")
        if self.candidates not in ("clones", "inverse-depth"):
            raise ConfigError(f"candidates must be 'clones' (Bailey: pose clones, the bearings "
                              f"wait) or 'inverse-depth' (updated at once, made Euclidean when "
                              f"Gaussian), got {self.candidates!r}")

    @classmethod
    def preset(cls, name: str = "paper", **options: Any) -> "EkfConfig":
        """The config of preset ``name`` (:data:`EKF_PRESETS`), ``options`` replacing fields."""
        return _from_preset(cls, EKF_PRESETS, name, options)


@dataclass(frozen=True)
class InverseDepthConfig:
    """Options of ``ekf-invdepth`` (undelayed inverse-depth initialisation).

    gate_probability, initial_pose_sigma, second_order, max_bearing_nonlinearity,
    nonlinearity_frame, observability_constrained, iterations, odometry_sigma_scale,
    restart_after_gated : as in :class:`EkfConfig` (the second-order variance of an
        inverse-depth bearing is that of its term in ``rho``; its nonlinearity index is 0).
    rho_init_per_m, rho_sigma_per_m : prior inverse depth of a new feature and its std. dev.;
        None derives them from the header's sensor range ``R``: ``2/R`` and ``1/R``, so the
        2-sigma interval runs from infinity (Civera's rule) to ``R/4``; Civera's ``0.1`` and
        ``0.5`` per metre when the range is unknown. (Paper setup, 25 runs: ``1.5/R, 0.75/R``
        gave 3.4 cm MPE at t = 300, ``2/R, 1/R`` 2.7 cm, ``3/R, 2/R`` 3.7 cm.)
    linearity_max : Civera's linearity index below which a feature becomes Euclidean.
    """

    gate_probability: float = 0.999
    rho_init_per_m: float | None = None
    rho_sigma_per_m: float | None = None
    linearity_max: float = 0.1
    initial_pose_sigma: tuple[float, float, float] = (0.0, 0.0, 0.0)
    second_order: bool = True
    max_bearing_nonlinearity: float = 0.2
    nonlinearity_frame: str = "robot"
    observability_constrained: bool = True
    iterations: int = 1
    odometry_sigma_scale: float = 1.0
    restart_after_gated: int | None = None

    def __post_init__(self) -> None:
        _check_common(self)
        if not self.linearity_max > 0:
            raise ConfigError("linearity_max must be > 0")

    @classmethod
    def preset(cls, name: str = "paper", **options: Any) -> "InverseDepthConfig":
        """The config of preset ``name`` (:data:`INVDEPTH_PRESETS`), ``options`` replacing
        fields."""
        return _from_preset(cls, INVDEPTH_PRESETS, name, options)


#: Presets of ``ekf``: ``"paper"`` (the defaults) and ``"real"`` for recordings (MRCLAM6, the
#: g2o set; chosen with the measurements in the module docstring).
EKF_PRESETS: dict[str, dict[str, Any]] = {
    "paper": {},
    "real": {"candidates": "inverse-depth", "max_bearing_nonlinearity": math.inf,
             "iterations": 2, "restart_after_gated": 3},
}

#: Presets of ``ekf-invdepth``, as :data:`EKF_PRESETS`.
INVDEPTH_PRESETS: dict[str, dict[str, Any]] = {
    "paper": {},
    "real": {"max_bearing_nonlinearity": math.inf, "iterations": 2,
             "restart_after_gated": 3},
}


class _EkfSlam:
    """Shared machinery: state layout, predict, gated batch update, trajectory, estimate."""

    def __init__(self, header: StreamHeader, start_pose: tuple[float, float, float],
                 config: EkfConfig | InverseDepthConfig) -> None:
        self._header = header
        self.filter = BearingEkf(np.asarray(start_pose, dtype=float),
                                 np.diag(np.asarray(config.initial_pose_sigma, float) ** 2),
                                 header.bearing_sigma_rad, config.observability_constrained)
        p = config.gate_probability
        self._gate = float(chi2.ppf(p, 1)) if p < 1 else np.inf
        self._iterations = int(config.iterations)
        self._odom_scale = float(config.odometry_sigma_scale)
        rng_m = header.sensor_range_m
        self.rho_init = config.rho_init_per_m or (2.0 / rng_m if rng_m else 0.1)
        self.rho_sigma = config.rho_sigma_per_m or (1.0 / rng_m if rng_m else 0.5)
        self.n_converted = 0
        self.n_restarted = 0
        self._restart_after = config.restart_after_gated or math.inf
        self._gated_run: dict[int, int] = {}          # inverse-depth feature -> gated in a row
        self._sizes: dict[tuple[str, int], int] = {}
        self._offset: dict[tuple[str, int], int] = {}
        self._last_t: int | None = None
        self._pose_t: list[int] = []
        self._poses: list[np.ndarray] = []
        self._pose_covs: list[np.ndarray] = []
        self.n_gated = 0
        self.n_updates = 0
        self.n_nonlinear = 0
        self._max_nonlin = float(config.max_bearing_nonlinearity)
        self._robot_frame = config.nonlinearity_frame == "robot"
        self._second = bool(config.second_order)

    # -- layout -----------------------------------------------------------------------------
    def _rebuild(self) -> None:
        off = 3
        self._offset = {}
        for key, size in self._sizes.items():
            self._offset[key] = off
            off += size
        if off != self.filter.dim:
            raise RuntimeError("internal: state layout and filter size disagree")

    def _add_blocks(self, keys: list[tuple[str, int]], value: np.ndarray, idx: np.ndarray,
                    jac: np.ndarray, noise_cov: np.ndarray) -> None:
        is_angle = np.zeros(len(value), bool)
        pos = 0
        for key in keys:
            size = _SIZE[key[0]]
            if key[0] in (_CLONE, _IDP):
                is_angle[pos + 2] = True
            pos += size
        self.filter.augment(value, idx, jac, noise_cov, is_angle)
        for key in keys:
            self._sizes[key] = _SIZE[key[0]]
        self._rebuild()

    def _remove_blocks(self, keys: list[tuple[str, int]]) -> None:
        if not keys:
            return
        idx = np.concatenate([self._offset[k] + np.arange(self._sizes[k]) for k in keys])
        self.filter.remove(idx)
        for k in keys:
            del self._sizes[k]
        self._rebuild()

    def _block_index(self, offsets: np.ndarray, size: int) -> np.ndarray:
        return np.asarray(offsets, np.int64)[:, None] + np.arange(size)

    # -- measurement model ------------------------------------------------------------------
    def _model(self, pose_off: np.ndarray, kinds: np.ndarray, offsets: np.ndarray,
               constrained: bool = True
               ) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, list[Any]]]:
        """The bearing model for filterpy, memoised on ``x``.

        Bearings are taken from the poses at ``pose_off`` (0: the robot, else a clone) to the
        blocks at ``offsets`` of size ``kinds`` (2: Euclidean landmark, 4: inverse-depth
        feature). The returned function maps ``x`` to ``h (k,)``, the dense Jacobian
        ``H (k, n)`` and its nonzero part as ``[(row mask, columns (m, s), values (m, s))]``
        per kind (OC-constrained when the filter is and ``constrained``).
        """
        k = len(offsets)
        groups = []
        for size, fn in ((2, bearing_and_jacobian), (4, invdepth_bearing_and_jacobian)):
            sel = kinds == size
            if sel.any():
                cols = np.concatenate([self._block_index(pose_off[sel], 3),
                                       self._block_index(offsets[sel], size)], 1)
                groups.append((sel, np.flatnonzero(sel)[:, None], cols, fn))
        memo: dict[str, Any] = {}

        def both(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[Any]]:
            if "x" in memo and np.array_equal(memo["x"], x):
                return memo["h"], memo["H"], memo["parts"]
            h = np.empty(k)
            H = np.zeros((k, len(x)))
            parts = []
            for sel, rows, cols, fn in groups:
                v = x[cols]
                h[sel], j = fn(v[:, :3], v[:, 3:])
                if constrained and self.filter.observability_constrained:
                    j = self._constrain(j, cols)
                H[rows, cols] = j
                parts.append((sel, cols, j))
            memo.update(x=x.copy(), h=h, H=H, parts=parts)
            return h, H, parts

        return both

    def _constrain(self, jac: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Jacobian rows that satisfy ``h N = 0`` (observability-constrained EKF).

        ``N`` (n, 3) spans global translation and rotation of the linearised system
        (:attr:`BearingEkf.nullspace`); keeping ``H N = 0`` at every step keeps them
        unobservable, so the filter gains no spurious information about them (Huang, Mourikis
        and Roumeliotis, IJRR 2010). A row to a Euclidean landmark keeps its direction and is
        linearised at the closest point that satisfies the constraint: with ``u`` the unit
        vector of the current ray and ``a_l``, ``a_p`` the positions the landmark's and the
        pose's rows of ``N`` are anchored at, ``h_l = J u / L``, ``h_p = -h_l``,
        ``h_psi = -1`` with ``L = u . (a_l - a_p)``. Other rows (inverse-depth features, or
        ``L <= 0``) are projected, ``h <- h - (h N_S)(N_S^T N_S)^-1 N_S^T`` over their own
        columns ``S``.

        Parameters
        ----------
        jac : array of shape (m, s)
            Rows over the columns ``cols`` (pose first, then the landmark block).
        cols : int array of shape (m, s)

        Returns
        -------
        ndarray of shape (m, s)
        """
        N = self.filter.nullspace
        out = jac.copy()
        project = np.ones(len(jac), bool)
        if jac.shape[1] == 5:
            h_l = jac[:, 3:5]                                    # J u / |r|
            u = np.stack([h_l[:, 1], -h_l[:, 0]], 1)
            u /= np.sqrt(np.einsum("ki,ki->k", u, u))[:, None]
            a_l = np.stack([N[cols[:, 4], 2], -N[cols[:, 3], 2]], 1)
            a_p = np.stack([N[cols[:, 1], 2], -N[cols[:, 0], 2]], 1)
            length = np.einsum("ki,ki->k", u, a_l - a_p)
            ok = length > 1e-6
            new_l = np.stack([-u[ok, 1], u[ok, 0]], 1) / length[ok, None]
            out[ok, 3:5] = new_l
            out[ok, 0:2] = -new_l
            project = ~ok
        if project.any():
            ns = N[cols[project]]                                # (m, s, 3)
            h = jac[project]
            gram = np.einsum("msi,msj->mij", ns, ns)
            coef = np.linalg.solve(gram, np.einsum("ms,msi->mi", h, ns)[..., None])[..., 0]
            out[project] = h - np.einsum("msi,mi->ms", ns, coef)
        return out

    def _gated_update(self, pose_off: np.ndarray, kinds: np.ndarray, offsets: np.ndarray,
                      z: np.ndarray) -> np.ndarray:
        """Gate each bearing on its own NIS, then one batched filterpy update with the rest.

        The NIS of bearing ``i`` is ``y_i^2 / (H_i P H_i^T + var_i)`` with the wrapped
        innovation ``y_i`` and the variance of :meth:`_second_order`; it is compared with the
        chi-square 1-dof quantile. Bearings past ``max_bearing_nonlinearity`` are not used.
        With ``iterations > 1`` the iterates of the iterated update use the model's own
        Jacobians and only the last step the observability-constrained ones.

        Returns
        -------
        ndarray of shape (k,), bool
            The bearings that failed the gate.
        """
        model = self._model(pose_off, kinds, offsets)
        x, P = self.filter.x, self.filter.P
        h, _, parts = model(x)
        var = np.full(len(z), self.filter.bearing_sigma_rad ** 2)
        index = np.zeros(len(z))
        hph = np.zeros(len(z))
        for sel, cols, j in parts:
            block = P[cols[:, :, None], cols[:, None, :]]          # (m, s, s)
            hph[sel] = np.einsum("mi,mij,mj->m", j, block, j)
            var[sel], index[sel] = self._second_order(x[cols], block)
        usable = index <= self._max_nonlin
        gated = (np.asarray(angle_residual(z, h)) ** 2 / (hph + var) > self._gate) & usable
        self.n_nonlinear += int(np.count_nonzero(~usable))
        self.n_gated += int(np.count_nonzero(gated))
        keep = usable & ~gated
        if keep.any():
            # filterpy evaluates hx and jac at this same x: the memo computes them once
            plain = (self._model(pose_off, kinds, offsets, constrained=False)
                     if self._iterations > 1 and self.filter.observability_constrained
                     else model)
            self.filter.update(z[keep], lambda x: model(x)[0][keep],
                               lambda x: model(x)[1][keep], var[keep], self._iterations,
                               lambda x: plain(x)[1][keep])
            self.n_updates += int(np.count_nonzero(keep))
        return gated

    def _second_order(self, values: np.ndarray, block: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
        """Bearing variances with the second-order linearisation error; nonlinearity index.

        Euclidean landmark: for ``r = l - p`` with covariance ``C`` (``C_rr``, ``C_pp``,
        ``C_rp`` in the frame of the ray: radial, perpendicular) the second-order term of
        ``atan2`` is ``-d_r d_p / |r|^2``, of variance ``(C_rr C_pp + C_rp^2) / |r|^4``. The
        index ``(C_rr C_pp)^(1/4) / |r|`` measures how far the linearisation is to be
        trusted. Inverse-depth feature: the second-order term in ``rho``,
        ``h_rho_rho d_rho^2 / 2`` with ``h_rho_rho = -2 (v x d)(v . d) / |v|^4``
        (``d = a - p``, ``v = rho d + m``), of variance ``(h_rho_rho var_rho)^2 / 2``; index 0.
        With ``second_order`` the variance is added to ``sigma^2``; the mean of the term is not
        (it would move a filter fed noise-free data off the truth).

        Parameters
        ----------
        values : array of shape (m, 5) or (m, 7)
            The states of the rows' columns: pose ``[x, y, psi]`` then the landmark block.
        block : array of shape (m, s, s)
            Their covariance.

        Returns
        -------
        var_rad2 : ndarray of shape (m,)
        nonlinearity : ndarray of shape (m,)
        """
        m = len(values)
        var = np.full(m, self.filter.bearing_sigma_rad ** 2)
        if values.shape[1] == 7:
            if self._second:
                dvec = values[:, 3:5] - values[:, 0:2]
                rho, th = values[:, 6], values[:, 5]
                v = rho[:, None] * dvec + np.stack([np.cos(th), np.sin(th)], 1)
                vv = np.einsum("ki,ki->k", v, v)
                cross = v[:, 0] * dvec[:, 1] - v[:, 1] * dvec[:, 0]
                h_rr = -2.0 * cross * np.einsum("ki,ki->k", v, dvec) / (vv * vv)
                var += 0.5 * (h_rr * block[:, 6, 6]) ** 2
            return var, np.zeros(m)
        d2, c_rr, c_pp, c_rp = ray_covariance(values, block, self._robot_frame)
        prod = np.clip(c_rr * c_pp, 0, None)
        if self._second:
            var += (prod + c_rp ** 2) / (d2 * d2)
        return var, prod ** 0.25 / np.sqrt(d2)

    # -- inverse-depth features ---------------------------------------------------------------
    def _add_inverse_depth(self, ids: np.ndarray, z: np.ndarray) -> None:
        """Add first sightings as inverse-depth features anchored at the robot (Civera):
        ``[x, y, psi + z, rho_init]`` with ``rho ~ N(rho_init, rho_sigma^2)``."""
        if ids.size:
            m = ids.size
            x = self.filter.x
            value = np.column_stack([np.broadcast_to(x[:2], (m, 2)), wrap_angle(x[2] + z),
                                     np.full(m, self.rho_init)]).ravel()
            g = np.tile(np.vstack([np.eye(3), np.zeros((1, 3))]), (m, 1))      # (4m, 3)
            noise = np.diag(np.tile([0.0, 0.0, self.filter.bearing_sigma_rad ** 2,
                                     self.rho_sigma ** 2], m))
            self._add_blocks([(_IDP, int(i)) for i in ids], value, np.arange(3), g, noise)

    def _idp_blocks(self) -> tuple[list[tuple[str, int]], np.ndarray]:
        keys = [k for k in self._sizes if k[0] == _IDP]
        bi = self._block_index(np.array([self._offset[k] for k in keys], np.int64), 4)
        return keys, bi

    def _convert(self, ready: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> None:
        """Replace the inverse-depth features that ``ready(features (k, 4), covs (k, 4, 4))``
        selects by Euclidean ``[x, y]`` blocks (the exact linear map of their Gaussian)."""
        keys, bi = self._idp_blocks()
        if not keys:
            return
        x, P = self.filter.x, self.filter.P
        f = x[bi]
        sel = np.flatnonzero(ready(f, P[bi[:, :, None], bi[:, None, :]]) & (f[:, 3] > 0))
        if sel.size == 0:
            return
        pts, jac = invdepth_to_xy(f[sel])
        m = sel.size
        idx = bi[sel].ravel()
        g = np.zeros((2 * m, 4 * m))
        rows = 2 * np.arange(m)[:, None] + np.arange(2)
        cols = 4 * np.arange(m)[:, None] + np.arange(4)
        g[rows[:, :, None], cols[:, None, :]] = jac
        old = [keys[s] for s in sel]
        self._add_blocks([(_LM, k[1]) for k in old], pts.ravel(), idx, g,
                         np.zeros((2 * m, 2 * m)))
        self._remove_blocks(old)
        for k in old:
            self._gated_run.pop(k[1], None)
        self.n_converted += m

    def _update_mapped(self, ids: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Gate and apply the bearings to landmarks in the state; returns the mask of those."""
        in_state = np.zeros(len(ids), bool)
        kinds = np.zeros(len(ids), np.int64)
        offsets = np.zeros(len(ids), np.int64)
        for n, i in enumerate(ids.tolist()):
            for kind in (_LM, _IDP):
                off = self._offset.get((kind, i))
                if off is not None:
                    in_state[n], kinds[n], offsets[n] = True, _SIZE[kind], off
        if np.any(in_state):
            gated = self._gated_update(np.zeros(np.count_nonzero(in_state), np.int64),
                                       kinds[in_state], offsets[in_state], z[in_state])
            # an inverse-depth feature gated again and again was started from an outlier:
            # drop it; the current sighting starts it again (as a new sighting)
            restart = []
            for i, kind, g in zip(ids[in_state].tolist(), kinds[in_state].tolist(),
                                  gated.tolist()):
                if kind == _SIZE[_IDP]:
                    run_length = self._gated_run.get(i, 0) + 1 if g else 0
                    self._gated_run[i] = run_length
                    if run_length >= self._restart_after:
                        restart.append(i)
            if restart:
                self._remove_blocks([(_IDP, i) for i in restart])
                for i in restart:
                    del self._gated_run[i]
                in_state &= ~np.isin(ids, restart)
                self.n_restarted += len(restart)
        return in_state

    # -- the Mapper protocol ----------------------------------------------------------------
    def step(self, step: Step) -> None:
        """Predict with the step's odometry, update with its bearings, grow the map."""
        if self._last_t is not None and step.t <= self._last_t:
            raise ConfigError(f"steps must come in increasing t: got t = {step.t} after "
                              f"t = {self._last_t}")
        if step.odom is not None:
            self.filter.predict(step.odom,
                                self._odom_scale * step.odometry_sigma(self._header))
        ids, z = step.landmark_ids, step.bearings_rad
        if ids.size:
            if len(np.unique(ids)) != ids.size:
                raise ConfigError(f"step {step.t}: a landmark id appears twice")
            in_state = self._update_mapped(ids, z)
            self._new_sightings(step.t, ids[~in_state], z[~in_state])
        self._last_t = step.t
        self._pose_t.append(step.t)
        self._poses.append(self.filter.x[:3].copy())
        self._pose_covs.append(self.filter.P[:3, :3].copy())

    def _new_sightings(self, t: int, ids: np.ndarray, z: np.ndarray) -> None:
        raise NotImplementedError

    def _landmarks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Ids, positions ``(n, 2)`` and covariances ``(n, 2, 2)`` of the reportable landmarks."""
        keys = [k for k in self._sizes if k[0] == _LM]
        ids = np.array([k[1] for k in keys], np.int64)
        bi = self._block_index(np.array([self._offset[k] for k in keys], np.int64), 2)
        x, P = self.filter.x, self.filter.P
        return ids, x[bi].reshape(-1, 2), P[bi[:, :, None], bi[:, None, :]].reshape(-1, 2, 2), {}

    def estimate(self) -> MapEstimate:
        """The filtered map, the filtered trajectory (every step) and their covariances."""
        ids, xy, cov, info = self._landmarks()
        order = np.argsort(ids)
        info = dict(info)
        info.update(state_dim=self.filter.dim, gated_bearings=self.n_gated,
                    nonlinear_bearings=self.n_nonlinear, used_bearings=self.n_updates,
                    restarted=self.n_restarted)
        if not self._poses:
            return MapEstimate.empty(reason="no steps yet", **info)
        if ids.size == 0:
            info["reason"] = "no landmark initialised yet"
        return MapEstimate(ids[order], xy[order], pose_t=np.array(self._pose_t),
                           poses=np.array(self._poses), landmark_cov=cov[order],
                           pose_cov=np.array(self._pose_covs), info=info)


class EkfMapper(_EkfSlam):
    """Bearing-only EKF-SLAM with Bailey's constrained (delayed) initialisation (``ekf``).

    Parameters
    ----------
    header : StreamHeader
        Supplies the bearing and odometry sigmas.
    start_pose : (x_m, y_m, psi_rad)
        The first pose; the map is in this frame.
    config : EkfConfig, optional
        Or ``preset`` (:data:`EKF_PRESETS`: ``"paper"``, the default, or ``"real"``) and
        its fields as keyword options (they replace the preset's).
    """

    def __init__(self, header: StreamHeader, *, start_pose: tuple[float, float, float] =
                 (0.0, 0.0, 0.0), config: EkfConfig | None = None, preset: str = "paper",
                 **options: Any) -> None:
        if config is not None and (options or preset != "paper"):
            raise ConfigError("give either config= or preset= and options, not both")
        self.config = config or EkfConfig.preset(preset, **options)
        super().__init__(header, start_pose, self.config)
        # id -> sightings [(step, bearing), ...]; the first is the anchor
        self._candidates: dict[int, list[tuple[int, float]]] = {}
        self.n_reanchored = 0
        # why candidates seen again were not initialised: their rays do not cross in front of
        # both poses, or the KL divergence is above init_kl_max
        self.n_rejected = {"behind": 0, "kl": 0}

    def _triangulation_test(self, clone_off: np.ndarray, z1: np.ndarray, z2: np.ndarray
                            ) -> dict[str, np.ndarray]:
        """Triangulate candidates from their clones and the current pose; Bailey's test."""
        x, P = self.filter.x, self.filter.P
        m = len(z1)
        ci = self._block_index(clone_off, 3)
        ui = np.concatenate([ci, np.broadcast_to(np.arange(3), (m, 3))], 1)   # (m, 6)
        cov_u = np.zeros((m, 8, 8))
        cov_u[:, :6, :6] = P[ui[:, :, None], ui[:, None, :]]
        cov_u[:, 6, 6] = cov_u[:, 7, 7] = self.filter.bearing_sigma_rad ** 2
        pose_c = x[ci]
        pose_r = np.broadcast_to(x[:3], (m, 3))
        pts, jac = triangulate_two_bearings(pose_c, pose_r, z1, z2)
        cov_lin = jac @ cov_u @ jac.transpose(0, 2, 1)
        # unscented estimate of the same distribution (symmetric sigma points, equal weights)
        w, v = np.linalg.eigh(cov_u)
        sq = v * np.sqrt(8.0 * np.clip(w, 0.0, None))[:, None, :]      # columns, sqrt(n) spread
        mu = np.concatenate([pose_c, pose_r, z1[:, None], z2[:, None]], 1)      # (m, 8)
        sig = np.concatenate([mu[:, None, :] + sq.transpose(0, 2, 1),
                              mu[:, None, :] - sq.transpose(0, 2, 1)], 1)       # (m, 16, 8)
        sp, _, _ = _triangulate_point(sig[..., 0:3], sig[..., 3:6], sig[..., 6], sig[..., 7])
        with np.errstate(invalid="ignore", over="ignore"):
            mean_u = sp.mean(1)
            dev = sp - mean_u[:, None, :]
            cov_ut = np.einsum("msi,msj->mij", dev, dev) / sp.shape[1]
            kl = gaussian_kl_2d(mean_u, cov_ut, pts, cov_lin)
        kl[~np.isfinite(kl)] = np.inf
        # depth along both rays (in front of the robot at both sightings)
        d1 = pts - pose_c[:, :2]
        d2 = pts - pose_r[:, :2]
        a1 = pose_c[:, 2] + z1
        a2 = pose_r[:, 2] + z2
        front = (np.einsum("mi,mi->m", d1, np.column_stack([np.cos(a1), np.sin(a1)])) > 0) \
            & (np.einsum("mi,mi->m", d2, np.column_stack([np.cos(a2), np.sin(a2)])) > 0)
        parallax = np.abs(angle_residual(a2, a1))
        return {"points": pts, "jac": jac, "kl": kl, "front": front & np.isfinite(pts).all(1),
                "parallax": parallax, "noise_cov": self.filter.bearing_sigma_rad ** 2
                * (jac[:, :, 6:7] @ jac[:, :, 6:7].transpose(0, 2, 1)
                   + jac[:, :, 7:8] @ jac[:, :, 7:8].transpose(0, 2, 1)),
                "clone_index": ci}

    def _initialise(self, ids: np.ndarray, test: dict[str, np.ndarray], sel: np.ndarray) -> None:
        """Add the selected candidates' landmarks with their cross-covariances, then apply
        their stored intermediate bearings (taken from the clones) in one batched update."""
        m = int(np.count_nonzero(sel))
        ci = test["clone_index"][sel]                         # (m, 3)
        idx, inv = np.unique(np.concatenate([np.arange(3), ci.ravel()]), return_inverse=True)
        pose_cols = inv[:3]
        clone_cols = inv[3:].reshape(m, 3)
        jac = test["jac"][sel]
        g = np.zeros((2 * m, len(idx)))
        rows = 2 * np.arange(m)[:, None] + np.arange(2)       # (m, 2)
        g[rows[:, :, None], clone_cols[:, None, :]] += jac[:, :, 0:3]
        g[rows[:, :, None], np.broadcast_to(pose_cols, (m, 3))[:, None, :]] += jac[:, :, 3:6]
        noise = np.zeros((2 * m, 2 * m))
        noise[rows[:, :, None], rows[:, None, :]] = test["noise_cov"][sel]
        new_ids = ids[sel].tolist()
        self._add_blocks([(_LM, i) for i in new_ids], test["points"][sel].ravel(), idx, g,
                         noise)
        later = [(i, ts, zs) for i in new_ids for ts, zs in self._candidates.pop(i)[1:]]
        if later and self.config.use_intermediate_bearings:
            self._gated_update(np.array([self._offset[(_CLONE, ts)] for _, ts, _ in later],
                                        np.int64),
                               np.full(len(later), 2, np.int64),
                               np.array([self._offset[(_LM, i)] for i, _, _ in later],
                                        np.int64),
                               np.array([zs for _, _, zs in later]))

    def _gaussian_enough(self, features: np.ndarray, covs: np.ndarray) -> np.ndarray:
        """Bailey's test on the Euclidean form of inverse-depth candidates."""
        return invdepth_conversion_kl(features, covs) <= self.config.init_kl_max

    def _new_sightings(self, t: int, ids: np.ndarray, z: np.ndarray) -> None:
        if self.config.candidates == "inverse-depth":
            self._add_inverse_depth(ids, z)
            self._convert(self._gaussian_enough)
            return
        cand = np.array([i in self._candidates for i in ids.tolist()], bool)
        restart = ~cand
        extend = np.zeros(len(ids), bool)
        if np.any(cand):
            cid = ids[cand]
            first = [self._candidates[i][0] for i in cid.tolist()]
            anchor_t = np.array([f[0] for f in first], np.int64)
            z1 = np.array([f[1] for f in first])
            clone_off = np.array([self._offset[(_CLONE, int(a))] for a in anchor_t], np.int64)
            test = self._triangulation_test(clone_off, z1, z[cand])
            ready = test["front"] & (test["kl"] <= self.config.init_kl_max)
            self.n_rejected["behind"] += int(np.count_nonzero(~test["front"]))
            self.n_rejected["kl"] += int(np.count_nonzero(test["front"] & ~ready))
            bad = (~test["front"] & (test["parallax"] > self.config.inconsistent_parallax_rad)) \
                | ((t - anchor_t) >= self.config.max_pending_steps)
            bad &= ~ready
            self.n_reanchored += int(np.count_nonzero(bad))
            if np.any(ready):
                self._initialise(cid, test, ready)
            pos = np.flatnonzero(cand)
            restart[pos[bad]] = True
            extend[pos[~bad & ~ready]] = True
        for i, zi in zip(ids[restart].tolist(), z[restart].tolist()):
            self._candidates[i] = [(t, zi)]
        if self.config.use_intermediate_bearings:
            for i, zi in zip(ids[extend].tolist(), z[extend].tolist()):
                self._candidates[i].append((t, zi))
        if np.any(restart | extend) and (_CLONE, t) not in self._sizes:
            self._add_blocks([(_CLONE, t)], self.filter.x[:3].copy(), np.arange(3), np.eye(3),
                             np.zeros((3, 3)))
        used = {ts for sightings in self._candidates.values() for ts, _ in sightings}
        self._remove_blocks([k for k in self._sizes if k[0] == _CLONE and k[1] not in used])

    def _landmarks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        ids, xy, cov, _ = super()._landmarks()
        pending = sorted(self._candidates) + sorted(k[1] for k in self._sizes if k[0] == _IDP)
        return ids, xy, cov, {"pending": pending, "reanchored": self.n_reanchored,
                              "converted": self.n_converted,
                              **{f"init_rejected_{k}": v for k, v in self.n_rejected.items()}}


class InverseDepthEkfMapper(_EkfSlam):
    """Bearing-only EKF-SLAM with undelayed inverse-depth features (``ekf-invdepth``).

    Parameters
    ----------
    header : StreamHeader
    start_pose : (x_m, y_m, psi_rad)
    config : InverseDepthConfig, optional
        Or ``preset`` (:data:`INVDEPTH_PRESETS`) and its fields as keyword options.
    """

    def __init__(self, header: StreamHeader, *, start_pose: tuple[float, float, float] =
                 (0.0, 0.0, 0.0), config: InverseDepthConfig | None = None,
                 preset: str = "paper", **options: Any) -> None:
        if config is not None and (options or preset != "paper"):
            raise ConfigError("give either config= or preset= and options, not both")
        self.config = config or InverseDepthConfig.preset(preset, **options)
        super().__init__(header, start_pose, self.config)

    def _new_sightings(self, t: int, ids: np.ndarray, z: np.ndarray) -> None:
        self._add_inverse_depth(ids, z)
        self._convert(self._linear_enough)

    def _linear_enough(self, features: np.ndarray, covs: np.ndarray) -> np.ndarray:
        """Civera's linearity index ``4 sigma_d / d |cos alpha|`` below ``linearity_max``."""
        x = self.filter.x
        rho = features[:, 3]
        ok = rho > 0
        lin = np.full(len(rho), np.inf)
        if np.any(ok):
            sig_rho = np.sqrt(covs[ok, 3, 3])
            pts, _ = invdepth_to_xy(features[ok])
            d_vec = pts - x[:2]
            d = np.linalg.norm(d_vec, axis=1)
            m = np.column_stack([np.cos(features[ok, 2]), np.sin(features[ok, 2])])
            cos_a = np.einsum("ki,ki->k", m, d_vec) / d
            lin[ok] = 4.0 * (sig_rho / rho[ok] ** 2) / d * np.abs(cos_a)
        return lin < self.config.linearity_max

    def _landmarks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        ids, xy, cov, _ = super()._landmarks()
        keys, bi = self._idp_blocks()
        left_out: list[int] = []
        if keys:
            x, P = self.filter.x, self.filter.P
            f = x[bi]
            ok = f[:, 3] > 0
            left_out = sorted(k[1] for k, o in zip(keys, ok) if not o)
            if np.any(ok):
                pts, jac = invdepth_to_xy(f[ok])
                b = bi[ok]
                c = jac @ P[b[:, :, None], b[:, None, :]] @ jac.transpose(0, 2, 1)
                ids = np.concatenate([ids, [k[1] for k, o in zip(keys, ok) if o]]).astype(
                    np.int64)
                xy = np.concatenate([xy, pts])
                cov = np.concatenate([cov, c])
        return ids, xy, cov, {"inverse_depth": int(len(keys)), "left_out": left_out,
                              "converted": self.n_converted}


__all__ = ["BearingEkf", "EKF_PRESETS", "EkfConfig", "EkfMapper", "INVDEPTH_PRESETS",
           "InverseDepthConfig", "InverseDepthEkfMapper", "bearing_and_jacobian",
           "invdepth_bearing_and_jacobian", "invdepth_conversion_kl", "invdepth_to_xy",
           "ray_covariance", "triangulate_two_bearings", "gaussian_kl_2d", "motion_jacobians"]
