"""Pose resection against a known map: robot poses from bearings to mapped landmarks.

Used by :mod:`baselines.hybrid` to turn the BOM-STMDS map (the paper, sections III-B to III-D)
into a start for every pose of the factor graph. Pure functions on arrays: no mapper state.

* :func:`resect_poses`: every pose at once, each from its own bearings (and an optional prior),
  by a heading grid with the best position per heading in closed form, then Gauss-Newton with
  Huber (IRLS) weights;
* :func:`resect_pose`: one pose;
* :func:`resect_trajectory`: a whole trajectory in two passes (alone, then with the odometry
  prediction from the pose before as a prior), gaps and the start chained by the odometry.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from bomgraph.angles import angle_residual, wrap_angle
from bomgraph.checks import id_array, row_array
from bomgraph.errors import ConfigError
from bomgraph.geometry import (bearing_offsets, compose, inverse, pair_bearings, ray_normals,
                               rotation)


def resection_jacobian(pose: np.ndarray, landmarks_xy: np.ndarray) -> np.ndarray:
    """Jacobian ``(k, 3)`` of the predicted bearings ``atan2(l - p) - psi`` w.r.t. the pose
    ``[x, y, psi]`` (``pose`` of shape (3,) or one pose per landmark, (k, 3))."""
    _, d, r2 = bearing_offsets(pose, landmarks_xy)
    return _pose_jacobian(d, r2)


def _pose_jacobian(offset_xy: np.ndarray, range2_m2: np.ndarray) -> np.ndarray:
    """:func:`resection_jacobian` from :func:`~bomgraph.geometry.bearing_offsets`'s offset
    ``(k, 2)`` and squared range ``(k,)`` (floored at 1e-18 m^2)."""
    r2 = np.maximum(range2_m2, 1e-18)
    return np.column_stack([offset_xy[:, 1] / r2, -offset_xy[:, 0] / r2,
                            -np.ones(len(offset_xy))])


def _group_sum(owner: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Sum ``values`` (J, ...) over rows with the same ``owner`` (J,), shape (n, ...).

    One ``np.add.reduceat`` over the rows sorted by owner (they usually are: bearings come in
    step order), no sparse matrix."""
    out = np.zeros((n, *values.shape[1:]))
    if len(owner) == 0:
        return out
    own = np.asarray(owner, dtype=np.int64)
    if np.any(own[1:] < own[:-1]):
        order = np.argsort(own, kind="stable")
        own, values = own[order], values[order]
    starts = np.flatnonzero(np.r_[True, own[1:] != own[:-1]])
    out[own[starts]] = np.add.reduceat(values, starts, axis=0)
    return out


def _huber_rho(r: np.ndarray, k: float) -> np.ndarray:
    a = np.abs(r)
    return np.where(a <= k, 0.5 * r * r, k * (a - 0.5 * k))


def resect_poses(owner: np.ndarray, landmarks_xy: np.ndarray, bearings_rad: np.ndarray,
                 sigma_rad: np.ndarray, n_poses: int, *,
                 prior_poses: np.ndarray | None = None,
                 prior_sigma: np.ndarray | None = None,
                 prior_cov: np.ndarray | None = None,
                 initial_poses: np.ndarray | None = None, n_headings: int = 72,
                 huber_k: float = 2.0, iterations: int = 10
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Robot poses that best explain bearings to known landmarks, all poses at once.

    For each pose minimises ``sum_j 2 rho(r_j / sigma_j) + e^T C^-1 e``, ``e = pose - prior``
    (heading wrapped), ``C = diag(prior_sigma^2)`` or ``prior_cov``
    (``r_j`` the wrapped bearing residual, ``rho`` Huber): every heading of a grid gets its
    best position in closed form (the least-squares intersection of the lines through the
    landmarks along the bearings), the best grid point is polished by Gauss-Newton with
    Huber (IRLS) weights, accepting only steps that lower the objective.

    Parameters
    ----------
    owner : int array of shape (J,)
        Which pose (0 .. n_poses-1) took each bearing.
    landmarks_xy : array of shape (J, 2)
        Known position of the landmark of each bearing.
    bearings_rad, sigma_rad : arrays of shape (J,)
        Bearings relative to the robot heading and their std. dev.
    n_poses : int
    prior_poses : array of shape (n_poses, 3), optional
        A prior per pose (NaN rows: none).
    prior_sigma : array of shape (n_poses, 3) or (3,), optional
        Std. dev. of the priors (metres, metres, radians), independent in world x, y, psi.
    prior_cov : array of shape (n_poses, 3, 3), optional
        Instead of ``prior_sigma``: the priors' covariances over world ``(x, y, psi)``.
    initial_poses : array of shape (n_poses, 3), optional
        Starting points for Gauss-Newton; the heading grid is searched only for the rows that
        have none (NaN).
    n_headings, huber_k, iterations : grid size, Huber threshold, Gauss-Newton iterations.

    Returns
    -------
    poses : ndarray of shape (n_poses, 3)
        NaN where undetermined: fewer than 2 bearings without a prior.
    cost : ndarray of shape (n_poses,)
        The objective at the result (NaN where undetermined).
    n_bearings : ndarray of shape (n_poses,)
    """
    own = np.asarray(owner, dtype=np.int64).reshape(-1)
    lm = np.asarray(landmarks_xy, dtype=float).reshape(-1, 2)
    b = np.asarray(bearings_rad, dtype=float).reshape(-1)
    sig = np.broadcast_to(np.asarray(sigma_rad, dtype=float), b.shape)
    if not (len(own) == len(lm) == len(b)):
        raise ConfigError(f"resect_poses: {len(own)} owners, {len(lm)} landmarks, "
                          f"{len(b)} bearings")
    if own.size and (own.min() < 0 or own.max() >= n_poses):
        raise ConfigError("resect_poses: owner indices must lie in 0 .. n_poses-1")
    prior = (np.full((n_poses, 3), np.nan) if prior_poses is None
             else np.asarray(prior_poses, dtype=float).reshape(n_poses, 3))
    has_prior = np.all(np.isfinite(prior), axis=1)
    if prior_cov is not None and prior_sigma is not None:
        raise ConfigError("resect_poses: give prior_sigma or prior_cov, not both")
    if prior_cov is not None:
        pc = np.asarray(prior_cov, dtype=float).reshape(n_poses, 3, 3)
        pc = np.where(has_prior[:, None, None], pc, np.eye(3))
    else:
        ps = np.broadcast_to(np.asarray(1.0 if prior_sigma is None else prior_sigma,
                                        dtype=float), (n_poses, 3))
        pc = np.eye(3) * (ps ** 2)[:, None, :]
    info = np.where(has_prior[:, None, None], np.linalg.inv(pc), 0.0)  # (T, 3, 3)
    prior0 = np.where(has_prior[:, None], prior, 0.0)
    n_b = np.bincount(own, minlength=n_poses)
    valid = (n_b >= 2) | has_prior

    def objective(rows: np.ndarray, cands: np.ndarray) -> np.ndarray:
        """The objective of candidates ``(R, H, 3)`` for poses ``rows`` (sorted), ``(R, H)``."""
        mask = np.zeros(n_poses, bool)
        mask[rows] = True
        sel = mask[own]
        o = np.searchsorted(rows, own[sel])
        c = cands[o]
        r = angle_residual(pair_bearings(c, lm[sel][:, None, :], wrapped=False),   # (J', H)
                           b[sel][:, None]) / sig[sel][:, None]
        e = cands - prior0[rows][:, None, :]
        e[..., 2] = angle_residual(cands[..., 2], prior0[rows][:, None, 2])
        return (2 * _group_sum(o, _huber_rho(r, huber_k), len(rows))
                + np.einsum("rhi,rij,rhj->rh", e, info[rows], e))

    poses = np.zeros((n_poses, 3))
    cost = np.full(n_poses, np.inf)
    start = (np.full((n_poses, 3), np.nan) if initial_poses is None
             else np.asarray(initial_poses, dtype=float).reshape(n_poses, 3))
    given = np.all(np.isfinite(start), axis=1) & valid
    if given.any():
        poses[given] = start[given]
        rows = np.flatnonzero(given)
        cost[rows] = objective(rows, poses[rows, None, :])[:, 0]
    grid = valid & ~given
    if grid.any():
        # grid over the heading: the best position for each in closed form
        rows = np.flatnonzero(grid)
        sel = grid[own]
        g_own = np.searchsorted(rows, own[sel])
        offsets = np.linspace(-np.pi, np.pi, n_headings, endpoint=False)
        psi = prior0[rows, 2:3] + offsets[None, :]                       # (G, H)
        n = ray_normals(psi[g_own] + b[sel][:, None])                    # (J', H, 2, 2)
        w = 1.0 / sig[sel] ** 2
        a = _group_sum(g_own, w[:, None, None, None] * n, len(rows))     # (G, H, 2, 2)
        rhs = _group_sum(g_own, np.einsum("j,jhab,jb->jha", w, n, lm[sel]), len(rows))
        # the prior at the grid heading: I_pp (xy - prior_xy) + I_pq e_psi, e_psi fixed
        a += info[rows, None, :2, :2]
        e_psi = angle_residual(psi, prior0[rows, 2:3])                  # (G, H)
        rhs += (np.einsum("gij,gj->gi", info[rows, :2, :2], prior0[rows, :2])[:, None, :]
                - info[rows, None, :2, 2] * e_psi[..., None])
        det = a[..., 0, 0] * a[..., 1, 1] - a[..., 0, 1] * a[..., 1, 0]
        ok = det > 1e-12 * np.maximum(a[..., 0, 0] + a[..., 1, 1], 1e-300) ** 2
        safe = np.where(ok, det, 1.0)
        xy = np.stack([(a[..., 1, 1] * rhs[..., 0] - a[..., 0, 1] * rhs[..., 1]) / safe,
                       (a[..., 0, 0] * rhs[..., 1] - a[..., 1, 0] * rhs[..., 0]) / safe], -1)
        cands = np.concatenate([xy, wrap_angle(psi)[..., None]], -1)    # (G, H, 3)
        grid_cost = np.where(ok, objective(rows, cands), np.inf)
        best = np.argmin(grid_cost, axis=1)
        poses[rows] = cands[np.arange(len(rows)), best]
        cost[rows] = grid_cost[np.arange(len(rows)), best]
    valid &= np.isfinite(cost)
    poses[~valid] = 0.0
    # Gauss-Newton with IRLS weights, per pose, accepting only improving steps
    active = valid.copy()
    for _ in range(iterations):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        sel = active[own]
        o, l_, b_, s_ = np.searchsorted(idx, own[sel]), lm[sel], b[sel], sig[sel]
        p = poses[idx]
        pred, d, r2 = bearing_offsets(p[o], l_)
        r = angle_residual(pred, b_) / s_
        wr = np.where(np.abs(r) <= huber_k, 1.0, huber_k / np.maximum(np.abs(r), 1e-300))
        jac = _pose_jacobian(d, r2) / s_[:, None]
        h = _group_sum(o, wr[:, None, None] * jac[:, :, None] * jac[:, None, :], len(idx))
        g = _group_sum(o, (wr * r)[:, None] * jac, len(idx))
        e = np.column_stack([p[:, :2] - prior0[idx, :2],
                             angle_residual(p[:, 2], prior0[idx, 2])])
        h += info[idx]
        g += np.einsum("nij,nj->ni", info[idx], e)
        try:
            step = -np.linalg.solve(h, g[..., None])[..., 0]
        except np.linalg.LinAlgError:
            break
        trial = p + step
        trial[:, 2] = wrap_angle(trial[:, 2])
        new_cost = objective(idx, trial[:, None, :])[:, 0]
        better = new_cost < cost[idx]
        gain = np.where(better, cost[idx] - new_cost, 0.0)
        poses[idx[better]] = trial[better]
        cost[idx[better]] = new_cost[better]
        still = better & (np.max(np.abs(step), axis=1) >= 1e-10) \
            & (gain > 1e-10 * np.maximum(cost[idx], 1.0))
        active[idx[~still]] = False
    poses[~valid] = np.nan
    cost = np.where(valid, cost, np.nan)
    return poses, cost, n_b


def resect_pose(landmarks_xy: np.ndarray, bearings_rad: np.ndarray,
                sigma_rad: np.ndarray | float, prior_pose: np.ndarray | None = None,
                prior_sigma: np.ndarray | None = None, *, n_headings: int = 72,
                huber_k: float = 2.0, iterations: int = 15) -> tuple[np.ndarray, float]:
    """One pose by :func:`resect_poses`: returns ``(pose (3,), cost)``; NaN if undetermined.

    ``landmarks_xy`` (k, 2), ``bearings_rad`` (k,), ``sigma_rad`` scalar or (k,),
    ``prior_pose`` (3,) and ``prior_sigma`` (3,) optional.
    """
    lm = np.asarray(landmarks_xy, dtype=float).reshape(-1, 2)
    poses, cost, _ = resect_poses(
        np.zeros(len(lm), np.int64), lm, np.asarray(bearings_rad, dtype=float).reshape(-1),
        np.broadcast_to(np.asarray(sigma_rad, dtype=float), (len(lm),)), 1,
        prior_poses=None if prior_pose is None else np.asarray(prior_pose, float)[None],
        prior_sigma=None if prior_sigma is None else np.asarray(prior_sigma, float)[None],
        n_headings=n_headings, huber_k=huber_k, iterations=iterations)
    return poses[0], float(cost[0])


def resect_trajectory(owner: np.ndarray, landmark_ids: np.ndarray, bearings_rad: np.ndarray,
                      bearing_sigma_rad: float, map_ids: np.ndarray, map_xy: np.ndarray,
                      odoms: np.ndarray, odometry_sigma: np.ndarray, *,
                      start: np.ndarray | None = None, n_headings: int = 36,
                      huber_k: float = 2.0, map_sigma_m: float = 0.03,
                      prior_sigma: Sequence[float] = (0.02, 0.02, math.radians(2.0))
                      ) -> np.ndarray | None:
    """Every pose of a trajectory by resection against a map, shape (T, 3), or None if no
    pose resects.

    Pass 1 resects each pose with at least 3 mapped bearings on its own (from ``start`` if
    given; a pose whose fit is then poor, more than 9 per bearing, is redone from the heading
    grid); pass 2 again with the odometry prediction from the pass-1 pose before it as a prior
    (covariance ``diag(prior_sigma^2) + G diag(odometry_sigma^2) G^T``, ``G =
    blockdiag(R(psi_{t-1}), 1)``: the odometry sigmas are in the frame of the pose before,
    turned into the world by its pass-1 heading), each bearing's
    std. dev. ``sqrt(sigma^2 + (map_sigma_m / r)^2)`` at its range ``r`` (the map's error).
    Poses left undetermined are chained from their neighbours by the odometry.

    Parameters
    ----------
    owner, landmark_ids, bearings_rad : arrays of shape (J,)
        Every bearing of the stream: the step (0 .. T-1) that took it, its landmark, its value
        relative to the robot heading (radians).
    bearing_sigma_rad : float
    map_ids : int array of shape (n,), map_xy : array of shape (n, 2)
        The map (metres); bearings to landmarks not in it are ignored.
    odoms : array of shape (T, 3)
        Row ``t`` is the increment ``[dx_m, dy_m, dpsi_rad]`` from pose ``t-1`` to ``t`` (row 0
        unused).
    odometry_sigma : array of shape (T, 3)
        Std. dev. of each row of ``odoms`` (its components, in the frame of pose ``t-1``).
    start : array of shape (T, 3), optional
        Starting poses of pass 1 (else the heading grid).
    n_headings, huber_k : heading grid size and Huber threshold of :func:`resect_poses`.
    map_sigma_m : float
    prior_sigma : (m, m, rad)
    """
    (owner, landmark_ids, bearings_rad, map_ids, map_xy, odoms,
     odometry_sigma) = _trajectory_inputs(owner, landmark_ids, bearings_rad, map_ids, map_xy,
                                          odoms, odometry_sigma)
    n_t = len(odoms)
    ids = np.asarray(landmark_ids)
    order = np.argsort(map_ids)
    pos = np.clip(np.searchsorted(map_ids[order], ids), 0, len(map_ids) - 1)
    have = map_ids[order][pos] == ids
    own, lm, b = owner[have], map_xy[order][pos[have]], bearings_rad[have]
    sig_b = float(bearing_sigma_rad)
    kw = dict(n_headings=n_headings, huber_k=huber_k)
    p1, c1, n_b = resect_poses(own, lm, b, np.full(len(b), sig_b), n_t,
                               initial_poses=start, **kw)
    if start is not None:
        poor = np.isfinite(c1) & (c1 > 9.0 * np.maximum(n_b, 1))
        if poor.any():
            q, _, _ = resect_poses(own, lm, b, np.full(len(b), sig_b), n_t,
                                   initial_poses=np.where(poor[:, None], np.nan, p1), **kw)
            p1[poor] = q[poor]
    ok1 = (n_b >= 3) & np.all(np.isfinite(p1), axis=1)
    prior = np.full((n_t, 3), np.nan)
    prev_ok = np.flatnonzero(ok1[:-1]) + 1
    prior[prev_ok] = compose(p1[prev_ok - 1], odoms[prev_ok])
    psi_prev = np.zeros(n_t)
    psi_prev[prev_ok] = p1[prev_ok - 1, 2]
    g = np.zeros((n_t, 3, 3))
    g[:, :2, :2] = rotation(psi_prev)
    g[:, 2, 2] = 1.0
    odo_var = np.asarray(odometry_sigma, dtype=float).reshape(n_t, 3) ** 2
    prior_cov = (np.eye(3) * np.asarray(prior_sigma, dtype=float) ** 2
                 + np.einsum("nij,nj,nkj->nik", g, odo_var, g))
    ref = np.where(ok1[:, None], p1, prior)[own, :2]
    rng = np.hypot(*(lm - ref).T)
    sig = np.where(np.isfinite(rng),
                   np.sqrt(sig_b ** 2 + (map_sigma_m / np.maximum(rng, 0.05)) ** 2),
                   2 * sig_b)
    poses, _, _ = resect_poses(own, lm, b, sig, n_t, prior_poses=prior, prior_cov=prior_cov,
                               initial_poses=np.where(ok1[:, None], p1, np.nan), **kw)
    ok = np.all(np.isfinite(poses), axis=1) & ((n_b >= 3) | np.isfinite(prior[:, 0]))
    if not ok.any():
        return None
    first = int(np.argmax(ok))
    for t in range(first - 1, -1, -1):          # before the first: odometry backwards
        back = inverse(odoms[t + 1])
        back[2] = -odoms[t + 1, 2]              # unwrapped (compose wraps): keeps the bits
        poses[t] = compose(poses[t + 1], back)
    for t in range(first + 1, n_t):             # gaps: odometry forwards
        if not ok[t]:
            poses[t] = compose(poses[t - 1], odoms[t])
    return poses


def _trajectory_inputs(owner: np.ndarray, landmark_ids: np.ndarray, bearings_rad: np.ndarray,
                       map_ids: np.ndarray, map_xy: np.ndarray, odoms: np.ndarray,
                       odometry_sigma: np.ndarray) -> tuple[np.ndarray, ...]:
    """:func:`resect_trajectory`'s arrays, refused in one line naming the argument and what
    to give when their shapes disagree (values unchanged)."""
    def bad(message: str) -> ConfigError:
        return ConfigError(f"resect_trajectory: {message}")

    own = id_array(owner, "owner", bad)
    lid = id_array(landmark_ids, "landmark_ids", bad)
    brg = np.asarray(bearings_rad, dtype=float)
    if not (own.ndim == lid.ndim == brg.ndim == 1 and own.size == lid.size == brg.size):
        raise bad(f"owner, landmark_ids and bearings_rad must be 1-D, one entry per bearing, "
                  f"got shapes {own.shape}, {lid.shape}, {brg.shape}")
    m_ids = id_array(map_ids, "map_ids", bad)
    m_xy = row_array(map_xy, 2, "map_xy", bad, copy=False)
    if m_ids.shape[0] != m_xy.shape[0]:
        raise bad(f"map_ids has {m_ids.shape[0]} ids but map_xy {m_xy.shape[0]} rows")
    odo = row_array(odoms, 3, "odoms", bad, copy=False)
    sig = row_array(odometry_sigma, 3, "odometry_sigma", bad, copy=False)
    if sig.shape != odo.shape:
        raise bad(f"odometry_sigma must have the shape of odoms {odo.shape}, got {sig.shape}")
    if own.size and own.max() >= len(odo):
        raise bad(f"a bearing was taken at step {int(own.max())} but odoms has {len(odo)} rows: "
                  f"give one row per step 0 .. T-1, row 0 unused (not dead_reckon's T-1 "
                  f"increments: prepend a row of zeros)")
    if own.size and own.min() < 0:
        raise bad(f"owner must be steps >= 0, got {int(own.min())}")
    return own, lid, brg, m_ids, m_xy, odo, sig


__all__ = ["resect_poses", "resect_pose", "resect_trajectory", "resection_jacobian"]
