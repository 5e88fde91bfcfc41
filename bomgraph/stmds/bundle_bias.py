"""Second-order bias of a window bundle's solution (``tri_bias_correction``).

The window's least-squares estimate is the maximum-likelihood one, but its residuals are
nonlinear in the unknowns (a bearing in the landmark's offset from the pose, an odometry
increment in the heading of the pose it starts from), and a nonlinear least-squares estimate
is biased at order ``sigma^2``. For whitened residuals ``r_i(x)`` with unit noise, Jacobian
``J`` and Hessians ``H_i``, Box (1971) gives the bias

    b = -1/2 (J^T J)^-1 J^T d,        d_i = tr((J^T J)^-1 H_i),

to order ``sigma^2``. A landmark seen at low parallax is the textbook case: its depth is
nonlinear in the bearings and its estimate errs long with one sign. The solution minus ``b``
is unbiased to that order.

Hessians (exact, analytic): a bearing residual ``atan2(p - z) - psi - theta`` has the Hessian
``H`` of :func:`~bomgraph.geometry.bearing_hessian` in the landmark ``p`` and in the position
``z`` of its pose, ``-H`` between them, nothing in ``psi``; an odometry residual
``R(-psi_a) (z_b - z_a) - u`` has second derivatives only in the start pose's heading
``psi_a`` (with itself and with the positions of both poses); the heading residual is linear.
"""

from __future__ import annotations

import numpy as np

from ..geometry import bearing_hessian
from .bundle_lm import _between_residuals, _Problem


def residual_hessian_traces(prob: _Problem, poses: np.ndarray, points: np.ndarray,
                            cov: np.ndarray) -> np.ndarray:
    """``tr(cov H_i)`` of every whitened residual of the window problem.

    Parameters
    ----------
    prob : the window's problem (its rays, odometry and weights).
    poses : array of shape (W, 3)
        The window's poses (the first one fixed: the gauge).
    points : array of shape (L, 2)
        Its landmarks, in the problem's order.
    cov : array of shape (n, n), symmetric
        Over the problem's variables (poses 1..W-1, then the landmarks; ``prob.n``).

    Returns
    -------
    ndarray of shape (prob.rows,)
        In the order of :meth:`_Problem.linearise`'s rows: the odometry rows ``(W - 1, 3)``
        flattened, then the bearing rows; dimensionless (whitened).
    """
    n_p = prob.n_pose_vars
    two = np.arange(2)
    # bearing rows: H on (p, p) and (z, z), -H on (p, z): tr(cov H) = <H, S>, S the covariance
    # of the offset p - z
    k, lm = prob.k, prob.lm
    hess = bearing_hessian(points[lm] - poses[k, :2])                          # (R, 2, 2)
    lc = n_p + 2 * lm[:, None] + two                                          # (R, 2)
    s = cov[lc[:, :, None], lc[:, None, :]]
    pc = prob.pose_col[k]
    var = pc >= 0
    zc = pc[var, None] + two
    cross = cov[lc[var][:, :, None], zc[:, None, :]]
    s[var] += cov[zc[:, :, None], zc[:, None, :]] - cross - cross.transpose(0, 2, 1)
    d_bearing = np.einsum("rab,rab->r", hess, s) * prob.w_b
    # odometry rows: second derivatives in the start pose's heading only (none from pose 0)
    m = len(prob.odoms)
    d_odo = np.zeros((m, 3))
    if m > 1:
        a, b = poses[1:-1], poses[2:]
        c, sn = np.cos(a[:, 2]), np.sin(a[:, 2])
        dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
        ca = prob.pose_col[1:-1]                       # columns of the start poses
        cb = prob.pose_col[2:]
        s_pp = cov[ca + 2, ca + 2]
        # cov of psi_a with the offset z_b - z_a
        s_px = cov[ca + 2, cb] - cov[ca + 2, ca]
        s_py = cov[ca + 2, cb + 1] - cov[ca + 2, ca + 1]
        along = c * dx + sn * dy
        lateral = -sn * dx + c * dy
        d_odo[1:, 0] = -along * s_pp + 2.0 * (-sn * s_px + c * s_py)
        d_odo[1:, 1] = -lateral * s_pp + 2.0 * (-c * s_px - sn * s_py)
        d_odo *= prob.w_odo
    return np.concatenate([d_odo.ravel(), d_bearing])


def second_order_bias(prob: _Problem, poses: np.ndarray, points: np.ndarray,
                      cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Box's order-``sigma^2`` bias of the window's solution ``(poses, points)``.

    Parameters
    ----------
    prob, poses, points : the problem and its least-squares solution.
    cov : array of shape (n, n)
        ``(J^T J)^-1`` at the solution (whitened; the first-order covariance).

    Returns
    -------
    (ndarray (W, 3), ndarray (L, 2))
        The bias of the poses (zero for the first, the gauge; m, m, rad) and of the
        landmarks (m): subtract them from the solution.
    """
    _, jac = prob.linearise(poses, points)
    d = residual_hessian_traces(prob, poses, points, cov)
    b = -0.5 * (cov @ (jac.T @ d))
    pose_bias = np.zeros_like(poses)
    pose_bias[1:] = b[:prob.n_pose_vars].reshape(-1, 3)
    return pose_bias, b[prob.n_pose_vars:].reshape(-1, 2)


def corrected_squared_distance(e: np.ndarray, cov_e: np.ndarray, bias_e: np.ndarray,
                               domain: str) -> np.ndarray:
    """Squared pair distances whose fused quantity is unbiased to order ``sigma^2``.

    A fusion rule averages ``g = d^2``, ``d`` or ``1 / d`` (``domain`` ``"d2"``, ``"d"``,
    ``"inv"``; :data:`.distances._RULES`). With the pair's difference ``e = p_i - p_j`` biased
    by ``bias_e`` and of covariance ``cov_e``, the bias of ``g(e)`` is ``grad g . bias_e + 1/2
    tr(hess g cov_e)``: for ``d^2`` ``2 e . b + tr C``; for ``d`` ``e . b / d + (tr C - e^T C e /
    d^2) / (2 d)``; for ``1 / d`` ``-e . b / d^3 + (3 e^T C e / d^2 - tr C) / (2 d^3)``. The value
    returned is the squared distance whose ``g`` is ``g(e)`` minus that bias; where that is not
    positive (the expansion does not hold) the squared distance of ``e`` is kept.

    Parameters
    ----------
    e : (P, 2) m; cov_e : (P, 2, 2) m^2; bias_e : (P, 2) m; domain : str

    Returns
    -------
    ndarray of shape (P,), m^2
    """
    d2 = np.einsum("pa,pa->p", e, e)
    d = np.sqrt(d2)
    tr = cov_e[:, 0, 0] + cov_e[:, 1, 1]
    along = np.einsum("pa,pab,pb->p", e, cov_e, e) / d2
    eb = np.einsum("pa,pa->p", e, bias_e)
    if domain == "d2":
        g = d2 - (2.0 * eb + tr)
        out = g
    elif domain == "d":
        g = d - (eb / d + (tr - along) / (2.0 * d))
        out = g * g
    elif domain == "inv":
        g = 1.0 / d - (-eb / d ** 3 + (3.0 * along - tr) / (2.0 * d ** 3))
        out = 1.0 / np.where(g > 0, g, 1.0) ** 2
    else:
        raise ValueError(f"unknown domain {domain!r}")
    return np.where((g > 0) & np.isfinite(out), out, d2)


def full_covariance(info: np.ndarray) -> np.ndarray | None:
    """``info^-1`` (Jacobi-scaled for conditioning), None if singular or not finite."""
    scale = 1.0 / np.sqrt(np.maximum(np.diag(info), 1e-300))
    try:
        inv = np.linalg.inv(info * scale[:, None] * scale[None, :])
    except np.linalg.LinAlgError:
        return None
    inv = inv * scale[:, None] * scale[None, :]
    return inv if np.all(np.isfinite(inv)) else None


__all__ = ["corrected_squared_distance", "full_covariance", "residual_hessian_traces",
           "second_order_bias"]
