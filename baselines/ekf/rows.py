"""The fused per-step kernel of the EKF baselines' paper path: every bearing to a Euclidean
landmark of one step predicted, linearised (observability-constrained), and given its
second-order variance and its innovation variance in a few vectorised numpy calls (paper
section IV, Exp. 2; issue 14 item 3).

The arithmetic is that of :func:`~baselines.ekf.models.bearing_and_jacobian`,
:meth:`~baselines.ekf.slam.EkfSlam._constrain` and
:func:`~baselines.ekf.models.second_order_variance` with the three quadratic forms of a
bearing's 5 touched states written as one batched product ``C = R B R^T``: with ``B`` the
(5, 5) covariance of ``[x, y, psi, lx, ly]`` and the rows ``R`` the radial and perpendicular
directions of the ray (:func:`~baselines.ekf.models.ray_covariance`) and the constrained
bearing Jacobian ``h``, ``C`` holds ``C_rr``, ``C_pp``, ``C_rp`` and ``h B h^T``. The sums run in
another order than in those functions, so results agree with them to rounding
(tests/baselines/test_ekf_rows.py), not bit for bit.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from bomgraph.geometry import bearing_offsets

from .filter import JacobianRows

#: ``(jac (m, 5), cols (m, 5)) -> jac (m, 5)``: the general observability constraint (the
#: projection of :meth:`~baselines.ekf.slam.EkfSlam._constrain`) for rows whose closest
#: constrained linearisation does not exist.
Constrain = Callable[[np.ndarray, np.ndarray], np.ndarray]

#: the sign pattern that turns ``[ux, uy]`` into ``[-uy, ux]`` (after reversing)
_PERP = np.array([-1.0, 1.0])


def landmark_rows(x: np.ndarray, P: np.ndarray, nullspace: np.ndarray,  # noqa: N803
                  cols: np.ndarray, white_sigma_rad: float, constrain: Constrain
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Predicted bearings, constrained Jacobian rows, ``H_i P H_i^T``, second-order variances
    and nonlinearity indices of ``m`` bearings from poses to Euclidean landmarks.

    Parameters
    ----------
    x : array of shape (n,)
    P : array of shape (n, n)
    nullspace : array of shape (n, 3)
        :attr:`~baselines.ekf.filter.BearingEkf.nullspace`.
    cols : int array of shape (m, 5)
        The states of each bearing: its pose ``[x, y, psi]``, then its landmark ``[lx, ly]``.
    white_sigma_rad : float
        The std. dev. of the bearing's white error.
    constrain : callable
        The general constraint for rows where the closest one does not exist (``L <= 1e-6``,
        :meth:`~baselines.ekf.slam.EkfSlam._constrain`).

    Returns
    -------
    h_rad : ndarray of shape (m,)
        Not wrapped (``atan2(dy, dx) - psi``; the innovation wraps once).
    jac : ndarray of shape (m, 5)
        Over ``cols``; a view into a fresh array.
    hph : ndarray of shape (m,)
    var_rad2 : ndarray of shape (m,)
    nonlinearity : ndarray of shape (m,)
    """
    m = len(cols)
    v = x[cols]                                                  # (m, 5)
    block = P[cols[:, :, None], cols[:, None, :]]                # (m, 5, 5)
    h, d, q = bearing_offsets(v[:, 0:3], v[:, 3:5])              # q: |r|^2
    dist = np.sqrt(q)
    u = d / dist[:, None]                                        # the ray's unit vector
    a = nullspace[cols, 2]                                       # anchors: [-a_y, a_x]
    length = u[:, 0] * (a[:, 4] - a[:, 1]) + u[:, 1] * (a[:, 0] - a[:, 3])
    # rows: radial [-u, 0, u], perpendicular [-w, -|r|, w] with w = [-uy, ux], and the
    # constrained bearing row [-w / L, -1, w / L]
    r = np.empty((m, 3, 5))
    r[:, 0, 3:5] = u
    np.multiply(u[:, ::-1], _PERP, out=r[:, 1, 3:5])
    with np.errstate(divide="ignore", invalid="ignore"):   # rows with L <= 0 are replaced
        np.divide(r[:, 1, 3:5], length[:, None], out=r[:, 2, 3:5])
    np.negative(r[:, :, 3:5], out=r[:, :, 0:2])
    r[:, 0, 2] = 0.0
    np.negative(dist, out=r[:, 1, 2])
    r[:, 2, 2] = -1.0
    if not (length > 1e-6).all():
        bad = ~(length > 1e-6)
        raw = np.zeros((int(np.count_nonzero(bad)), 5))
        rb, db, qb = r[bad], d[bad], q[bad]
        raw[:, 3], raw[:, 4] = -db[:, 1] / qb, db[:, 0] / qb
        raw[:, 0], raw[:, 1], raw[:, 2] = -raw[:, 3], -raw[:, 4], -1.0
        rb[:, 2] = constrain(raw, cols[bad])
        r[bad] = rb
    c = r @ block @ r.transpose(0, 2, 1)                         # (m, 3, 3)
    prod = np.maximum(c[:, 0, 0] * c[:, 1, 1], 0.0)
    c_rp = c[:, 0, 1]
    var = white_sigma_rad ** 2 + (prod + c_rp * c_rp) / (q * q)
    return h, r[:, 2], c[:, 2, 2], var, prod ** 0.25 / dist





def feature_rows(x: np.ndarray, P: np.ndarray, nullspace: np.ndarray,  # noqa: N803
                 cols: np.ndarray, white_sigma_rad: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """As :func:`landmark_rows` for ``m`` bearings to inverse-depth features ``[x0, y0, theta,
    rho]``: the arithmetic of :func:`~baselines.ekf.models.invdepth_bearing_and_jacobian`, the
    projected constraint of :meth:`~baselines.ekf.slam.EkfSlam._constrain` and the
    second-order variance of :func:`~baselines.ekf.models.second_order_variance`, as batched
    products.

    Parameters
    ----------
    cols : int array of shape (m, 7)
        The pose ``[x, y, psi]``, then the feature.

    Returns
    -------
    h_rad (m,) (not wrapped), jac (m, 7), hph (m,), var_rad2 (m,); the nonlinearity index of
    a feature row is 0.
    """
    v = x[cols]                                                  # (m, 7)
    block = P[cols[:, :, None], cols[:, None, :]]                # (m, 7, 7)
    amp = v[:, 3:5] - v[:, 0:2]                                  # anchor - pose
    th, rho = v[:, 5], v[:, 6]
    ct, st = np.cos(th), np.sin(th)
    vx, vy = rho * amp[:, 0] + ct, rho * amp[:, 1] + st          # rho (a - p) + m
    q = vx * vx + vy * vy
    gx, gy = -vy / q, vx / q
    h = np.arctan2(vy, vx) - v[:, 2]
    j = np.empty((len(q), 1, 7))
    j[:, 0, 3], j[:, 0, 4] = rho * gx, rho * gy
    j[:, 0, 0], j[:, 0, 1] = -j[:, 0, 3], -j[:, 0, 4]
    j[:, 0, 2] = -1.0
    j[:, 0, 5] = -gx * st + gy * ct
    j[:, 0, 6] = gx * amp[:, 0] + gy * amp[:, 1]
    ns = nullspace[cols]                                         # (m, 7, 3)
    ns_t = ns.transpose(0, 2, 1)
    gram = ns_t @ ns
    rhs = ns_t @ j.transpose(0, 2, 1)                            # (m, 3, 1)
    try:
        coef = np.linalg.solve(gram, rhs)
    except np.linalg.LinAlgError:       # a degenerate nullspace (e.g. after a huge step)
        coef = np.linalg.pinv(gram) @ rhs
    j -= (ns @ coef).transpose(0, 2, 1)                          # h N_S = 0
    hph = (j @ block @ j.transpose(0, 2, 1))[:, 0, 0]
    cross = vx * amp[:, 1] - vy * amp[:, 0]
    h_rr = -2.0 * cross * (vx * amp[:, 0] + vy * amp[:, 1]) / (q * q)
    var = white_sigma_rad ** 2 + 0.5 * (h_rr * block[:, 6, 6]) ** 2
    return h, j[:, 0], hph, var
def take_rows(parts: JacobianRows, keep: np.ndarray) -> JacobianRows:
    """The rows ``keep`` (bool, (k,)) of a sparse Jacobian, renumbered ``0..count(keep)-1``
    (moved here from slam.py)."""
    new = np.cumsum(keep) - 1
    out = []
    for rows, cols, j in parts:
        m = keep[rows]
        if m.any():
            out.append((new[rows[m]], cols[m], j[m]))
    return out


__all__ = ["feature_rows", "landmark_rows", "take_rows"]
