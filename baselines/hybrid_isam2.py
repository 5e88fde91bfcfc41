"""``hybrid-isam2``: iSAM2 whose new landmarks enter at their BOM-STMDS positions.

``gtsam-isam2`` (:class:`baselines.isam2.Isam2Mapper`) lets a landmark into the graph only
once two of its rays intersect with ``min_parallax_rad`` of parallax (0.3 rad): until then
its bearings wait and the landmark is not mapped; a landmark whose rays stay nearly parallel
(seen ahead while driving towards it) waits a long time. BOM-STMDS (the paper, sections
III-B to III-D) maps landmarks from pair distances, without that wait. This mapper runs the
two side by side:

1. every step goes to iSAM2 and to the seed mapper (``seed_method``, ``stmds-smacof``);
2. when a pending landmark with at least two bearings does not yet pass the parallax rule,
   the seed map (recomputed at most every ``seed_every`` steps) is aligned into the running
   frame, rigid with reflection allowed and trimmed
   (:func:`baselines.gtsam_tools.align_map`), onto the landmarks iSAM2 already holds plus
   the pending ones whose rays intersect with ``align_parallax_rad`` on the current poses
   (:func:`bomgraph.geometry.intersect_ray_groups`);
3. the seed position is moved onto the landmark's rays (:func:`refine_on_rays`: the rays
   fix its direction, the seed the depth they leave open) and the landmark enters the graph
   there, with all its buffered bearings, if that point lies in front of its rays and
   within the sensor range gate. Optionally (``seed_sigma_m``) a ``PriorFactorPoint2`` at
   that position holds it while its rays are nearly parallel (the cause of GTSAM's
   "Indeterminant linear system", :func:`baselines.gtsam_tools.diagnose`); by default
   none: an update that fails is recovered by :class:`Isam2Mapper` (the landmark goes back
   to pending and retries).

Landmarks the seed does not place enter as in ``gtsam-isam2``. Everything else (updates,
rebuilds after a failed update, the batch fall-back, ``info``) is
:class:`~baselines.isam2.Isam2Mapper`'s; ``info`` adds ``seeded_landmarks`` and ``seed``
(why the last seeding attempt did or did not place landmarks).

Built by composition on :class:`Isam2Mapper`: the only thing it relies on is that the mapper
holds its :class:`~baselines.bearing_graph.BearingGraph` as ``problem`` and asks it
``admit(pose_at, only_fresh=True)`` once per step; the graph here is a subclass whose
``admit`` first enters the seeded landmarks. Measured: ``docs/measurements.md``
("hybrid-isam2").
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Callable, ClassVar, Mapping, Sequence

import gtsam
import numpy as np

from bomgraph.angles import angle_residual
from bomgraph.config import requirement, resolve
from bomgraph.errors import BomgraphError
from bomgraph.geometry import intersect_ray_groups
from bomgraph.mapper import MapEstimate, Mapper, check_seed, create_mapper
from bomgraph.stream import Step, StreamHeader

from .bearing_graph import BearingGraph, landmark_key, landmarks_from_values
from .gtsam_tools import align_map
from .hybrid import check_seed_mapper
from .isam2 import Isam2Config, Isam2Mapper

_REAL_SEED = {"seed_options": {"preset": "real"}}


@dataclass(frozen=True)
class HybridIsam2Config(Isam2Config):
    """Options of ``hybrid-isam2``: the graph and iSAM2 fields of :class:`Isam2Config` plus
    the seeding.

    Presets (:meth:`Presets.preset`): ``"paper"`` (the defaults, seed ``stmds-smacof`` with
    its paper configuration) and ``"real"`` (``gtsam-isam2``'s ``"real"`` robust kernels and
    weak landmark prior, and the seed's ``"real"`` preset, windowed bundle adjustment, for
    recordings).

    Attributes
    ----------
    seed_method : str
        Registered mapper whose map seeds the new landmarks.
    seed_options : mapping, optional
        Options of the seed mapper (e.g. ``{"preset": "real"}``).
    seed_every : int
        The seed map is recomputed at most every this many steps (only when a landmark is
        waiting for it).
    seed_sigma_m : float or None
        Std. dev. (m) of a prior put on a seeded landmark at its seed position, kept for
        good; None (the default) puts none: the seed is only the starting point and the
        landmark rests on its bearings, so the solution is the same problem's as
        ``gtsam-isam2`` (a kept prior counts the seed's information twice and biased the
        map; ``docs/measurements.md``). Without a prior the seed position is also refined
        on the rays with ``max_align_rms_m`` as its std. dev. (:func:`refine_on_rays`).
    align_trim : float
        The alignment is refitted without landmarks whose residual exceeds ``align_trim``
        times the median residual.
    align_parallax_rad : float
        Pending landmarks whose rays intersect with at least this parallax on the current
        poses join the alignment's reference (besides the landmarks in the graph).
    min_align_landmarks : int
        Landmarks common to the seed map and the reference needed to align (>= 3).
    max_align_rms_m : float
        An alignment whose RMS residual exceeds this is not used (the seed map and the
        running frame disagree: too early, or a bad seed).
    """

    PRESETS: ClassVar[Mapping[str, Mapping[str, Any]]] = {
        "paper": {},
        "real": {**Isam2Config.PRESETS["real"], **_REAL_SEED},
    }

    seed_method: str = "stmds-smacof"
    seed_options: Mapping[str, Any] | None = None
    seed_every: int = 1
    seed_sigma_m: float | None = None
    align_trim: float = 3.0
    align_parallax_rad: float = 0.1
    min_align_landmarks: int = 3
    max_align_rms_m: float = 0.3

    def __post_init__(self) -> None:
        super().__post_init__()
        need = requirement("HybridIsam2Config")
        need(isinstance(self.seed_method, str)
             and self.seed_method not in ("hybrid", "hybrid-isam2", "oracle"),
             f"seed_method must name a registered non-hybrid mapper, got {self.seed_method!r}")
        need(self.seed_options is None or isinstance(self.seed_options, Mapping),
             "seed_options must be a mapping of the seed mapper's options")
        check_seed("HybridIsam2Config", self.seed_method, self.seed_options)
        need(self.seed_every >= 1, "seed_every must be >= 1")
        need(self.seed_sigma_m is None or self.seed_sigma_m > 0,
             "seed_sigma_m must be > 0 or None")
        need(self.align_trim > 1, "align_trim must be > 1")
        need(0 < self.align_parallax_rad < np.pi / 2, "align_parallax_rad must be in (0, pi/2)")
        need(self.min_align_landmarks >= 3, "min_align_landmarks must be >= 3")
        need(self.max_align_rms_m > 0, "max_align_rms_m must be > 0")


class _SeededGraph(BearingGraph):
    """The bearing graph whose ``admit`` first asks ``seeder`` for landmarks to enter."""

    seeder: Callable[["_SeededGraph", Callable[[np.ndarray], np.ndarray]], None] | None = None

    def admit(self, pose_at: Callable[[np.ndarray], np.ndarray], *,
              only_fresh: bool = False) -> list[int]:
        before = set(self.landmark_ids)
        if self.seeder is not None:
            self.seeder(self, pose_at)
        seeded = [lid for lid in self.landmark_ids if lid not in before]
        return seeded + super().admit(pose_at, only_fresh=only_fresh)


class HybridIsam2Mapper(Isam2Mapper):
    """``hybrid-isam2``: iSAM2 with new landmarks seeded from BOM-STMDS (module docstring).

    Parameters
    ----------
    header : StreamHeader
    start_pose : (x_m, y_m, psi_rad)
        The map frame (first pose).
    seed_mapper : Mapper, optional
        A seed mapper instance to use instead of building ``seed_method`` (fed the same
        steps; its map may be in any frame, mirrored or not).
    config : HybridIsam2Config, optional
    preset : str, optional
        A :class:`HybridIsam2Config` preset (``"paper"``, ``"real"``).
    **options
        Fields of :class:`HybridIsam2Config` (with ``preset``, not with ``config``).
    """

    def __init__(self, header: StreamHeader, *,
                 start_pose: Sequence[float] = (0.0, 0.0, 0.0),
                 seed_mapper: Mapper | None = None,
                 config: HybridIsam2Config | None = None, preset: str | None = None,
                 **options: Any) -> None:
        cfg = resolve(HybridIsam2Config, config, preset, options)
        super().__init__(header, start_pose=start_pose, config=cfg)
        self.config: HybridIsam2Config = cfg
        check_seed_mapper("HybridIsam2Config", seed_mapper, cfg.seed_options, preset, options)
        self.seed = seed_mapper if seed_mapper is not None else create_mapper(
            cfg.seed_method, header, **dict(cfg.seed_options or {}))
        # nothing has been fed yet: the plain graph is swapped for the seeded one
        self.problem = _SeededGraph(header, cfg, start_pose)
        self.problem.seeder = self._seed_pending
        self._rays: dict[int, tuple[list[int], list[float]]] = {}
        self._seed_map: MapEstimate | None = None
        self._seed_t = -1
        self.seeded: list[int] = []
        self._seed_status = "no landmark waiting yet"

    def step(self, step: Step) -> None:
        self.seed.step(step)
        for lid, brg in zip(step.landmark_ids.tolist(), step.bearings_rad.tolist()):
            ts, bs = self._rays.setdefault(lid, ([], []))
            ts.append(step.t)
            bs.append(brg)
        super().step(step)

    # -- seeding --------------------------------------------------------------------------
    def _waiting(self, graph: BearingGraph, pose_at: Callable[[np.ndarray], np.ndarray]
                 ) -> list[int]:
        """Pending landmarks with >= 2 bearings that the parallax rule does not yet admit."""
        ids = [lid for lid, n in sorted(graph.pending().items()) if n >= 2]
        _, ok = graph.initial_points(*graph.rays_of(ids, pose_at, self._rays))
        return [lid for lid, good in zip(ids, ok.tolist()) if not good]

    def _current_seed(self, t: int) -> MapEstimate | None:
        if self._seed_map is None or t - self._seed_t >= self.config.seed_every:
            try:
                self._seed_map = self.seed.estimate()
            except BomgraphError as exc:
                self._seed_status = f"seed mapper failed: {exc}"
                self._seed_map = None
            self._seed_t = t
        return self._seed_map

    def _reference(self, graph: BearingGraph, pose_at: Callable[[np.ndarray], np.ndarray]
                   ) -> tuple[np.ndarray, np.ndarray]:
        """Landmarks in the running frame: those iSAM2 holds, and pending ones whose rays
        intersect with ``align_parallax_rad`` on the current poses."""
        in_graph = np.array([lid for lid in graph.landmark_ids
                             if self.estimate_values.exists(landmark_key(lid))], np.int64)
        xy = [landmarks_from_values(self.estimate_values, in_graph)]
        ids = [lid for lid in sorted(graph.pending()) if len(self._rays[lid][0]) >= 2]
        poses, bearings, owner, m = graph.rays_of(ids, pose_at, self._rays)
        p, ok = intersect_ray_groups(poses[:, :2], poses[:, 2] + bearings, owner, m,
                                     min_parallax_rad=self.config.align_parallax_rad)
        return (np.concatenate([in_graph, np.array(ids, np.int64)[ok]]),
                np.concatenate([*xy, p[ok]]).reshape(-1, 2))

    def _seed_pending(self, graph: BearingGraph,
                      pose_at: Callable[[np.ndarray], np.ndarray]) -> None:
        waiting = self._waiting(graph, pose_at)
        if not waiting:
            return
        seed = self._current_seed(graph.n_steps - 1)
        if seed is None:
            return
        if not np.isin(waiting, seed.landmark_ids).any():
            self._seed_status = "the seed map has none of the waiting landmarks"
            return
        ref_ids, ref_xy = self._reference(graph, pose_at)
        if np.intersect1d(seed.landmark_ids, ref_ids).size < self.config.min_align_landmarks:
            self._seed_status = "too few landmarks to align the seed map on"
            return
        aligned = align_map(seed, ref_ids, ref_xy, trim=self.config.align_trim)
        if aligned.rms_m > self.config.max_align_rms_m:
            self._seed_status = (f"seed map alignment RMS {aligned.rms_m:.3f} m > "
                                 f"max_align_rms_m")
            return
        where = aligned.as_dict()
        entered = []
        for lid in waiting:
            xy = where.get(lid)
            ts, bs = self._rays[lid]
            if xy is None:
                continue
            poses, brg = pose_at(np.asarray(ts)), np.asarray(bs)
            xy = refine_on_rays(xy, poses, brg, float(self.header.bearing_sigma_rad),
                                self.config.seed_sigma_m or self.config.max_align_rms_m)
            if not self._plausible(xy, poses, brg):
                continue
            graph.enter(lid, xy)
            entered.append(lid)
            if self.config.seed_sigma_m is not None:
                prior = gtsam.NonlinearFactorGraph()
                prior.add(gtsam.PriorFactorPoint2(
                    landmark_key(lid), gtsam.Point2(float(xy[0]), float(xy[1])),
                    gtsam.noiseModel.Isotropic.Sigma(2, float(self.config.seed_sigma_m))))
                self.add_factors(prior)
        self.seeded.extend(entered)
        self._seed_status = (f"seeded {len(entered)} of {len(waiting)} waiting (alignment on "
                             f"{aligned.n_common}, RMS {aligned.rms_m:.3f} m)")

    def _plausible(self, xy: np.ndarray, poses: np.ndarray, bearings_rad: np.ndarray) -> bool:
        """In front of every ray (within 90 degrees of it) and inside the range gate."""
        d = xy - poses[:, :2]
        c, s = np.cos(poses[:, 2] + bearings_rad), np.sin(poses[:, 2] + bearings_rad)
        if np.any(d[:, 0] * c + d[:, 1] * s <= 0):
            return False
        rng = self.header.sensor_range_m
        return rng is None or bool(np.all(np.hypot(d[:, 0], d[:, 1])
                                          <= self.config.range_gate * rng))

    def estimate(self) -> MapEstimate:
        est = super().estimate()
        info = {**est.info, "seeded_landmarks": sorted(self.seeded), "seed": self._seed_status}
        return replace(est, info=info)


def refine_on_rays(seed_xy: np.ndarray, poses: np.ndarray, bearings_rad: np.ndarray,
                   bearing_sigma_rad: float, seed_sigma_m: float,
                   iterations: int = 10) -> np.ndarray:
    """The point that best fits its rays and its seed position, shape (2,).

    Gauss-Newton on ``sum_k (angle_residual(atan2(x - p_k), psi_k + b_k) / sigma_b)^2 +
    |x - seed|^2 / sigma_s^2`` from the seed: the rays fix the direction, the seed the depth
    they leave open. ``poses`` (k, 3), ``bearings_rad`` (k,).
    """
    x = np.asarray(seed_xy, dtype=float).copy()
    seed = x.copy()
    w_b, w_s = 1.0 / bearing_sigma_rad ** 2, 1.0 / seed_sigma_m ** 2
    for _ in range(iterations):
        d = x - poses[:, :2]
        r2 = np.maximum(np.sum(d * d, axis=1), 1e-12)
        res = angle_residual(np.arctan2(d[:, 1], d[:, 0]), poses[:, 2] + bearings_rad)
        jac = np.column_stack([-d[:, 1], d[:, 0]]) / r2[:, None]
        h = w_b * jac.T @ jac + w_s * np.eye(2)
        g = w_b * jac.T @ res + w_s * (x - seed)
        step = np.linalg.solve(h, -g)
        x = x + step
        if float(np.max(np.abs(step))) < 1e-9:
            break
    return x


__all__ = ["HybridIsam2Config", "HybridIsam2Mapper", "refine_on_rays"]
