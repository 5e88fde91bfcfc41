"""The filter of the EKF baselines: a state that grows and shrinks, held by filterpy's
``ExtendedKalmanFilter``, with a predict and an update that exploit the structure of
bearing-only SLAM (paper section IV, Exp. 2).

:class:`BearingEkf` keeps the state ``x`` (shape ``(n,)``) and covariance ``P`` (``(n, n)``) in a
``filterpy.kalman.ExtendedKalmanFilter`` (``kf.x``, ``kf.P``; after an update also ``kf.y``
and ``kf.S`` of that batch; the gain ``K`` is never formed, so ``kf.K`` is filterpy's
initial zeros (3, 1), and ``kf.R`` stays the single-bearing ``bearing_sigma_rad**2`` set at
construction, not the batch's ``diag(var)``). The state is ``[x_m, y_m, psi_rad]`` of the robot followed by
blocks the mappers lay out (landmarks ``[x_m, y_m]``, pose clones ``[x_m, y_m, psi_rad]``,
inverse-depth features ``[x0_m, y0_m, theta_rad, rho_per_m]``).

Which part of filterpy is used, and why: the ``ExtendedKalmanFilter`` object holds the state,
and its ``update`` (``K = P H^T S^-1``, ``x + K y`` with a ``residual``, Joseph form) is the
reference the lean update is tested against (tests/baselines/test_ekf_filter.py, to 1e-12).
filterpy's ``predict`` and ``update`` are not called on the hot path: both are dense in the
full state (``F P F^T`` and ``(I - KH) P (I - KH)^T`` are ``O(n^3)``) and copy ``x`` and ``P``
four times per call, though ``F`` is the identity outside the pose block and a bearing touches
5 (landmark) or 7 (inverse-depth feature) states. Here, in place on ``kf.x`` and ``kf.P``:

- Predict: ``pose ⊕ u`` on ``x[:3]``; ``P_rr = F P_rr F^T + Q``, ``P_rm = F P_rm`` (the rest
  of ``P`` is unchanged), ``Q = G Sigma_u G^T`` with ``Sigma_u = diag(sigma_u**2)``
  (:func:`~baselines.ekf.models.motion_jacobians`). ``O(n)``.
- Update: a batch of ``k`` bearings whose Jacobian is given by its nonzero blocks
  (:data:`JacobianRows`); with ``U`` the states they touch, ``P H^T = P[:, U] H_U^T`` and
  ``S = H_U P[U, U] H_U^T + R``; ``x += K y`` (``y`` wrapped by
  :func:`bomgraph.angles.angle_residual`) and ``P -= W W^T`` with ``W = P H^T L^-T``,
  ``S = L L^T``: the covariance of the optimal gain (equal to filterpy's Joseph form for it),
  exactly symmetric. ``O(n^2 k)``. Optionally iterated (Gauss-Newton on the prior and the
  bearings; Bell and Cathey 1993).
- Observability constraints (OC-EKF, Huang, Mourikis and Roumeliotis, IJRR 2010): the
  nullspace ``N`` (n, 3) of global translation and rotation is carried with the state and the
  propagation Jacobian keeps ``F N_k = N_{k+1}``; the mappers linearise each bearing row so
  that ``h N = 0``.
- Size: the state may not exceed ``max_state`` entries; :meth:`BearingEkf.augment` raises
  :class:`StateLimitError` before allocating more (a dense ``n x n`` covariance of 8 ``n^2``
  bytes).
"""

from __future__ import annotations

import math
from typing import Callable, Sequence

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter
from scipy.linalg.lapack import dpotrf as _potrf, dtrtri as _trtri

from bomgraph.angles import angle_residual, wrap_angle
from bomgraph.errors import BomgraphError, ConfigError

#: A bearing Jacobian by its nonzero blocks: ``[(rows (m,), cols (m, s), values (m, s)), ...]``
#: (``H[rows[i], cols[i, j]] = values[i, j]``; within one row the columns are distinct).
JacobianRows = Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]]
#: ``x (n,) -> (h (k,), JacobianRows)``: predicted bearings and their Jacobian.
BearingModel = Callable[[np.ndarray], tuple[np.ndarray, JacobianRows]]


class StateLimitError(BomgraphError):
    """The filter's state would exceed its declared size (``max_state``)."""


class FilterNumericalError(BomgraphError):
    """The filter met numbers it cannot represent (an overflowing covariance, a non-positive
    innovation covariance); the state is left as it was before the failed operation."""


def rows_from_dense(H: np.ndarray) -> JacobianRows:  # noqa: N803
    """A dense Jacobian ``(k, n)`` as :data:`JacobianRows` (for tests and small models)."""
    k, n = H.shape
    return [(np.arange(k), np.broadcast_to(np.arange(n), (k, n)), H)]


def _compact(rows: JacobianRows, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The states ``U`` a Jacobian touches (sorted) and the dense ``H_U`` of shape ``(k, |U|)``."""
    everything = np.concatenate([c.ravel() for _, c, _ in rows]) if len(rows) > 1 \
        else rows[0][1].ravel()
    mark = np.zeros(everything.max() + 1, bool)
    mark[everything] = True
    cols = np.flatnonzero(mark)
    position = np.cumsum(mark) - 1                   # state index -> column of H_U
    hu = np.zeros((k, cols.size))
    for r, c, v in rows:
        hu[r[:, None], position[c]] = v
    return cols, hu


class BearingEkf:
    """A planar bearing-only EKF with a state that grows and shrinks (held by filterpy).

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
    max_state : int, optional
        The largest state allowed (:class:`StateLimitError` beyond it); None: no limit.
    limit_hint : str
        Appended to the :class:`StateLimitError` message (which option raises the limit).
    """

    def __init__(self, pose0: np.ndarray, pose_cov0: np.ndarray,
                 bearing_sigma_rad: float, observability_constrained: bool = False,
                 max_state: int | None = None, limit_hint: str = "") -> None:
        pose0 = np.asarray(pose0, dtype=float).reshape(3)
        pose_cov0 = np.asarray(pose_cov0, dtype=float).reshape(3, 3)
        if not (np.all(np.isfinite(pose0)) and np.all(np.isfinite(pose_cov0))):
            raise ConfigError("BearingEkf: the initial pose and its covariance must be finite")
        if not (math.isfinite(bearing_sigma_rad) and 0 < bearing_sigma_rad <= math.pi):
            raise ConfigError(f"BearingEkf: bearing_sigma_rad must be in (0, pi] (a larger "
                              f"sigma carries no information), got {bearing_sigma_rad}")
        self.bearing_sigma_rad = float(bearing_sigma_rad)
        self.max_state = max_state
        self._limit_hint = limit_hint
        self.kf = ExtendedKalmanFilter(dim_x=3, dim_z=1)
        self.kf.R = np.eye(1) * self.bearing_sigma_rad ** 2
        self._is_angle = np.array([False, False, True])
        self._angle_index = np.array([2])
        self.observability_constrained = bool(observability_constrained)
        #: incremented by every change of ``x`` or ``P`` (models memoise on it)
        self.version = 0
        # the unobservable directions of the linearised system (global translation and
        # rotation), one row per state: [[1, 0, -y], [0, 1, x], [0, 0, 1]] for a pose
        self.nullspace = np.array([[1.0, 0.0, -pose0[1]], [0.0, 1.0, pose0[0]], [0, 0, 1.0]])
        self._set_state(np.array([pose0[0], pose0[1], float(wrap_angle(pose0[2]))]),
                        0.5 * (pose_cov0 + pose_cov0.T))

    # -- read access ------------------------------------------------------------------------
    @property
    def x(self) -> np.ndarray:
        """The state, shape ``(n,)`` (filterpy's array; do not modify)."""
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
        self.version += 1
        self.kf.dim_x = len(x)
        self.kf.x = x
        self.kf.P = P

    def _difference(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """``a - b`` with the angle states differenced by ``angle_residual``."""
        d = a - b
        d[self._is_angle] = angle_residual(a[self._is_angle], b[self._is_angle])
        return d

    def check_room(self, m: int, what: str = "") -> None:
        """Raise :class:`StateLimitError` if ``m`` more states would exceed ``max_state``
        (``what`` names them in the message, e.g. "2500 new landmarks")."""
        n = self.dim
        if self.max_state is not None and n + m > self.max_state:
            grow = f" with {what}" if what else ""
            raise StateLimitError(
                f"the EKF state would grow{grow} to {n + m} entries (a dense covariance of "
                f"{8 * (n + m) ** 2 / 2 ** 30:.2f} GiB), beyond its limit of {self.max_state}"
                f"{self._limit_hint}")

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
        noise_cov : array of shape (m, m), or (m,) for a diagonal one
            ``(dg/dw) Cov(w) (dg/dw)^T``.
        is_angle : bool array of shape (m,)
            Which new states are angles (wrapped after every update).

        Returns
        -------
        int
            The index of the first new state.

        Raises
        ------
        StateLimitError
            If ``n + m`` exceeds ``max_state`` (checked before anything is allocated).
        """
        P = self.kf.P
        n, m = self.dim, len(value)
        self.check_room(m)
        cross = P[:, idx] @ jac.T
        new_p = np.empty((n + m, n + m))
        new_p[:n, :n] = P
        new_p[:n, n:] = cross
        new_p[n:, :n] = cross.T
        blk = jac @ cross[idx]
        noise_cov = np.asarray(noise_cov, float)
        if noise_cov.ndim == 1:
            blk[np.diag_indices(m)] += noise_cov
        else:
            blk += noise_cov
        new_p[n:, n:] = 0.5 * (blk + blk.T)
        angle = np.asarray(is_angle, bool)
        self._is_angle = np.concatenate([self._is_angle, angle])
        self._angle_index = np.flatnonzero(self._is_angle)
        self.nullspace = np.concatenate([self.nullspace, jac @ self.nullspace[idx]])
        new_x = np.concatenate([self.kf.x, np.asarray(value, float)])
        new_x[n:][angle] = wrap_angle(new_x[n:][angle])
        self._set_state(new_x, new_p)
        return n

    def clone(self, idx: np.ndarray) -> int:
        """Append a copy of the states ``idx`` (stochastic cloning): :meth:`augment` with
        ``g`` the identity and no noise, without its products. Returns the first new index."""
        P = self.kf.P  # noqa: N806
        n, m = self.dim, len(idx)
        self.check_room(m)
        new_p = np.empty((n + m, n + m))
        new_p[:n, :n] = P
        new_p[:n, n:] = P[:, idx]
        new_p[n:] = new_p[idx]
        self._is_angle = np.concatenate([self._is_angle, self._is_angle[idx]])
        self._angle_index = np.flatnonzero(self._is_angle)
        self.nullspace = np.concatenate([self.nullspace, self.nullspace[idx]])
        self._set_state(np.concatenate([self.kf.x, self.kf.x[idx]]), new_p)
        return n

    def remove(self, idx: np.ndarray) -> None:
        """Marginalise the states ``idx`` out (drop their rows and columns)."""
        keep = np.ones(self.dim, bool)
        keep[np.asarray(idx, dtype=np.int64)] = False
        if np.any(~keep[:3]):
            raise ConfigError("BearingEkf.remove: the robot pose (states 0..2) cannot be removed")
        self._is_angle = self._is_angle[keep]
        self._angle_index = np.flatnonzero(self._is_angle)
        self.nullspace = self.nullspace[keep]
        k = np.flatnonzero(keep)
        self._set_state(self.kf.x[k], self.kf.P[k[:, None], k])

    def retract(self, idx: np.ndarray, var: float) -> None:
        """Take out of the state the information of direct measurements ``0 = x_i + v_i``,
        ``v_i ~ N(0, var)`` independent, ``i`` in ``idx``, that earlier updates (or
        ``augment``) put in: the inverse of their EKF update, in place. With ``S = var I -
        P[idx, idx]`` (the residuals' covariance), ``x += P[:, idx] S^-1 x[idx]``, ``P +=
        P[:, idx] S^-1 P[idx, :]`` (the information form ``P'^-1 = P^-1 - E E^T / var``).
        ``O(n^2 k)``.

        Raises
        ------
        FilterNumericalError
            If ``S`` is not positive definite (the rest of the state does not know those
            states at all); the state is left as it was.
        """
        kf = self.kf
        idx = np.asarray(idx, np.int64)
        cols = kf.P[:, idx]                                       # (n, k)
        s = var * np.eye(idx.size) - cols[idx]
        chol, info = _potrf(0.5 * (s + s.T), lower=1)
        if info == 0:
            l_inv, info = _trtri(chol, lower=1)
        if info != 0 or not math.isfinite(float(chol.sum())):
            raise FilterNumericalError(f"cannot retract the measurements of states "
                                       f"{idx.tolist()}: the rest of the state does not know "
                                       f"them (variance {var} against theirs)")
        w = cols @ l_inv.T                                        # P[:, idx] L^-T
        self.version += 1
        kf.x += w @ (l_inv @ kf.x[idx])
        kf.x[self._angle_index] = wrap_angle(kf.x[self._angle_index])
        kf.P += w @ w.T

    # -- filtering --------------------------------------------------------------------------
    def predict(self, odom: np.ndarray, odom_sigma: np.ndarray,
                odom_cov_extra: np.ndarray | None = None) -> None:
        """Odometry predict on the pose block: ``x_r = x_r ⊕ u``, ``P_rr = F P_rr F^T + Q``,
        ``P_rm = F P_rm`` (``F = d(x_r ⊕ u)/dx_r``, ``Q = G Sigma_u G^T``,
        ``Sigma_u = diag(odom_sigma**2)`` plus ``odom_cov_extra``, a symmetric (3, 3)
        covariance of ``u`` in the odometry frame, m^2 / m rad / rad^2, when given).

        With ``observability_constrained`` the heading column of ``F`` is
        ``J (p_{k+1|k} - a_k)`` where ``a_k`` is the position the nullspace's rotation
        direction is anchored at (the previous prior, as in the first-estimates Jacobian),
        so that ``F N_k`` is again the nullspace of a rigid motion at the new prior position.
        ``N`` is propagated with the same ``F``.
        """
        x, P = self.kf.x, self.kf.P
        # the 3 x 3 pose block in Python floats (numpy's per-call cost exceeds the arithmetic)
        ux, uy, upsi = np.ravel(odom).astype(float).tolist()
        va, vb, vc = (v * v for v in np.ravel(odom_sigma).tolist())   # inf, not OverflowError
        px, py, psi = x[:3].tolist()
        c, s = math.cos(psi), math.sin(psi)
        nx, ny = px + c * ux - s * uy, py + s * ux + c * uy          # pose ⊕ u (compose)
        npsi = float(wrap_angle(psi + upsi))
        N = self.nullspace                                    # noqa: N806
        if self.observability_constrained:
            # the anchor a_k = [N[1, 2], -N[0, 2]]; the column is J (p_{k+1|k} - a_k)
            f0, f1 = -(ny + float(N[0, 2])), nx - float(N[1, 2])
        else:                           # F = [[1, 0, f0], [0, 1, f1], [0, 0, 1]]
            f0, f1 = -s * ux - c * uy, c * ux - s * uy
        (p00, p01, p02), (p10, p11, p12), (p20, p21, p22) = P[:3, :3].tolist()
        a0, a1, a2 = p00 + f0 * p20, p01 + f0 * p21, p02 + f0 * p22      # F P
        b0, b1, b2 = p10 + f1 * p20, p11 + f1 * p21, p12 + f1 * p22
        r00, r01, r02 = a0 + f0 * a2, a1 + f1 * a2, a2                   # F P F^T
        r10, r11, r12 = b0 + f0 * b2, b1 + f1 * b2, b2
        r20, r21, r22 = p20 + f0 * p22, p21 + f1 * p22, p22
        cs = c * s * (va - vb)                                # Q = G diag(sigma_u^2) G^T
        rr = [[r00 + (c * c * va + s * s * vb), 0.5 * (r01 + r10) + cs, 0.5 * (r02 + r20)],
              [0.0, r11 + (s * s * va + c * c * vb), 0.5 * (r12 + r21)],
              [0.0, 0.0, r22 + vc]]
        rr[1][0], rr[2][0], rr[2][1] = rr[0][1], rr[0][2], rr[1][2]
        if odom_cov_extra is not None:                        # G E G^T, G = blockdiag(R, 1)
            g = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            e = np.asarray(odom_cov_extra, float)
            rr = (np.array(rr) + g @ (0.5 * (e + e.T)) @ g.T).tolist()
        with np.errstate(over="ignore", invalid="ignore"):
            rm = P[:2, 3:] + np.multiply.outer((f0, f1), P[2, 3:])   # F P_rm (row 2 as is)
            # one check: a sum is finite only if every term is (inf - inf is nan)
            finite = math.isfinite(float(rm.sum()) + sum(rr[0]) + sum(rr[1]) + rr[2][2]
                                   + nx + ny + npsi)
        if not finite:
            raise FilterNumericalError(
                f"the predicted pose or its covariance overflows (odometry "
                f"{np.ravel(odom).tolist()}, sigma {np.ravel(odom_sigma).tolist()}): the "
                f"odometry or its sigma is beyond what the filter can represent")
        self.version += 1
        n0, n1, n2 = N[:3].tolist()
        N[:2] = [[n0[i] + f0 * n2[i] for i in range(3)], [n1[i] + f1 * n2[i] for i in range(3)]]
        P[:3, :3] = rr
        if len(x) > 3:
            P[:2, 3:] = rm
            P[3:, :2] = rm.T
        x[:3] = (nx, ny, npsi)

    def decay(self, idx: np.ndarray, factor: np.ndarray, noise_var: np.ndarray) -> None:
        """A first-order Gauss-Markov step of scalar states, in place: ``x_i <- a_i x_i + n_i``
        with independent ``n_i ~ N(0, q_i)``; ``P`` rows and columns ``i`` scaled by ``a_i``,
        ``q_i`` added to the diagonal. ``O(n k)``.

        Parameters
        ----------
        idx : int array of shape (k,), distinct
        factor : array of shape (k,)
            ``a_i``.
        noise_var : array of shape (k,)
            ``q_i``.
        """
        x, P = self.kf.x, self.kf.P
        self.version += 1
        a = np.asarray(factor, float)
        x[idx] *= a
        P[idx, :] *= a[:, None]
        P[:, idx] *= a
        P[idx, idx] += noise_var
        self.nullspace[idx] *= a[:, None]

    def update(self, z_rad: np.ndarray, model: BearingModel,
               var_rad2: np.ndarray | None = None, iterations: int = 1,
               model_iterate: BearingModel | None = None,
               innovation: np.ndarray | None = None) -> None:
        """One batched bearing update, in place on filterpy's ``x`` and ``P``.

        Parameters
        ----------
        z_rad : array of shape (k,)
        model : callable ``x (n,) -> (h (k,), JacobianRows)``
            Predicted bearings and their sparse Jacobian (:data:`JacobianRows`).
        var_rad2 : array of shape (k,), optional
            Variance of each bearing (default ``bearing_sigma_rad**2``); ``R = diag(var)``.
        iterations : int
            1: the EKF update. More: the iterated EKF (Gauss-Newton on the prior and the
            bearings; Bell and Cathey 1993): ``x_{i+1} = x_0 + K_i (z - h(x_i) - H_i (x_0 -
            x_i))`` with ``H_i``, ``K_i`` at ``x_i``. The last step is the EKF update with the
            model linearised at the last iterate, ``h(x_i) + H_i (x - x_i)``, so ``P`` is
            ``(I - K_i H_i) P_0``. Stops early once an iterate moves less than 1e-10.
        model_iterate : callable, optional
            The model for the iterates (default ``model``); ``model`` is used for the last
            step. (The mappers iterate with the model's own Jacobian and make the last step
            with the observability-constrained one.)
        innovation : array of shape (k,), optional
            ``angle_residual(z, h(x))`` at the current state if the caller has it already.
        """
        kf = self.kf
        x0, P = kf.x, kf.P
        z = np.asarray(z_rad, float)
        k = len(z)
        var = (np.full(k, self.bearing_sigma_rad ** 2) if var_rad2 is None
               else np.asarray(var_rad2, float))
        xi = x0
        it_model = model if model_iterate is None else model_iterate
        for _ in range(int(iterations) - 1):
            h, rows = it_model(xi)
            cols, hu = _compact(rows, k)
            y = np.asarray(angle_residual(z, h)) - hu @ self._difference(x0, xi)[cols]
            hp = hu @ P[cols]                                     # H P, (k, n)
            s = hp[:, cols] @ hu.T + np.diag(var)
            # A singular S fails like _apply's check: the state is untouched (numpy 2.0-2.3
            # raise here after the 1e12 m step of tests/baselines/test_ekf_hostile.py)
            try:
                x_next = x0 + np.linalg.solve(s, y) @ hp
            except np.linalg.LinAlgError:
                raise FilterNumericalError(
                    "the innovation covariance of the bearing update is not positive definite "
                    "or not finite (the update is skipped)") from None
            x_next[self._is_angle] = wrap_angle(x_next[self._is_angle])
            converged = np.max(np.abs(self._difference(x_next, xi))) < 1e-10
            xi = x_next
            if converged:
                break
        h, rows = model(xi)
        cols, hu = _compact(rows, k)
        if xi is not x0:           # the model linearised at x_i, h_i + H_i (x_0 - x_i)
            y = np.asarray(angle_residual(z, h + hu @ self._difference(x0, xi)[cols]))
        else:
            y = np.asarray(angle_residual(z, h)) if innovation is None else innovation
        self.update_compact(cols, hu, y, var)

    def update_compact(self, cols: np.ndarray, hu: np.ndarray, y: np.ndarray,
                       var: np.ndarray) -> None:
        """The EKF update with a Jacobian given by the states it touches, in place.

        Parameters
        ----------
        cols : int array of shape (u,), sorted, distinct
            The states ``U`` the bearings touch.
        hu : array of shape (k, u)
            ``H[:, U]`` (``H`` is zero elsewhere).
        y : array of shape (k,)
            The wrapped innovations ``z - h(x)``.
        var : array of shape (k,)
            The bearing variances (``R = diag(var)``).
        """
        hp = hu @ self.kf.P[cols]                                 # H P = (P H^T)^T, (k, n)
        self._apply(hp, hp[:, cols] @ hu.T, y, var)

    def update_rows(self, cols: np.ndarray, jac: np.ndarray, y: np.ndarray,
                    var: np.ndarray) -> None:
        """The EKF update with a Jacobian given row by row by its nonzeros, in place.

        Parameters
        ----------
        cols : int array of shape (k, s)
            The states bearing ``i`` touches (distinct within a row, or repeated with a zero
            in ``jac``).
        jac : array of shape (k, s)
            ``H[i, cols[i]]``.
        y, var : arrays of shape (k,)
            As in :meth:`update_compact`.
        """
        hp = (jac[:, None, :] @ self.kf.P[cols])[:, 0]            # H P, (k, n)
        # (H P H^T)^T: row b is sum_s H[b, s] (H P)[:, cols[b, s]] (symmetrised in _apply)
        self._apply(hp, (hp[:, cols].transpose(1, 0, 2) @ jac[:, :, None])[..., 0], y, var)

    def _apply(self, hp: np.ndarray, s: np.ndarray, y: np.ndarray, var: np.ndarray) -> None:
        """``x += K y``, ``P -= K S K^T`` from ``H P`` (k, n) and ``H P H^T`` (k, k)."""
        kf = self.kf
        x0, P = kf.x, kf.P
        k = len(y)
        s = 0.5 * (s + s.T)
        s.flat[::k + 1] += var                                    # S = H P H^T + R
        chol, info = _potrf(s, lower=1)                           # S = L L^T
        if info == 0:
            l_inv, info = _trtri(chol, lower=1)
        with np.errstate(over="ignore", invalid="ignore"):
            finite = info == 0 and math.isfinite(chol.sum() + hp.sum() + y.sum())
        if not finite:
            raise FilterNumericalError("the innovation covariance of the bearing update is not "
                                       "positive definite or not finite (the update is skipped)")
        self.version += 1
        w_t = l_inv @ hp                                          # L^-1 H P = W^T, (k, n)
        x0 += (l_inv @ y) @ w_t                                   # x + K y, K = W L^-1
        angles = self._angle_index
        x0[angles] = wrap_angle(x0[angles])
        P -= w_t.T @ w_t                                          # P - K S K^T (symmetric)
        kf.S, kf.y = s, y


__all__ = ["BearingEkf", "BearingModel", "FilterNumericalError", "JacobianRows",
           "StateLimitError", "rows_from_dense"]
