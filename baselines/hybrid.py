"""``hybrid``: the GTSAM bearing factor graph seeded with the BOM-STMDS map.

BOM-STMDS (the paper, sections III-B to III-D) builds a landmark map without localising the
robot; a factor graph needs a good start for every pose and landmark or Levenberg-Marquardt
settles in a wrong basin (starting from dead reckoning it often does). At each ``estimate()``:

1. run the seed mapper alongside (``seed_method``, BOM-STMDS Method 2 by default) and take its
   map, which lives in its own frame, possibly mirrored;
2. align it rigidly, reflection allowed (:func:`bomgraph.evaluate.align`, trimmed), into the
   odometry frame: onto the previous solution's landmarks, or at first onto landmarks
   triangulated from the dead-reckoned early trajectory;
3. initialise every pose by resection against that map (:func:`resect_poses`, all poses at
   once: each pose's bearings to the mapped landmarks, a grid over the heading or the previous
   solution as the start, Gauss-Newton with Huber weights; then again with the odometry
   prediction from the pose before as a prior; poses that see fewer than 3 mapped landmarks
   are chained by the odometry), then move the whole start rigidly so that the first pose is
   ``start_pose``;
4. run LM on the same graph as ``gtsam-batch`` (:mod:`baselines.factor_graph`) from that start,
   and from the warm start of the previous solution; keep the lower cost.

With dead-reckoned poses instead of resected ones the issue measured 32% convergence; the
resection is what makes the seed useful.

Landmarks enter the graph by the same rule as in the other GTSAM mappers (so the graphs and
their costs compare); their start is the aligned seed position, else the ray intersection on
the resected poses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any, Sequence

import gtsam
import numpy as np
from scipy import sparse

from bomgraph.angles import angle_residual, wrap_angle
from bomgraph.errors import BomgraphError, ConfigError
from bomgraph.evaluate import Alignment, align
from bomgraph.geometry import compose, dead_reckon
from bomgraph.mapper import MapEstimate, Mapper, create_mapper
from bomgraph.stream import Step, StreamHeader
from bomgraph.geometry import intersect_rays, ray_normals

from .factor_graph import (BatchMapper, FactorGraphConfig, config_from, estimate_from_values,
                           insert_pose, landmark_key, landmarks_from_values, poses_from_values,
                           solve_lm)


@dataclass(frozen=True)
class HybridConfig:
    """Options of the seeding (the graph and LM options are a :class:`FactorGraphConfig`).

    Attributes
    ----------
    seed_method : str
        Registered mapper whose map seeds the graph.
    align_steps : int
        At the first alignment, landmarks are triangulated from the dead-reckoned poses of the
        first ``align_steps`` steps (all steps if that leaves fewer than 3 common landmarks).
    align_trim : float
        Alignment is redone without landmarks whose residual exceeds ``align_trim`` times the
        median residual (and 1 cm).
    map_sigma_m : float
        Assumed position error of the seed map: a bearing to a landmark at range ``r`` has
        std. dev. ``sqrt(sigma_theta^2 + (map_sigma_m / r)^2)`` in the resection.
    prior_sigma : (m, m, rad)
        Std. dev. of the odometry prediction used as the resection prior, added in quadrature
        to the step's odometry sigma.
    n_headings : int
        Grid over the heading in the resection.
    resection_huber_k : float
        Huber threshold (whitened) of the resection's bearing residuals.
    warm_start : bool
        Also run LM from the previous solution and keep the lower cost.
    seed_huber, warm_huber : bool
        Run the Huber pass (``FactorGraphConfig.huber_k``) before the plain one from the
        seeded start / from the warm start. With two starts to choose from, neither needed it
        on the paper setup; ``gtsam-batch`` (one start) does.
    """

    seed_method: str = "stmds-smacof"
    align_steps: int = 50
    align_trim: float = 3.0
    map_sigma_m: float = 0.03
    prior_sigma: tuple[float, float, float] = (0.02, 0.02, math.radians(2.0))
    n_headings: int = 36
    resection_huber_k: float = 2.0
    warm_start: bool = True
    seed_huber: bool = False
    warm_huber: bool = False

    def __post_init__(self) -> None:
        def need(ok: bool, msg: str) -> None:
            if not ok:
                raise ConfigError(f"HybridConfig: {msg}")

        need(isinstance(self.seed_method, str) and self.seed_method not in ("hybrid", "oracle"),
             f"seed_method must name a registered non-hybrid mapper, got {self.seed_method!r}")
        need(self.align_steps >= 2, "align_steps must be >= 2")
        need(self.align_trim > 1, "align_trim must be > 1")
        need(self.map_sigma_m >= 0, "map_sigma_m must be >= 0")
        need(len(self.prior_sigma) == 3 and all(s > 0 for s in self.prior_sigma),
             "prior_sigma must be 3 numbers > 0")
        need(self.n_headings >= 4, "n_headings must be >= 4")
        need(self.resection_huber_k > 0, "resection_huber_k must be > 0")


# --------------------------------------------------------------------------------------------
# Resection
# --------------------------------------------------------------------------------------------

def resection_jacobian(pose: np.ndarray, landmarks_xy: np.ndarray) -> np.ndarray:
    """Jacobian ``(k, 3)`` of the predicted bearings ``atan2(l - p) - psi`` w.r.t. the pose
    ``[x, y, psi]`` (``pose`` of shape (3,) or one pose per landmark, (k, 3))."""
    d = np.asarray(landmarks_xy, dtype=float) - np.asarray(pose, dtype=float)[..., :2]
    r2 = np.maximum((d * d).sum(-1), 1e-18)
    return np.column_stack([d[:, 1] / r2, -d[:, 0] / r2, -np.ones(len(d))])


def _group_sum(owner: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Sum ``values`` (J, ...) over rows with the same ``owner`` (J,), shape (n, ...)."""
    if len(owner) == 0:
        return np.zeros((n, *values.shape[1:]))
    m = sparse.csr_matrix((np.ones(len(owner)), (owner, np.arange(len(owner)))),
                          shape=(n, len(owner)))
    return np.asarray(m @ values.reshape(len(owner), -1)).reshape(n, *values.shape[1:])


def _huber_rho(r: np.ndarray, k: float) -> np.ndarray:
    a = np.abs(r)
    return np.where(a <= k, 0.5 * r * r, k * (a - 0.5 * k))


def resect_poses(owner: np.ndarray, landmarks_xy: np.ndarray, bearings_rad: np.ndarray,
                 sigma_rad: np.ndarray, n_poses: int, *,
                 prior_poses: np.ndarray | None = None,
                 prior_sigma: np.ndarray | None = None,
                 initial_poses: np.ndarray | None = None, n_headings: int = 72,
                 huber_k: float = 2.0, iterations: int = 10
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Robot poses that best explain bearings to known landmarks, all poses at once.

    For each pose minimises ``sum_j 2 rho(r_j / sigma_j) + |(pose - prior) / prior_sigma|^2``
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
        Std. dev. of the priors (metres, metres, radians).
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
    ps = np.broadcast_to(np.asarray(1.0 if prior_sigma is None else prior_sigma, dtype=float),
                         (n_poses, 3))
    info = np.where(has_prior[:, None], 1.0 / ps ** 2, 0.0)            # (T, 3)
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
        d = lm[sel][:, None, :] - c[..., :2]                            # (J', H, 2)
        r = angle_residual(np.arctan2(d[..., 1], d[..., 0]) - c[..., 2],
                           b[sel][:, None]) / sig[sel][:, None]
        e = cands - prior0[rows][:, None, :]
        e[..., 2] = angle_residual(cands[..., 2], prior0[rows][:, None, 2])
        return (2 * _group_sum(o, _huber_rho(r, huber_k), len(rows))
                + (e * e * info[rows][:, None, :]).sum(-1))

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
        a[..., 0, 0] += info[rows, None, 0]
        a[..., 1, 1] += info[rows, None, 1]
        rhs += (info[rows, :2] * prior0[rows, :2])[:, None, :]
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
        d = l_ - p[o, :2]
        r = angle_residual(np.arctan2(d[:, 1], d[:, 0]) - p[o, 2], b_) / s_
        wr = np.where(np.abs(r) <= huber_k, 1.0, huber_k / np.maximum(np.abs(r), 1e-300))
        jac = resection_jacobian(p[o], l_) / s_[:, None]
        h = _group_sum(o, wr[:, None, None] * jac[:, :, None] * jac[:, None, :], len(idx))
        g = _group_sum(o, (wr * r)[:, None] * jac, len(idx))
        e = np.column_stack([p[:, :2] - prior0[idx, :2],
                             angle_residual(p[:, 2], prior0[idx, 2])])
        h[:, [0, 1, 2], [0, 1, 2]] += info[idx]
        g += info[idx] * e
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


# --------------------------------------------------------------------------------------------
# Alignment
# --------------------------------------------------------------------------------------------

def trimmed_align(source_xy: np.ndarray, target_xy: np.ndarray, trim: float = 3.0,
                  floor_m: float = 0.01) -> Alignment:
    """Rigid alignment with reflection of ``source`` onto ``target`` ((n, 2) each, n >= 3),
    refitted once without the points whose residual exceeds ``trim`` times the median (and
    ``floor_m``)."""
    al = align(source_xy, target_xy, allow_reflection=True)
    res = np.linalg.norm(al.apply(source_xy) - target_xy, axis=1)
    keep = res <= max(trim * float(np.median(res)), floor_m)
    if 3 <= keep.sum() < len(keep):
        al = align(source_xy[keep], target_xy[keep], allow_reflection=True)
    return al


def _inverse_increment(odom: np.ndarray) -> np.ndarray:
    """The increment ``v`` with ``compose(compose(p, odom), v) = p``, shape (3,)."""
    c, s = math.cos(float(odom[2])), math.sin(float(odom[2]))
    return np.array([-c * odom[0] - s * odom[1], s * odom[0] - c * odom[1], -odom[2]])


def _rigid_to(pose_from: np.ndarray, pose_to: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, float]:
    """Rotation ``R``, translation ``c`` and angle with ``R pose_from.xy + c = pose_to.xy``."""
    ang = float(angle_residual(pose_to[2], pose_from[2]))
    cs, sn = math.cos(ang), math.sin(ang)
    r = np.array([[cs, -sn], [sn, cs]])
    return r, pose_to[:2] - r @ pose_from[:2], ang


# --------------------------------------------------------------------------------------------
# The mapper
# --------------------------------------------------------------------------------------------

class HybridMapper(BatchMapper):
    """``hybrid``: LM on the bearing factor graph, started from the BOM-STMDS map.

    Parameters
    ----------
    header : StreamHeader
    start_pose : (x_m, y_m, psi_rad)
        The map frame (first pose).
    seed_options : dict, optional
        Options of the seed mapper.
    seed_mapper : Mapper, optional
        A seed mapper instance to use instead of building ``seed_method`` (fed the same
        steps; its map may be in any frame, mirrored or not).
    hybrid : HybridConfig, optional
    config : FactorGraphConfig, optional
    **options
        Fields of :class:`HybridConfig` or of :class:`FactorGraphConfig` (by name).
    """

    def __init__(self, header: StreamHeader, *,
                 start_pose: Sequence[float] = (0.0, 0.0, 0.0),
                 seed_options: dict[str, Any] | None = None,
                 seed_mapper: Mapper | None = None,
                 hybrid: HybridConfig | None = None,
                 config: FactorGraphConfig | None = None, **options: Any) -> None:
        names = {f.name for f in fields(HybridConfig)}
        hyb_opts = {k: options.pop(k) for k in list(options) if k in names}
        if hybrid is not None and hyb_opts:
            raise ConfigError(f"pass either hybrid= or its options, not both "
                              f"(got {sorted(hyb_opts)})")
        self.hybrid = hybrid or HybridConfig(**hyb_opts)
        super().__init__(header, start_pose=start_pose, config=config_from(config, options))
        if seed_mapper is not None and seed_options:
            raise ConfigError("seed_options apply to seed_method; pass them to seed_mapper's "
                              "constructor instead")
        self.seed = seed_mapper if seed_mapper is not None else create_mapper(
            self.hybrid.seed_method, header, **(seed_options or {}))
        self._steps_ids: list[np.ndarray] = []
        self._steps_brg: list[np.ndarray] = []
        self._odom_sigma: list[np.ndarray] = []
        self._resected: np.ndarray | None = None
        self._seed_map: dict[int, np.ndarray] = {}
        self._have_solution = False

    def step(self, step: Step) -> None:
        super().step(step)
        self.seed.step(step)
        self._steps_ids.append(step.landmark_ids)
        self._steps_brg.append(step.bearings_rad)
        self._odom_sigma.append(step.odometry_sigma(self.header))

    # -- seeding --------------------------------------------------------------------------
    def _dead_reckoned(self) -> np.ndarray:
        odoms = np.array([o for o in self.problem.odoms[1:]]).reshape(-1, 3)
        return dead_reckon(odoms, self.problem.start_pose)

    def _reference(self, seed_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        """Landmarks in the odometry frame to align the seed onto: the previous solution's
        (then True), else triangulated on the dead-reckoned early trajectory."""
        if self._have_solution and self.problem.landmark_ids:
            ids = np.array(sorted(self.problem.landmark_ids), dtype=np.int64)
            common = np.intersect1d(ids, seed_ids)
            if common.size >= 3:
                return common, landmarks_from_values(self.values, common), True
        poses = self._dead_reckoned()
        for upto in (min(self.hybrid.align_steps, len(poses)), len(poses)):
            ids_out, xy_out = self._triangulate(poses[:upto], upto, seed_ids)
            if ids_out.size >= 3:
                return ids_out, xy_out, False
        return np.zeros(0, np.int64), np.zeros((0, 2)), False

    def _triangulate(self, poses: np.ndarray, upto: int, only: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
        ts = np.concatenate([np.full(len(self._steps_ids[t]), t) for t in range(upto)])
        ids = np.concatenate(self._steps_ids[:upto])
        brg = np.concatenate(self._steps_brg[:upto])
        out_ids, out_xy = [], []
        for lid in np.intersect1d(np.unique(ids), only):
            sel = ids == lid
            if sel.sum() < 2:
                continue
            p = poses[ts[sel]]
            xy, ok = intersect_rays(p[:, :2], p[:, 2] + brg[sel],
                                    min_parallax_rad=self.config.min_parallax_rad)
            if ok:
                out_ids.append(int(lid))
                out_xy.append(xy)
        return np.array(out_ids, dtype=np.int64), np.array(out_xy).reshape(-1, 2)

    def _resect_all(self, map_ids: np.ndarray, map_xy: np.ndarray,
                    start: np.ndarray | None = None) -> np.ndarray | None:
        """Every pose by resection against the map, shape (T, 3), or None if none resects.

        Pass 1 resects each pose with at least 3 mapped bearings on its own (from ``start``
        (T, 3) if given; a pose whose fit is then poor, more than 9 per bearing, is redone
        from the heading grid); pass 2 again with the odometry prediction from the pass-1
        pose before it as a prior, bearings weighted by the map error at their range. Poses
        left undetermined are chained from their neighbours by the odometry.
        """
        cfg = self.hybrid
        n_t = self.problem.n_steps
        owner = np.concatenate([np.full(len(i), t, np.int64)
                                for t, i in enumerate(self._steps_ids)])
        ids = np.concatenate(self._steps_ids)
        brg = np.concatenate(self._steps_brg)
        order = np.argsort(map_ids)
        pos = np.clip(np.searchsorted(map_ids[order], ids), 0, len(map_ids) - 1)
        have = map_ids[order][pos] == ids
        own, lm, b = owner[have], map_xy[order][pos[have]], brg[have]
        sig_b = float(self.header.bearing_sigma_rad)
        kw = dict(n_headings=cfg.n_headings, huber_k=cfg.resection_huber_k)
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
        odoms = np.array([np.zeros(3) if o is None else o for o in self.problem.odoms])
        sigmas = np.array(self._odom_sigma)
        prev_ok = np.flatnonzero(ok1[:-1]) + 1
        prior[prev_ok] = compose(p1[prev_ok - 1], odoms[prev_ok])
        prior_sigma = np.sqrt(np.asarray(cfg.prior_sigma) ** 2 + sigmas ** 2)
        ref = np.where(ok1[:, None], p1, prior)[own, :2]
        rng = np.hypot(*(lm - ref).T)
        sig = np.where(np.isfinite(rng),
                       np.sqrt(sig_b ** 2 + (cfg.map_sigma_m / np.maximum(rng, 0.05)) ** 2),
                       2 * sig_b)
        poses, _, _ = resect_poses(own, lm, b, sig, n_t, prior_poses=prior,
                                   prior_sigma=prior_sigma,
                                   initial_poses=np.where(ok1[:, None], p1, np.nan), **kw)
        ok = np.all(np.isfinite(poses), axis=1) & ((n_b >= 3) | np.isfinite(prior[:, 0]))
        if not ok.any():
            return None
        first = int(np.argmax(ok))
        for t in range(first - 1, -1, -1):          # before the first: odometry backwards
            poses[t] = compose(poses[t + 1], _inverse_increment(odoms[t + 1]))
        for t in range(first + 1, n_t):             # gaps: odometry forwards
            if not ok[t]:
                poses[t] = compose(poses[t - 1], odoms[t])
        return poses

    def _seed(self) -> tuple[gtsam.Values | None, dict[str, Any]]:
        """Initial values from the seed map, or None (and why)."""
        try:
            seed = self.seed.estimate()
        except BomgraphError as exc:
            return None, {"seed": f"seed mapper failed: {exc}"}
        if len(seed) < 3:
            return None, {"seed": f"seed map has {len(seed)} landmarks (< 3)"}
        ref_ids, ref_xy, in_solution_frame = self._reference(seed.landmark_ids)
        if ref_ids.size < 3:
            return None, {"seed": "fewer than 3 landmarks to align the seed map on"}
        _, i_seed, i_ref = np.intersect1d(seed.landmark_ids, ref_ids, return_indices=True)
        al = trimmed_align(seed.landmarks_xy[i_seed], ref_xy[i_ref], self.hybrid.align_trim)
        map_xy = al.apply(seed.landmarks_xy)
        # in the previous solution's frame its poses (and the odometry predictions of the
        # new ones) start the resection; otherwise a grid over the heading does
        start = (poses_from_values(self.values, np.arange(self.problem.n_steps))
                 if in_solution_frame else None)
        poses = self._resect_all(seed.landmark_ids, map_xy, start)
        if poses is None:
            return None, {"seed": "no pose sees 3 landmarks of the seed map"}
        # the first pose defines the frame: move the whole start rigidly onto it
        r, c, ang = _rigid_to(poses[0], self.problem.start_pose)
        poses = np.column_stack([poses[:, :2] @ r.T + c, wrap_angle(poses[:, 2] + ang)])
        map_xy = map_xy @ r.T + c
        self._resected = poses
        values = gtsam.Values()
        for t in range(self.problem.n_steps):
            insert_pose(values, t, poses[t], poses[t - 1] if t else None, self.config)
        self._seed_map = dict(zip(seed.landmark_ids.tolist(), map_xy))
        return values, {"seed": "ok", "seed_reflected": al.reflected,
                        "seed_landmarks": len(seed)}

    def _pose_at(self, ts: np.ndarray) -> np.ndarray:
        if self._resected is not None:
            return self._resected[np.asarray(ts, dtype=np.int64)]
        return super()._pose_at(ts)

    def _out_of_reach(self, values: gtsam.Values) -> np.ndarray:
        """Ids of the landmarks farther than ``range_gate * sensor_range_m`` from every pose
        (none when the header has no sensor range)."""
        rng = self.header.sensor_range_m
        ids = np.array(self.problem.landmark_ids, np.int64)
        if rng is None or not ids.size or self.problem.n_steps == 0:
            return np.zeros(0, np.int64)
        xy = landmarks_from_values(values, ids)
        poses = poses_from_values(values, np.arange(self.problem.n_steps))[:, :2]
        d2 = ((xy[:, None, :] - poses[None, :, :]) ** 2).sum(axis=2).min(axis=1)
        return ids[d2 > (self.config.range_gate * rng) ** 2]

    # -- estimate -------------------------------------------------------------------------
    def estimate(self) -> MapEstimate:
        if self.problem.n_steps == 0:
            return MapEstimate.empty(reason="no steps yet")
        self._resected = None
        self._seed_map = {}
        seeded, info = self._seed()
        warm = gtsam.Values(self.values)
        if seeded is not None:
            # the seed map places the landmarks the rays alone do not yet determine (too
            # little parallax on the resected poses): they enter at their seed position
            for lid, n_rays in self.problem.pending().items():
                if n_rays >= 2 and lid in self._seed_map:
                    self.problem.enter(lid, self._seed_map[lid])
        self.absorb()   # admission judged on the resected poses when seeded
        self._resected = None
        starts: list[tuple[str, gtsam.Values]] = []
        if seeded is not None:
            for lid in self.problem.landmark_ids:
                xy = self._seed_map.get(lid)
                if xy is None:
                    xy = self.values.atPoint2(landmark_key(lid))
                seeded.insert(landmark_key(lid), gtsam.Point2(float(xy[0]), float(xy[1])))
            starts.append(("seed", seeded))
        if seeded is None or (self.hybrid.warm_start and self._have_solution):
            # previous solution + odometry predictions + new landmarks' intersections
            for lid in self.problem.landmark_ids:
                if not warm.exists(landmark_key(lid)):
                    warm.insert(landmark_key(lid), self.values.atPoint2(landmark_key(lid)))
            starts.append(("warm", warm))
        huber = {"seed": self.hybrid.seed_huber, "warm": self.hybrid.warm_huber}
        solved = [(name, *solve_lm(self.graph, start, self.config,
                                   self.robust_graph if huber[name] else None))
                  for name, start in starts]
        # a start whose solution puts landmarks out of the sensor's reach of every pose (a
        # weakly seen landmark slid far along its rays: a converged but wrong minimum) loses
        # to one that does not, whatever the costs
        name, values, report = min(solved, key=lambda s: (self._out_of_reach(s[1]).size > 0,
                                                           s[2].final_error))
        self.values = values
        self._have_solution = True
        info.update(report.as_info())
        info["start"] = name
        info["starts"] = [s for s, _ in starts]
        est = estimate_from_values(self.problem, values, self.graph, info,
                                   self.config.covariances)
        far = self._out_of_reach(values)
        if far.size:
            # still there in the best solution: not determined yet (too little parallax);
            # left out of the map, and moved back to their seed position (if any) for the
            # next warm start
            for lid in far.tolist():
                if lid in self._seed_map:
                    xy = self._seed_map[lid]
                    self.values.update(landmark_key(lid), gtsam.Point2(float(xy[0]),
                                                                       float(xy[1])))
            keep = ~np.isin(est.landmark_ids, far)
            est = replace(est, landmark_ids=est.landmark_ids[keep],
                          landmarks_xy=est.landmarks_xy[keep],
                          landmark_cov=None if est.landmark_cov is None
                          else est.landmark_cov[keep],
                          info={**est.info, "out_of_reach": far.tolist()})
        return est


__all__ = ["HybridConfig", "HybridMapper", "resect_pose", "resection_jacobian",
           "trimmed_align"]
