"""Windowed triangulation by local bundle adjustment (issue 8, ``tri_method="ba"``).

The paper (Sec. III-A) triangulates every landmark from two consecutive poses placed by the
odometry alone. On recordings with small steps and a narrow view the heading drift of the
odometry inside a window is as large as the parallax, so a landmark placed from odometry-fixed
poses carries that drift into every distance. Here the poses of the window are estimated with
the landmarks: the window's ``W`` poses (the first one fixed at the origin, which fixes the
gauge) and every landmark seen from two of its poses or more minimise

    sum_m || between(x_{m-1}, x_m) - u_m ||^2_{Sigma_u}
      + sum_(k, l) angle_residual(atan2(p_l - z_k) - psi_k, theta_kl)^2 / sigma^2,

the maximum-likelihood problem of the window alone (Levenberg-Marquardt, dense: a window has
at most a few hundred unknowns). It starts from :func:`triangulation.triangulate_window_lsq`
(odometry poses, all rays of each landmark), so the gates of that function apply to the start;
rays whose standardised residual (whitened, divided by ``sqrt(1 - leverage)``) exceeds
``outlier_sigma`` are dropped one at a time (the worst first) and the window solved again,
so a gross bearing outlier cannot bend the window. The leverages are well-posed (a
pseudo-inverse of ``J^T J`` where it is numerically singular,
:class:`.bundle_lm.WindowInverse`); a ray of leverage ~1 (no redundancy, as each of a
landmark's only two rays) has a zero residual whatever its noise, and is neither tested nor
counted in the bearing-sigma estimate.

The joint covariance of the window's landmarks is the landmark block of ``(J^T J)^-1`` (first
order, exact for the MLE of a linear model); the variance of a pair's squared distance follows
with the cross-covariance of the two points, which carries the shared poses and bearings:
``var(d^2) = 4 e^T (C_ii + C_jj - C_ij - C_ji) e``, ``e = p_i - p_j``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..angles import angle_residual
from ..errors import ConfigError
from ..geometry import between, dead_reckon, effective_parallax, pair_bearings, to_local
from .bundle_lm import (SIGMA_FLOOR, UNDETERMINED_LEVERAGE,  # noqa: F401 (re-exported)
                        BundleProblem, WindowInverse, levenberg_marquardt,
                        window_bearing_residuals)
from .triangulation import PairEstimates, pair_indices
from .window import window_lsq_points



@dataclass(frozen=True)
class WindowBundle:
    """The landmarks of one window after local bundle adjustment.

    Attributes
    ----------
    column : ndarray of shape (k,), int64
        Column of each landmark in the ``bearings_rad`` matrix.
    points_xy : ndarray of shape (k, 2)
        Positions in metres in the frame of the window's first pose.
    covariance_m2 : ndarray of shape (2k, 2k)
        Joint covariance of the points (x0, y0, x1, y1, ...).
    poses : ndarray of shape (W, 3)
        The window's poses ``(x_m, y_m, psi_rad)``; the first is the origin.
    n_rays : ndarray of shape (k,), int64
        Rays of each landmark kept by the fit.
    n_outliers : int
        Rays dropped by the outlier test.
    converged : bool
        The last Levenberg-Marquardt solve met its tolerance.
    bearing_sigma_rad : float
        The bearing std. dev. of the fit: the one given, or the one estimated from the
        window's residuals (``estimate_sigma``).
    """

    column: np.ndarray
    points_xy: np.ndarray
    covariance_m2: np.ndarray
    poses: np.ndarray
    n_rays: np.ndarray
    n_outliers: int
    converged: bool
    bearing_sigma_rad: float = math.nan
    prefix_state: "PrefixState | None" = None

    def __len__(self) -> int:
        return len(self.column)


@dataclass(frozen=True)
class PrefixState:
    """Where :func:`bundle_adjust_window` stood after its last prefix short of the whole
    window: enough to go on from there on a longer window of the same steps (the open window
    of geometric windows, estimate after estimate) with the same arithmetic as one call.

    Attributes
    ----------
    solved : int
        Poses solved (the prefix's end).
    poses : ndarray of shape (solved, 3)
        Their solution, in the frame of the window's first pose.
    points_xy : ndarray of shape (n, 2)
        Landmarks by column of the window's bearing matrix (NaN: not fitted yet).
    dropped_pose, dropped_column : ndarrays of int64
        Rays dropped as outliers so far.
    """

    solved: int
    poses: np.ndarray
    points_xy: np.ndarray
    dropped_pose: np.ndarray
    dropped_column: np.ndarray


def bundle_adjust_window(odoms: ArrayLike, odometry_sigmas: ArrayLike, bearings_rad: ArrayLike,
                         bearing_sigma_rad: float, *, min_parallax_rad: float = 0.0,
                         max_range_m: float = np.inf, min_depth_m: float = 0.05,
                         outlier_sigma: float | None = 4.0,
                         initial_poses: ArrayLike | None = None,
                         initial_points: ArrayLike | None = None, initial_prefix: int = 1,
                         grow: int = 5, prefix_ends: Sequence[int] | None = None,
                         estimate_sigma: bool = False, resume: PrefixState | None = None,
                         robust_start: bool = False, max_outliers: int = 10,
                         max_iter: int = 30, tol: float = 1e-6
                         ) -> tuple[WindowBundle, int]:
    """Jointly estimate a window's poses and landmarks from its odometry and bearings.

    Parameters
    ----------
    odoms, odometry_sigmas : arrays of shape (W - 1, 3)
        Increments ``[dx_m, dy_m, dpsi_rad]`` between consecutive window poses and their
        independent std. devs.
    bearings_rad : array of shape (W, n)
        Bearing of landmark (column) ``j`` from window pose ``k``; NaN where not seen.
    bearing_sigma_rad : float
    min_parallax_rad, max_range_m : float
        Gates of the starting triangulation (:func:`triangulate_window_lsq`) and, on the
        adjusted poses, of the result: the effective parallax of a landmark's kept rays must
        be at least ``min_parallax`` and the point must be in front of every kept ray at a
        depth of at most ``max_range_m``.
    min_depth_m : float
        Landmarks closer than this to a pose that saw them are refused after the fit. A
        landmark straight ahead of a robot driving at it has rays that are nearly one line;
        the fit can slide it along them onto the path, where the bearing model is singular.
    outlier_sigma : float or None
        Rays with ``|residual| > outlier_sigma * sigma`` are dropped, the worst first, and the
        window solved again (None: keep every ray).
    max_outliers : int
        At most this many rays are dropped per window.
    initial_poses : array of shape (W, 3), optional
        Start of the poses (any frame; e.g. the previous window's solution for the poses it
        shares, continued by the odometry). Default: the odometry chain.
    initial_points : array of shape (n, 2), optional
        Start of the landmarks in the frame of ``initial_poses`` (NaN: none); those not given
        start from :func:`triangulate_window_lsq` on the starting poses.
    initial_prefix : int
        With ``initial_poses``: its first ``initial_prefix`` poses are already a solution (the
        poses shared with the previous window); the others are continued by the odometry.
    grow : int
        The window is solved on growing prefixes of its poses, ``grow`` poses more each time,
        every one started from the solution of the one before and new poses continued by the
        odometry from it. Over a long window the odometry drifts by more than the parallax and
        one solve from the whole odometry chain falls into a wrong minimum; short increments
        keep every start close. ``grow >= W`` is a single solve.
    prefix_ends : sequence of int, optional
        The prefixes' ends (pose counts) in place of ``grow`` (e.g. at equal fractions of the
        window's path, :meth:`.window.WindowSchedule.prefix_ends`); those not past the
        ``initial_prefix`` are skipped and the whole window is always solved last.
    estimate_sigma : bool
        Re-estimate the bearing std. dev. from the window's own residuals, starting from
        ``bearing_sigma_rad``: the sigma is multiplied by the robust scale of the
        standardised residuals (:func:`_robust_scale`) and the whole window solved again,
        until the scale is within :data:`SIGMA_TOL` of 1 (at most :data:`SIGMA_ROUNDS`
        times; the growing prefixes before it use ``bearing_sigma_rad``, e.g. the previous
        window's estimate). The weights of bearings
        against odometry, the outlier test (``outlier_sigma`` robust std. devs.) and the
        covariance then hold whether the stream's sigma is a small MAD estimate or a
        generous one.
    robust_start : bool
        A landmark the starting triangulation refuses (e.g. behind one of its rays) with at
        least three rays is tried again without each of them in turn
        (:func:`_start_without_outlier`): a ray is dropped as an outlier when the point its
        other rays give passes the start's gates, the ray points away from it (residual at
        least pi / 2) and the point is further from the ray's pose than that pose is from the
        nearest other pose that saw the landmark. Off: one misidentified detection refuses
        its landmark from every window that holds it, since the bundle's outlier test only
        sees landmarks that have a start. Not covered: a ray pointing away at a prefix's new
        poses for a landmark started on an earlier prefix (it goes straight to the fit, which
        refuses the landmark; e.g. at the last pose of the test window of
        ``tests/stmds/test_stmds_robust_start.py``).
    resume : PrefixState, optional
        Go on from the ``prefix_state`` of an earlier call on a shorter window of the same
        steps (same first pose, same bearings, columns remapped by the caller; ``prefix_ends``
        the same up to its end): the result is the one a single call on this window gives,
        bit for bit, without solving the shared prefixes again. ``initial_*`` are then unused.
    max_iter, tol : Levenberg-Marquardt iterations and relative cost decrease to stop at (1e-6:
        the paper-setup maps of 1e-10 to 0.3 % in MPE with a third fewer iterations,
        ``docs/measurements.md``).

    Returns
    -------
    WindowBundle, int
        The landmarks that pass the gates, and the number refused (by the start or after the
        fit, including landmarks left with fewer than two rays). ``prefix_state`` holds the
        state after the last prefix short of the window (None if there was none).
    """
    u = np.asarray(odoms, dtype=float).reshape(-1, 3)
    sig = np.asarray(odometry_sigmas, dtype=float).reshape(-1, 3)
    brg = np.array(bearings_rad, dtype=float)          # a copy: dropped rays become NaN
    n_win = len(u) + 1
    n_col = brg.shape[1]
    if grow < 1:
        raise ConfigError(f"grow must be >= 1, got {grow}")
    points = np.full((n_col, 2), np.nan)
    if initial_poses is None:
        poses = dead_reckon(u)
    else:
        given = np.asarray(initial_poses, dtype=float)
        if given.shape != (n_win, 3) or not np.all(np.isfinite(given)):
            raise ConfigError(f"initial_poses must be finite with shape ({n_win}, 3), got "
                              f"{given.shape}")
        poses = between(given[0], given)              # in the frame of the first pose
        if initial_points is not None:
            warm = np.asarray(initial_points, dtype=float)
            if warm.shape != (n_col, 2):
                raise ConfigError(f"initial_points must have shape ({n_col}, 2), got "
                                  f"{warm.shape}")
            points = to_local(given[0], warm)
    two_rays = np.isfinite(brg).sum(axis=0) >= 2
    # prefixes of the window solved in turn, each started from the one before
    solved = 1 if initial_poses is None else max(1, min(initial_prefix, n_win))
    n_outliers = 0
    if resume is not None:
        solved = min(resume.solved, n_win)
        poses = dead_reckon(u)
        poses[:solved] = resume.poses[:solved]
        points = np.array(resume.points_xy, dtype=float)
        brg[resume.dropped_pose, resume.dropped_column] = np.nan
        n_outliers = len(resume.dropped_pose)
    drop_k = [np.zeros(0, np.int64) if resume is None else resume.dropped_pose]
    drop_c = [np.zeros(0, np.int64) if resume is None else resume.dropped_column]
    state = None
    if prefix_ends is None:
        ends = list(range(solved + grow, n_win, grow)) + [n_win]
    else:
        ends = sorted({int(e) for e in prefix_ends if solved < e < n_win}) + [n_win]
    result = None
    sigma = float(bearing_sigma_rad)
    for end in ends:
        if end == n_win and solved > 1 and solved < n_win:
            state = PrefixState(solved, poses[:solved].copy(), points.copy(),
                                np.concatenate(drop_k), np.concatenate(drop_c))
        if end > solved:     # continue the poses not solved yet by the odometry
            poses[solved - 1:] = dead_reckon(u[solved - 1:], poses[solved - 1])
        seen = np.isfinite(brg[:end]).sum(axis=0) >= 2
        need = np.flatnonzero(seen & ~np.isfinite(points).all(axis=1))
        if need.size:        # new landmarks: all their rays from the poses as they stand
            start_col, start_xy = window_lsq_points(
                between(poses[:end - 1], poses[1:end]), brg[:end, need],
                min_parallax_rad=min_parallax_rad, max_range_m=max_range_m)
            points[need[start_col]] = start_xy
            if robust_start and n_outliers < max_outliers:
                refused = np.setdiff1d(need, need[start_col])
                rk, rc, rxy = _start_without_outlier(
                    poses[:end], brg[:end], refused, min_parallax_rad, max_range_m,
                    max_outliers - n_outliers)
                if rc.size:
                    points[rc] = rxy
                    brg[rk, rc] = np.nan
                    n_outliers += len(rk)
                    drop_k.append(rk)
                    drop_c.append(rc)
        column = np.flatnonzero(seen & np.isfinite(points).all(axis=1))
        result = _fit(u[:end - 1], sig[:end - 1], sigma, brg[:end],
                      poses[:end], column, points[column], min_parallax_rad, max_range_m,
                      min_depth_m, outlier_sigma, max_outliers - n_outliers, max_iter, tol,
                      estimate_sigma and end == n_win,
                      (SIGMA_RANGE[0] * bearing_sigma_rad, SIGMA_RANGE[1] * bearing_sigma_rad),
                      estimate_sigma)
        fit_poses, fit_column, fit_points, dropped, _, _, sigma_used = result
        poses[:end] = fit_poses
        points[:] = np.nan
        points[fit_column] = fit_points
        brg[dropped[0], dropped[1]] = np.nan
        n_outliers += len(dropped[0])
        drop_k.append(dropped[0])
        drop_c.append(dropped[1])
        solved = end
        sigma = sigma_used
    assert result is not None
    _, column, points_xy, _, cov, converged, sigma_used = result
    n_gated = int(np.count_nonzero(two_rays)) - len(column)
    if cov is None:                       # numerically singular: refuse the whole window
        return _empty(poses, n_outliers), n_gated + len(column)
    n_rays = np.isfinite(brg[:, column]).sum(axis=0).astype(np.int64)
    return WindowBundle(column, points_xy, cov, poses, n_rays, n_outliers, converged,
                        sigma_used, state), n_gated


def _fit(u: np.ndarray, sig: np.ndarray, bearing_sigma_rad: float, brg: np.ndarray,
         poses: np.ndarray, column: np.ndarray, points: np.ndarray, min_parallax_rad: float,
         max_range_m: float, min_depth_m: float, outlier_sigma: float | None,
         max_outliers: int, max_iter: int, tol: float, estimate_sigma: bool = False,
         sigma_bounds: tuple[float, float] = (0.0, math.inf),
         robust_test: bool = False) -> tuple:
    """Levenberg-Marquardt on one prefix, dropping outlier rays (the worst first) and the
    landmarks that fail the gates, until neither happens. With ``estimate_sigma`` the bearing
    sigma is re-estimated from the fit's own residuals first (:func:`_robust_scale`), kept
    within ``sigma_bounds``; with ``robust_test`` the outlier test is against
    ``outlier_sigma`` times the residuals' robust scale when that exceeds 1.

    Returns ``(poses, column, points, (dropped pose, dropped column), covariance or None,
    converged, bearing sigma used)``.
    """
    sub = brg[:, column]
    k, lm = np.nonzero(np.isfinite(sub))
    theta = sub[k, lm]
    drop_k: list[int] = []
    drop_c: list[int] = []
    n_lm = len(column)
    inverse: WindowInverse | None = None
    while True:
        if n_lm == 0:
            return (poses, column, points, (np.array(drop_k, np.int64),
                                            np.array(drop_c, np.int64)), None, False,
                    bearing_sigma_rad)
        for rnd in range(SIGMA_ROUNDS if estimate_sigma else 1):
            prob = BundleProblem(u, sig, bearing_sigma_rad, k, lm, theta, n_lm)
            poses, points, blocks, converged = levenberg_marquardt(prob, poses, points,
                                                                   max_iter, tol)
            res_rad = window_bearing_residuals(poses, points, k, lm, theta, False)[0]
            res = np.abs(res_rad) / bearing_sigma_rad
            determined = np.ones(len(k), bool)
            if (outlier_sigma is not None or estimate_sigma) and res.size:
                # standardised residuals r / (sigma sqrt(1 - h)), h the ray's leverage: a ray
                # at the newest pose is mostly absorbed by that pose's heading, so its raw
                # residual understates it and good rays of the same landmark would be
                # dropped first. A ray with h ~ 1 has no redundancy (its residual is zero
                # up to rounding whatever its noise, so r / sqrt(1 - h) would be rounding):
                # it is neither tested nor counted in the sigma estimate
                inverse = WindowInverse(prob, blocks)
                h = inverse.leverages_at(poses, points)
                determined = h < UNDETERMINED_LEVERAGE
                res = np.where(determined, res / np.sqrt(np.clip(1.0 - h, 1e-6, 1.0)), 0.0)
            if not estimate_sigma or rnd == SIGMA_ROUNDS - 1:
                break
            new_sigma = float(np.clip(bearing_sigma_rad * _robust_scale(res[determined]),
                                      *sigma_bounds))
            if abs(new_sigma / bearing_sigma_rad - 1.0) <= SIGMA_TOL:
                break
            bearing_sigma_rad = new_sigma
        worst = int(np.argmax(res)) if res.size else -1
        keep = None
        # with a sigma to estimate, the test is against the residuals' own robust scale when
        # that is larger (a sigma given too small must not drop good rays before the estimate)
        limit = outlier_sigma if outlier_sigma is None or not robust_test else \
            outlier_sigma * max(1.0, _robust_scale(res[determined]))
        if (outlier_sigma is not None and worst >= 0 and res[worst] > limit
                and len(drop_k) < max_outliers):
            keep = np.ones(len(k), bool)
            keep[worst] = False
            drop_k.append(int(k[worst]))
            drop_c.append(int(column[lm[worst]]))
        ok = _gates(poses, points, k, lm, res_rad, keep, n_lm, min_parallax_rad,
                    max_range_m, min_depth_m)
        if keep is None and ok.all():
            break
        if keep is None:
            keep = np.ones(len(k), bool)
        keep &= ok[lm]
        new_index = np.cumsum(ok) - 1
        column, points = column[ok], points[ok]
        k, lm, theta = k[keep], new_index[lm[keep]], theta[keep]
        n_lm = len(column)
    if inverse is None or inverse.blocks is not blocks:
        inverse = WindowInverse(prob, blocks)
    cov = inverse.landmark_covariance()
    return (poses, column, points, (np.array(drop_k, np.int64), np.array(drop_c, np.int64)),
            cov, converged, bearing_sigma_rad)


#: Re-estimations of the bearing sigma per fit at most, and the relative change that ends them.
SIGMA_ROUNDS = 6
SIGMA_TOL = 0.02
#: Fewest rays for a scale estimate, and the range of the estimate as a multiple of the
#: sigma given (noise-free rays would drive it to zero).
SIGMA_MIN_RAYS = 20
SIGMA_RANGE = (0.25, 4.0)


def _start_without_outlier(poses: np.ndarray, brg: np.ndarray, refused: np.ndarray,
                           min_parallax_rad: float, max_range_m: float,
                           max_drops: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Starts of refused landmarks with one ray left out (``robust_start`` of
    :func:`bundle_adjust_window`).

    Parameters
    ----------
    poses : array of shape (W, 3)
        The window's poses as they stand.
    brg : array of shape (W, n)
        Its bearings (NaN: not seen).
    refused : int array
        Columns the starting triangulation refused.
    min_parallax_rad, max_range_m : float
        The gates of :func:`.window.window_lsq_points`.
    max_drops : int
        At most this many rays are dropped (landmarks in column order).

    Returns
    -------
    (pose of each dropped ray, its column, the landmark's start point (k, 2))
    """
    empty = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 2)))
    seen = np.isfinite(brg[:, refused])
    cand = refused[seen.sum(axis=0) >= 3]
    if cand.size == 0 or max_drops <= 0:
        return empty
    # one column per (landmark, ray left out)
    ray_k, ray_c = np.nonzero(np.isfinite(brg[:, cand]).T)[::-1]
    owner = cand[ray_c]
    loo = brg[:, owner].copy()
    loo[ray_k, np.arange(owner.size)] = np.nan
    col, xy = window_lsq_points(between(poses[:-1], poses[1:]), loo,
                                min_parallax_rad=min_parallax_rad, max_range_m=max_range_m)
    if col.size == 0:
        return empty
    # residuals of every ray of the landmark at each point found without one of them
    full = brg[:, owner[col]]                                        # (W, m)
    pred = pair_bearings(poses[:, None, :], xy[None, :, :], wrapped=False)   # (W, m)
    res = np.abs(angle_residual(pred, full))
    left = res[ray_k[col], np.arange(col.size)].copy()
    res[ray_k[col], np.arange(col.size)] = np.nan
    rms = np.sqrt(np.nanmean(res ** 2, axis=0))
    at_ray = np.hypot(*(xy - poses[ray_k[col], :2]).T)
    # distance from the ray's pose to the nearest other pose that saw the landmark
    gap = np.hypot(*(poses[None, :, :2] - poses[ray_k[col], None, :2]).transpose(2, 0, 1))
    gap[~np.isfinite(full.T)] = np.inf
    gap[np.arange(col.size), ray_k[col]] = np.inf
    # the ray points away from the point its landmark's other rays agree on, and the point is
    # not within the robot's own step of that pose (from that close a small pose error turns
    # a bearing through any angle; from further it cannot)
    ok = (left >= math.pi / 2) & (at_ray > gap.min(axis=1))
    out_k, out_c, out_xy = [], [], []
    for c in np.unique(owner[col[ok]]):
        sel = np.flatnonzero(ok & (owner[col] == c))
        best = sel[np.argmin(rms[sel])]
        out_k.append(ray_k[col[best]])
        out_c.append(c)
        out_xy.append(xy[best])
        if len(out_c) == max_drops:
            break
    if not out_c:
        return empty
    return np.array(out_k, np.int64), np.array(out_c, np.int64), np.array(out_xy)


def _robust_scale(z: np.ndarray) -> float:
    """Robust scale of standardised residuals ``z`` (1 when the bearing sigma is right):
    ``1.4826 median |z|`` (the MAD of a zero-mean normal, unmoved by a few gross outliers);
    1 with fewer than :data:`SIGMA_MIN_RAYS` rays."""
    if z.size < SIGMA_MIN_RAYS:
        return 1.0
    return float(1.4826 * np.median(np.abs(z)))


def _gates(poses: np.ndarray, points: np.ndarray, k: np.ndarray, lm: np.ndarray,
           res_rad: np.ndarray, keep: np.ndarray | None, n_lm: int, min_parallax_rad: float,
           max_range_m: float, min_depth_m: float) -> np.ndarray:
    """Landmarks with two kept rays or more, in front of each (the ray's bearing points at
    the estimate: a residual under pi / 2) at ``min_depth_m`` to ``max_range_m`` deep, whose rays have
    :func:`~bomgraph.geometry.effective_parallax` ``>= min_parallax``."""
    if keep is not None:
        k, lm, res_rad = k[keep], lm[keep], res_rad[keep]
    d = points[lm] - poses[k, :2]
    ang = np.arctan2(d[:, 1], d[:, 0])
    depth = np.hypot(d[:, 0], d[:, 1])
    count = np.bincount(lm, minlength=n_lm)
    bad = (depth > max_range_m) | (depth < min_depth_m) | (np.abs(res_rad) >= math.pi / 2)
    far = np.bincount(lm, bad, minlength=n_lm) > 0
    parallax = effective_parallax(ang, lm, n_lm)
    return (count >= 2) & ~far & (parallax >= max(min_parallax_rad, 1e-15))


def _empty(poses: np.ndarray, n_outliers: int) -> WindowBundle:
    return WindowBundle(np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros((0, 0)), poses,
                        np.zeros(0, np.int64), n_outliers, False)


def relative_range_sigma(bundle: WindowBundle, bearings_rad: ArrayLike) -> np.ndarray:
    """How well each landmark of a window is triangulated: the largest std. dev. of its
    point (the square root of the larger eigenvalue of its 2 x 2 block of the bundle's
    covariance, from the rays' actual geometry and the window's bearing sigma) over its mean
    range from the poses that saw it (finite entries of ``bearings_rad``, the window's
    ``(W, n)`` bearing matrix). A landmark seen from a short baseline far away has a long,
    thin error ellipse along its rays: its value approaches the relative depth error."""
    brg = np.asarray(bearings_rad, dtype=float)[:, bundle.column]
    n = len(bundle)
    if n == 0:
        return np.zeros(0)
    idx = np.arange(n)
    blocks = bundle.covariance_m2.reshape(n, 2, n, 2)[idx, :, idx, :]        # (n, 2, 2)
    largest = np.linalg.eigvalsh(blocks)[:, -1]
    seen = np.isfinite(brg)
    d = bundle.points_xy[None, :, :] - bundle.poses[:, None, :2]             # (W, n, 2)
    rng = np.where(seen, np.hypot(d[..., 0], d[..., 1]), 0.0).sum(0) / seen.sum(0)
    return np.sqrt(np.maximum(largest, 0.0)) / rng


def bundle_pair_squared_distances(bundle: WindowBundle) -> PairEstimates:
    """Squared distance and first-order variance of every pair of a window's landmarks.

    ``var(d_ij^2) = 4 e^T (C_ii + C_jj - C_ij - C_ji) e`` with ``e = p_i - p_j`` and ``C`` the
    joint covariance of the bundle (shared poses and bearings included).
    """
    first, second = pair_indices(len(bundle))
    e = bundle.points_xy[first] - bundle.points_xy[second]
    n = len(bundle)
    blocks = bundle.covariance_m2.reshape(n, 2, n, 2).transpose(0, 2, 1, 3)
    d = (blocks[first, first] + blocks[second, second] - blocks[first, second]
         - blocks[second, first])
    var = 4.0 * np.einsum("pa,pab,pb->p", e, d, e)
    return PairEstimates(first, second, np.einsum("pa,pa->p", e, e), var, None)


__all__ = ["SIGMA_FLOOR", "PrefixState", "WindowBundle", "bundle_adjust_window",
           "bundle_pair_squared_distances", "relative_range_sigma"]
