"""``hybrid``: the GTSAM bearing factor graph seeded with the BOM-STMDS map.

BOM-STMDS (the paper, sections III-B to III-D) builds a landmark map without localising the
robot; a factor graph needs a good start for every pose and landmark or Levenberg-Marquardt
settles in a wrong basin (starting from dead reckoning it often does). At each ``estimate()``:

1. run the seed mapper alongside (``seed_method``, BOM-STMDS Method 2 by default) and take its
   map, which lives in its own frame, possibly mirrored;
2. align it rigidly, reflection allowed (:func:`bomgraph.evaluate.align`, trimmed), into the
   odometry frame: onto the previous solution's landmarks, or at first onto landmarks
   triangulated from the dead-reckoned early trajectory;
3. initialise every pose by resection against that map (:func:`resect_pose`: its bearings to
   the mapped landmarks plus the odometry prediction from the previous pose as a prior, a grid
   over the heading then Gauss-Newton), then move the whole start rigidly so that the first
   pose is ``start_pose``;
4. run LM on the same graph as ``gtsam-batch`` (:mod:`baselines.factor_graph`) from that start,
   and from the warm start of the previous solution; keep the lower cost.

Landmarks enter the graph by the same rule as in the other GTSAM mappers (so the graphs and
their costs compare); their start is the aligned seed position, else the ray intersection on
the resected poses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Sequence

import gtsam
import numpy as np

from bomgraph.angles import angle_residual, wrap_angle
from bomgraph.errors import BomgraphError, ConfigError
from bomgraph.evaluate import Alignment, align
from bomgraph.geometry import compose, dead_reckon
from bomgraph.mapper import MapEstimate, Mapper, create_mapper
from bomgraph.stream import Step, StreamHeader
from bomgraph.triangulate import intersect_rays, ray_normals

from .factor_graph import (BatchMapper, FactorGraphConfig, _config, _estimate_from_values,
                           insert_pose, landmark_key, landmarks_from_values, solve_lm)


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
    seed_huber : bool
        Run the Huber pass (``FactorGraphConfig.huber_k``) from the seeded start too (the
        warm start always gets it); the seed is usually close enough to skip it.
    """

    seed_method: str = "stmds-smacof"
    align_steps: int = 50
    align_trim: float = 3.0
    map_sigma_m: float = 0.03
    prior_sigma: tuple[float, float, float] = (0.02, 0.02, math.radians(2.0))
    n_headings: int = 72
    resection_huber_k: float = 2.0
    warm_start: bool = True
    seed_huber: bool = False

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

def _bearing_residuals(pose: np.ndarray, landmarks_xy: np.ndarray,
                       bearings_rad: np.ndarray) -> np.ndarray:
    d = landmarks_xy - pose[:2]
    return angle_residual(np.arctan2(d[:, 1], d[:, 0]) - pose[2], bearings_rad)


def resection_jacobian(pose: np.ndarray, landmarks_xy: np.ndarray) -> np.ndarray:
    """Jacobian ``(k, 3)`` of the predicted bearings ``atan2(l - p) - psi`` w.r.t. the pose."""
    d = landmarks_xy - pose[:2]
    r2 = np.maximum((d * d).sum(1), 1e-18)
    return np.column_stack([d[:, 1] / r2, -d[:, 0] / r2, -np.ones(len(d))])


def resect_pose(landmarks_xy: np.ndarray, bearings_rad: np.ndarray,
                sigma_rad: np.ndarray | float, prior_pose: np.ndarray,
                prior_sigma: np.ndarray, *, n_headings: int = 72, huber_k: float = 2.0,
                iterations: int = 15) -> tuple[np.ndarray, float]:
    """The robot pose that best explains bearings to known landmarks, with a pose prior.

    Minimises ``sum_k rho(r_k / sigma_k) + |(pose - prior) / prior_sigma|^2`` (``r_k`` the
    wrapped bearing residual, ``rho`` Huber): every heading of a grid gets its best position
    in closed form (the weighted least-squares intersection of the lines through the
    landmarks), the best grid point is polished by Gauss-Newton (IRLS for the Huber weights).

    Parameters
    ----------
    landmarks_xy : array of shape (k, 2)
        Known landmark positions (k may be 0: the prior is returned).
    bearings_rad : array of shape (k,)
        Bearings to them, relative to the robot heading.
    sigma_rad : float or array of shape (k,)
    prior_pose : array of shape (3,)
    prior_sigma : array of shape (3,)
        Std. dev. of the prior (metres, metres, radians), > 0.
    n_headings, huber_k, iterations : grid size, Huber threshold, Gauss-Newton iterations.

    Returns
    -------
    pose : ndarray of shape (3,)
    cost : float
        Final value of the objective (the whitened chi^2 with Huber).
    """
    lm = np.asarray(landmarks_xy, dtype=float).reshape(-1, 2)
    b = np.asarray(bearings_rad, dtype=float).reshape(-1)
    prior = np.asarray(prior_pose, dtype=float).reshape(3)
    ps = np.asarray(prior_sigma, dtype=float).reshape(3)
    if len(lm) != len(b):
        raise ConfigError(f"resect_pose: {len(lm)} landmarks but {len(b)} bearings")
    if len(lm) == 0:
        return prior.copy(), 0.0
    sig = np.broadcast_to(np.asarray(sigma_rad, dtype=float), b.shape)

    def costs(poses: np.ndarray) -> np.ndarray:
        """Objective for poses (m, 3), vectorised."""
        d = lm[None, :, :] - poses[:, None, :2]
        r = angle_residual(np.arctan2(d[..., 1], d[..., 0]) - poses[:, 2:3], b) / sig
        a = np.abs(r)
        rho = np.where(a <= huber_k, 0.5 * r * r, huber_k * (a - 0.5 * huber_k))
        e = np.column_stack([poses[:, :2] - prior[:2],
                             angle_residual(poses[:, 2], prior[2])]) / ps
        return 2 * rho.sum(1) + (e * e).sum(1)

    # grid over the heading: closed-form position for each
    psi = prior[2] + np.linspace(-np.pi, np.pi, n_headings, endpoint=False)
    rng = np.maximum(np.hypot(*(lm - prior[:2]).T), 1e-3)
    w = 1.0 / (sig * rng) ** 2                                   # (k,)
    n = ray_normals(psi[:, None] + b[None, :])                    # (H, k, 2, 2)
    a = np.einsum("k,hkij->hij", w, n) + np.diag(1.0 / ps[:2] ** 2)
    rhs = np.einsum("k,hkij,kj->hi", w, n, lm) + prior[:2] / ps[:2] ** 2
    xy = np.linalg.solve(a, rhs[..., None])[..., 0]
    cands = np.column_stack([xy, wrap_angle(psi)])
    grid_costs = costs(cands)
    pose = cands[int(np.argmin(grid_costs))].copy()
    best = float(grid_costs.min())
    # Gauss-Newton / IRLS polish
    for _ in range(iterations):
        r = _bearing_residuals(pose, lm, b) / sig
        wr = np.where(np.abs(r) <= huber_k, 1.0, huber_k / np.maximum(np.abs(r), 1e-300))
        j = resection_jacobian(pose, lm) / sig[:, None]
        e = np.array([pose[0] - prior[0], pose[1] - prior[1],
                      float(angle_residual(pose[2], prior[2]))]) / ps
        h = j.T @ (wr[:, None] * j) + np.diag(1.0 / ps ** 2)
        g = j.T @ (wr * r) + e / ps
        step = -np.linalg.solve(h, g)
        trial = pose + step
        trial[2] = wrap_angle(trial[2])
        c = float(costs(trial[None])[0])
        if c > best:
            break
        pose, gain, best = trial, best - c, c
        if np.max(np.abs(step)) < 1e-10 or gain < 1e-10 * max(best, 1.0):
            break
    return pose, best


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
        super().__init__(header, start_pose=start_pose, config=_config(config, options))
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

    def _reference(self, seed_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Landmarks in the odometry frame to align the seed onto: the previous solution's,
        else triangulated on the dead-reckoned early trajectory."""
        if self._have_solution and self.problem.landmark_ids:
            ids = np.array(sorted(self.problem.landmark_ids), dtype=np.int64)
            common = np.intersect1d(ids, seed_ids)
            if common.size >= 3:
                return common, landmarks_from_values(self.values, common)
        poses = self._dead_reckoned()
        for upto in (min(self.hybrid.align_steps, len(poses)), len(poses)):
            ids_out, xy_out = self._triangulate(poses[:upto], upto, seed_ids)
            if ids_out.size >= 3:
                return ids_out, xy_out
        return np.zeros(0, np.int64), np.zeros((0, 2))

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

    def _resect_all(self, map_ids: np.ndarray, map_xy: np.ndarray) -> np.ndarray:
        """Every pose by resection against the map, chained with the odometry prior."""
        cfg = self.hybrid
        slot = {int(i): k for k, i in enumerate(map_ids)}
        poses = np.empty((self.problem.n_steps, 3))
        prev = None
        sig_b = float(self.header.bearing_sigma_rad)
        for t in range(self.problem.n_steps):
            if t == 0:
                pred = self.problem.start_pose
                psig = np.asarray(cfg.prior_sigma)
            else:
                pred = compose(prev, self.problem.odoms[t])
                psig = np.sqrt(np.asarray(cfg.prior_sigma) ** 2 + self._odom_sigma[t] ** 2)
            ids = self._steps_ids[t]
            k = np.array([slot.get(int(i), -1) for i in ids], dtype=np.int64)
            have = k >= 0
            if have.sum() >= 2:
                lm = map_xy[k[have]]
                rng = np.maximum(np.hypot(*(lm - pred[:2]).T), 0.05)
                sig = np.sqrt(sig_b ** 2 + (cfg.map_sigma_m / rng) ** 2)
                pose, _ = resect_pose(lm, self._steps_brg[t][have], sig, pred, psig,
                                      n_headings=cfg.n_headings,
                                      huber_k=cfg.resection_huber_k)
            else:
                pose = pred
            poses[t] = pose
            prev = pose
        return poses

    def _seed(self) -> tuple[gtsam.Values | None, dict[str, Any]]:
        """Initial values from the seed map, or None (and why)."""
        try:
            seed = self.seed.estimate()
        except BomgraphError as exc:
            return None, {"seed": f"seed mapper failed: {exc}"}
        if len(seed) < 3:
            return None, {"seed": f"seed map has {len(seed)} landmarks (< 3)"}
        ref_ids, ref_xy = self._reference(seed.landmark_ids)
        if ref_ids.size < 3:
            return None, {"seed": "fewer than 3 landmarks to align the seed map on"}
        _, i_seed, i_ref = np.intersect1d(seed.landmark_ids, ref_ids, return_indices=True)
        al = trimmed_align(seed.landmarks_xy[i_seed], ref_xy[i_ref], self.hybrid.align_trim)
        map_xy = al.apply(seed.landmarks_xy)
        poses = self._resect_all(seed.landmark_ids, map_xy)
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

    # -- estimate -------------------------------------------------------------------------
    def estimate(self) -> MapEstimate:
        if self.problem.n_steps == 0:
            return MapEstimate.empty(reason="no steps yet")
        self._resected = None
        self._seed_map = {}
        seeded, info = self._seed()
        warm = gtsam.Values(self.values)
        self._absorb()   # admission judged on the resected poses when seeded
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
        solved = [(name, *solve_lm(self.graph, start, self.config,
                                   None if name == "seed" and not self.hybrid.seed_huber
                                   else self.robust_graph))
                  for name, start in starts]
        name, values, report = min(solved, key=lambda s: s[2].final_error)
        self.values = values
        self._have_solution = True
        info.update(report.as_info())
        info["start"] = name
        info["starts"] = [s for s, _ in starts]
        return _estimate_from_values(self.problem, values, self.graph, info,
                                     self.config.covariances)


__all__ = ["HybridConfig", "HybridMapper", "resect_pose", "resection_jacobian",
           "trimmed_align"]
