"""Windowed triangulation (issue 8; paper section III-B over more than two poses).

A window holds ``W`` consecutive poses and the ``W - 1`` odometry increments between
them. Every landmark seen from at least two of its poses is triangulated from the pair of its
rays furthest apart in the window (the longest baseline), if that pair passes the gates, in the frame
of the window's first pose (dead-reckoned from the increments). Two landmarks triangulated in the same window share the
odometry chain, so the first-order variance of their squared distance is taken over all
``3 (W - 1)`` increments (each with its own independent sigmas) and the four bearings used.
The Jacobians are analytic (complex plane): with ``p = z_a + r1 u_a`` the intersection of the
rays from poses ``a < b`` (positions ``z``, directions ``u = exp(i alpha)``), an increment
``m`` (pose ``m-1`` to ``m``) moves the point rigidly (translation, or rotation about ``z_m``)
when ``m <= a``, moves only the second ray when ``a < m <= b``, and does nothing after ``b``.
With ``W = 2`` this is exactly eq. 1-2 (:mod:`.triangulation`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..angles import angle_residual
from ..errors import ConfigError
from ..geometry import effective_parallax
from .triangulation import PairEstimates, TwoRayResult, select_pairs
from .window_schedule import WindowSchedule  # noqa: F401 (re-exported: the mapper's)


@dataclass(frozen=True, eq=False)
class WindowTriangulation(TwoRayResult):
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


def _window_chain(odoms: ArrayLike, bearings_rad: ArrayLike, caller: str
                  ) -> tuple[np.ndarray, np.ndarray, int, np.ndarray, np.ndarray, np.ndarray]:
    """The window's odometry chain in the complex plane, from its first pose.

    Returns ``(odoms (W-1, 3), bearings (W, n), W, psi (W,), heading = exp(i psi) (W,),
    z (W,) positions as x + i y)``. (Complex arithmetic, not ``geometry.chain_odometry``:
    the complex product rounds differently in the last bit, and the numbers must not change.)
    """
    u = np.asarray(odoms, dtype=float).reshape(-1, 3)
    brg = np.asarray(bearings_rad, dtype=float)
    w = len(u) + 1
    if brg.ndim != 2 or brg.shape[0] != w:
        raise ConfigError(f"{caller}: bearings must be ({w}, n) for {w - 1} "
                          f"increments, got shape {brg.shape}")
    psi = np.concatenate([[0.0], np.cumsum(u[:, 2])])
    heading = np.exp(1j * psi)
    z = np.concatenate([[0.0], np.cumsum(heading[:-1] * (u[:, 0] + 1j * u[:, 1]))])
    return u, brg, w, psi, heading, z


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
        would pick the pairs whose noise widened the angle: depths biased short
        (``docs/measurements.md``).
    n_gated : int
        Landmarks seen from two poses or more with no passing pair.
    """
    u, brg, w, psi, heading, z = _window_chain(odoms, bearings_rad, "triangulate_window")
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
    """``d z_k / d [dx, dy, dpsi]_m`` (complex, shape ``(B, W, W-1, 3)``) and ``d psi_k / d
    ...`` (real, same shape) of the dead-reckoned poses ``k`` of ``B`` windows wrt their
    increments ``m`` (``u`` of shape ``(B, W-1, 3)``, ``z`` and ``heading`` ``(B, W)``)."""
    n_b, w1 = u.shape[:2]
    w = w1 + 1
    k = np.arange(w)[:, None]
    m = np.arange(1, w1 + 1)[None, :]
    upto = (m <= k)[None]                                            # increment m moves pose k
    dz = np.zeros((n_b, w, w1, 3), np.complex128)
    dz[..., 0] = np.where(upto, heading[:, None, :-1], 0.0)
    dz[..., 1] = np.where(upto, 1j * heading[:, None, :-1], 0.0)
    dz[..., 2] = np.where(upto, 1j * (z[:, :, None] - z[:, None, 1:]), 0.0)
    dpsi = np.zeros((n_b, w, w1, 3))
    dpsi[..., 2] = upto
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
    u, brg, w, _, _, _ = _window_chain(odoms, bearings_rad, "triangulate_window_lsq")
    return _lsq_windows(u[None], brg[None], min_parallax_rad, max_range_m, max_iter, tol_m)[0]


def triangulate_windows_lsq(odoms: Sequence[ArrayLike], bearings_rad: Sequence[ArrayLike], *,
                            min_parallax_rad: float = 0.0, max_range_m: float = np.inf,
                            max_iter: int = 20, tol_m: float = 1e-13
                            ) -> list[tuple[WindowTriangulation, int]]:
    """:func:`triangulate_window_lsq` of several windows of ``W`` poses at once (lists of
    ``(W - 1, 3)`` increments and ``(W, n_b)`` bearings, ``n_b`` per window): the same
    numbers, bit for bit, window by window, in a few calls over all their rays (every ray and
    landmark is computed alone, the sums are per landmark)."""
    if len(odoms) != len(bearings_rad):
        raise ConfigError("triangulate_windows_lsq: one bearing matrix per window")
    if not len(odoms):
        return []
    chains = [_window_chain(o, b, "triangulate_windows_lsq") for o, b in zip(odoms, bearings_rad)]
    w = chains[0][2]
    if any(c[2] != w for c in chains):
        raise ConfigError("triangulate_windows_lsq: every window must have the same poses")
    n_max = max(c[1].shape[1] for c in chains)
    brg = np.full((len(chains), w, n_max), np.nan)
    for b, c in enumerate(chains):
        brg[b, :, :c[1].shape[1]] = c[1]
    u = np.stack([c[0] for c in chains])
    return _lsq_windows(u, brg, min_parallax_rad, max_range_m, max_iter, tol_m)


def _gather_rays(keep: np.ndarray, owner: np.ndarray, start: np.ndarray, *arrays: np.ndarray
                 ) -> tuple[np.ndarray, ...]:
    """The rays of the landmarks ``keep`` (indices of the groups of ``owner``, contiguous,
    starting at ``start``), in their order: ``(owner renumbered 0 .. len(keep) - 1, *arrays
    at those rays, the new group starts)``."""
    counts = np.diff(np.append(start, owner.size))[keep]
    first = start[keep]
    rays = np.repeat(first - np.cumsum(counts) + counts, counts) + np.arange(counts.sum())
    new_owner = np.repeat(np.arange(keep.size), counts)
    new_start = np.cumsum(counts) - counts
    return (new_owner, *(a[rays] for a in arrays), new_start)


def window_lsq_points(odoms: ArrayLike, bearings_rad: ArrayLike, *,
                      min_parallax_rad: float = 0.0, max_range_m: float = np.inf
                      ) -> tuple[np.ndarray, np.ndarray]:
    """The landmarks of :func:`triangulate_window_lsq` alone, without their Jacobians (the
    start of a window bundle, :mod:`.bundle`): ``(column (k,), points_xy (k, 2))``, the same
    numbers."""
    u, brg, _, _, _, _ = _window_chain(odoms, bearings_rad, "window_lsq_points")
    return _lsq_windows(u[None], brg[None], min_parallax_rad, max_range_m, 20, 1e-13,
                        jacobians=False)[0]


def _lsq_windows(u: np.ndarray, brg: np.ndarray, min_parallax_rad: float, max_range_m: float,
                 max_iter: int, tol_m: float, jacobians: bool = True) -> list[tuple]:
    """The kernel of :func:`triangulate_window_lsq` on ``B`` windows: ``u`` of shape
    ``(B, W-1, 3)``, ``brg`` ``(B, W, n)`` (NaN: not seen); one ``(WindowTriangulation,
    n_gated)`` per window, or without ``jacobians`` (one window) ``[(column, points_xy)]``."""
    n_b, w = brg.shape[:2]
    psi = np.concatenate([np.zeros((n_b, 1)), np.cumsum(u[:, :, 2], axis=1)], axis=1)
    heading = np.exp(1j * psi)
    z = np.concatenate([np.zeros((n_b, 1), np.complex128),
                        np.cumsum(heading[:, :-1] * (u[:, :, 0] + 1j * u[:, :, 1]), axis=1)],
                       axis=1)
    seen = np.isfinite(brg)
    cand_b, cand = np.nonzero(seen.sum(axis=1) >= 2)       # by window, then column
    nc = cand.size
    # the rays, grouped by landmark (owner-major order), poses increasing within a landmark
    owner, pose = np.nonzero(seen.transpose(0, 2, 1)[cand_b, cand])
    start = np.flatnonzero(np.r_[True, owner[1:] != owner[:-1]]) if owner.size else \
        np.zeros(0, np.int64)
    ray_b = cand_b[owner]
    alpha = psi[ray_b, pose] + brg[ray_b, pose, cand[owner]]
    ray = np.exp(1j * alpha)
    zr = z[ray_b, pose]

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
        # Gauss-Newton on the bearing residuals, each landmark until its step is small (the
        # landmarks still moving and their rays are gathered again as others finish)
        active = np.flatnonzero(np.isfinite(p))
        converged = np.zeros(nc, bool) if max_iter > 0 else np.ones(nc, bool)
        a_owner, a_zr, a_alpha, a_start = owner, zr, alpha, start
        if active.size < nc:
            a_owner, a_zr, a_alpha, a_start = _gather_rays(active, owner, start, zr, alpha)
        for _ in range(max_iter):
            if active.size == 0:
                break
            d = p[active][a_owner] - a_zr
            rho2 = (d * d.conj()).real
            q = 1j * d / rho2                               # gradient of the ray's angle
            res = angle_residual(np.angle(d), a_alpha)
            nxx, nxy, nyy, gx, gy = (np.add.reduceat(x, a_start) for x in (
                q.real ** 2, q.real * q.imag, q.imag ** 2, res * q.real, res * q.imag))
            det = nxx * nyy - nxy * nxy
            step = -((nyy * gx - nxy * gy) + 1j * (nxx * gy - nxy * gx)) / det
            p_new = p[active] + step
            p[active] = p_new
            small = np.abs(step) <= tol_m * np.maximum(np.abs(p_new), 1.0)
            converged[active[small]] = True
            moving = ~(small | ~np.isfinite(step))
            if not moving.all():
                sub = np.flatnonzero(moving)
                active = active[sub]
                a_owner, a_zr, a_alpha, a_start = _gather_rays(sub, a_owner, a_start, a_zr,
                                                               a_alpha)
        # gates: parallax of the ray directions, in front of every ray, depth
        d = p[owner] - zr
        span = effective_parallax(alpha, owner, nc)
        depth = (d * ray.conj()).real
        bad_ray = ~((depth > 0) & (depth <= max_range_m))
        good = np.isfinite(p) & (np.add.reduceat(bad_ray.astype(np.int64), start) == 0 if nc
                                 else np.zeros(0, bool))
        lo = max(min_parallax_rad, 1e-15)
        good &= span >= lo
        good &= converged
    kept = np.flatnonzero(good)
    if not jacobians:
        return [(cand[kept], np.column_stack([p[kept].real, p[kept].imag]))]
    keep = good[owner]
    # Jacobians at the optimum (implicit function theorem), rays of the kept landmarks only
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
        dz_r = np.stack([dz.real.reshape(n_b, w, c), dz.imag.reshape(n_b, w, c)],
                        axis=2)                                          # (B, W, 2, C)
        qv = np.column_stack([q.real, q.imag])
        o_b = ray_b[keep]
        m_ray = hk @ dz_r[o_b, k_pose] + qv[:, :, None] * dpsi.reshape(n_b, w, c)[
            o_b, k_pose][:, None, :]
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
    fields = (cand[kept], a_idx, b_idx, np.column_stack([pk.real, pk.imag]), depth_k[st],
              depth_k[last], np.sin(span_k), np.cos(span_k), jac_odo, jac_b)
    # window b holds the landmarks (and candidates) in one run each: by window, then column
    n_cand = np.bincount(cand_b, minlength=n_b)
    n_kept = np.bincount(cand_b[kept], minlength=n_b)
    ends = np.cumsum(n_kept)
    out = []
    for b in range(n_b):
        sl = slice(int(ends[b] - n_kept[b]), int(ends[b]))
        out.append((WindowTriangulation(*(f[sl] for f in fields)), int(n_cand[b] - n_kept[b])))
    return out


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
        As :func:`~bomgraph.stmds.triangulation.pair_squared_distances`.
    """
    first, second = select_pairs(len(tri), select)
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
    return PairEstimates(first, second, d2, var, full)


__all__ = ["WindowSchedule", "WindowTriangulation", "triangulate_window", "triangulate_window_lsq",
           "triangulate_windows_lsq", "window_lsq_points", "window_pair_squared_distances"]
