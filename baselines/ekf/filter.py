"""The filter of the EKF baselines: filterpy's ``ExtendedKalmanFilter`` with a state that grows
and shrinks (paper section IV, Exp. 2).

:class:`BearingEkf` wraps ``filterpy.kalman.ExtendedKalmanFilter``: filterpy runs every predict
and update; the wrapper builds it complete and resizes all its state-sized arrays together. The
state is ``[x_m, y_m, psi_rad]`` of the robot followed by blocks the mappers lay out (landmarks
``[x_m, y_m]``, pose clones ``[x_m, y_m, psi_rad]``, inverse-depth features ``[x0_m, y0_m,
theta_rad, rho_per_m]``); it is 1-D, shape ``(n,)``.

- Predict: filterpy's ``predict`` is linear, so :class:`_OdometryEkf` overrides ``predict_x``
  with ``pose ⊕ u`` and ``F`` is its Jacobian (identity outside the pose); the odometry noise
  ``Sigma_u = diag(sigma_u**2)`` enters as ``Q = G Sigma_u G^T``
  (:func:`~baselines.ekf.models.motion_jacobians`).
- Update: a batch of bearings, ``residual=bomgraph.angles.angle_residual`` (innovations
  straddling +-pi are small, never 2 pi), Joseph form ``P = (I-KH) P (I-KH)^T + K R K^T``;
  optionally iterated (Gauss-Newton on the prior and the bearings; Bell and Cathey 1993).
- Observability constraints (OC-EKF, Huang, Mourikis and Roumeliotis, IJRR 2010): the
  nullspace ``N`` (n, 3) of global translation and rotation is carried with the state and the
  propagation Jacobian keeps ``F N_k = N_{k+1}``; the mappers linearise each bearing row so
  that ``h N = 0``.
"""

from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from bomgraph.angles import angle_residual, wrap_angle
from bomgraph.errors import ConfigError
from bomgraph.geometry import compose

from .models import motion_jacobians


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
    observability_constrained : bool
        Propagate with the OC-EKF Jacobian (the mappers always do; False gives the plain EKF
        predict, which the filter's own tests check).

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


__all__ = ["BearingEkf"]
