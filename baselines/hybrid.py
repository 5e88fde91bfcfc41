"""``hybrid``: the GTSAM bearing factor graph seeded with the BOM-STMDS map.

BOM-STMDS (the paper, sections III-B to III-D) builds a landmark map without localising the
robot; a factor graph needs a good start for every pose and landmark or Levenberg-Marquardt
settles in a wrong basin (starting from dead reckoning it often does). At each ``estimate()``:

1. run the seed mapper alongside (``seed_method``, BOM-STMDS Method 2 by default) and take its
   map, which lives in its own frame, possibly mirrored;
2. align it rigidly, reflection allowed (:func:`bomgraph.evaluate.align`, trimmed), into the
   odometry frame: onto the previous solution's landmarks, or at first onto landmarks
   triangulated from the dead-reckoned early trajectory;
3. initialise every pose by resection against that map
   (:func:`baselines.resection.resect_trajectory`), then move the whole start rigidly so that
   the first pose is ``start_pose`` (steps 2-3: :func:`baselines.seeding.seed_start`, public
   in :mod:`baselines.gtsam_tools`);
4. run LM on the same graph as ``gtsam-batch`` (:class:`baselines.factor_graph.BatchState`)
   from that start, and from the warm start of the previous solution; keep the lower cost.

The mapper holds a :class:`~baselines.factor_graph.BatchState` (the graph and its values) and
the seed mapper; the resected poses are handed to the graph's landmark admission explicitly.
Landmarks enter by the same rule as in the other GTSAM mappers (so the graphs and their costs
compare); their start is the aligned seed position, else the ray intersection on the resected
poses. Measured effects: ``docs/measurements.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Mapping, Sequence

import gtsam
import numpy as np

from bomgraph.config import requirement, resolve
from bomgraph.errors import BomgraphError, ConfigError, TooFewLandmarksError
from bomgraph.mapper import MapEstimate, Mapper, check_seed, create_mapper
from bomgraph.method_limits import check_mapper_option
from bomgraph.stream import Step, StreamHeader

from .bearing_graph import FactorGraphConfig, landmark_key
from .factor_graph import BatchState, ScheduledSolver, SolveReport
from .seeding import (SeedAlignment, SeedStart, align_seed, seed_start,  # noqa: F401
                      triangulate_arrays, trimmed_align)               # (re-exported)

_ROBUST = FactorGraphConfig.PRESETS["robust"]
_REAL_SEED = {"seed_options": {"preset": "real"}}


@dataclass(frozen=True)
class HybridConfig(FactorGraphConfig):
    """Options of the hybrid: the graph and LM fields of :class:`FactorGraphConfig` plus the
    seeding.

    Presets (:meth:`Presets.preset`): ``"paper"`` (the defaults), ``"robust"`` (the factor
    graph's Cauchy kernels), ``"real-seed"`` (the seed mapper's ``"real"`` preset) and
    ``"real-seed-robust"`` (both), and ``"real"``, the recording setting (issue 15: one per
    method), which is ``"real-seed-robust"``.

    Attributes
    ----------
    huber_k : None
        Always None: with two starts to choose from the hybrid runs no Huber pass.
    seed_method : str
        Registered mapper whose map seeds the graph.
    seed_options : mapping, optional
        Options of the seed mapper (e.g. ``{"preset": "real"}``).
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
        Std. dev. of the odometry prediction used as the resection prior (world x, y, psi),
        added to the step's odometry covariance turned into the world by the heading of the
        pose before (:func:`~baselines.resection.resect_trajectory`).
    n_headings : int
        Grid over the heading in the resection.
    resection_huber_k : float
        Huber threshold (whitened) of the resection's bearing residuals.
    warm_start : bool
        Also run LM from the previous solution and keep the lower cost.
    start_tol_m : float
        Once there is a solution, the warm start is solved first, and the seed start only if
        that solution looks off (:meth:`~baselines.factor_graph.BatchState.looks_off`) or a
        seed landmark lies more than this (metres) from it. On the paper's runs the seed map's
        worst landmark is 0.2-1.1 m from the warm solution and both starts reach the same
        minimum; where the seed won (by 6,389 cost units) the gap was 100 km and the warm
        solution had a landmark out of reach (``docs/measurements.md``).
    """

    PRESETS: ClassVar[Mapping[str, Mapping[str, Any]]] = {
        "paper": {},
        "robust": dict(_ROBUST),
        "real-seed": dict(_REAL_SEED),
        "real-seed-robust": {**_REAL_SEED, **_ROBUST},
        "real": {**_REAL_SEED, **_ROBUST},
    }

    huber_k: float | None = None
    seed_method: str = "stmds-smacof"
    seed_options: Mapping[str, Any] | None = None
    align_steps: int = 50
    align_trim: float = 3.0
    map_sigma_m: float = 0.03
    prior_sigma: tuple[float, float, float] = (0.02, 0.02, math.radians(2.0))
    n_headings: int = 36
    resection_huber_k: float = 2.0
    warm_start: bool = True
    start_tol_m: float = 1.5

    def __post_init__(self) -> None:
        super().__post_init__()

        need = requirement("HybridConfig")

        need(self.huber_k is None, "the hybrid runs no Huber pass; huber_k must be None")
        need(isinstance(self.seed_method, str)
             and self.seed_method not in ("hybrid", "hybrid-isam2", "oracle"),
             f"seed_method must name a registered non-hybrid mapper, got {self.seed_method!r}")
        need(self.seed_options is None or isinstance(self.seed_options, Mapping),
             "seed_options must be a mapping of the seed mapper's options")
        check_seed("HybridConfig", self.seed_method, self.seed_options)
        need(self.align_steps >= 2, "align_steps must be >= 2")
        need(self.align_trim > 1, "align_trim must be > 1")
        need(self.map_sigma_m >= 0, "map_sigma_m must be >= 0")
        need(len(self.prior_sigma) == 3 and all(s > 0 for s in self.prior_sigma),
             "prior_sigma must be 3 numbers > 0")
        need(self.n_headings >= 4, "n_headings must be >= 4")
        need(self.resection_huber_k > 0, "resection_huber_k must be > 0")
        need(self.start_tol_m >= 0, "start_tol_m must be >= 0")


def check_seed_mapper(owner: str, seed_mapper: Mapper | None,
                      seed_options: Mapping[str, Any] | None, preset: str | None,
                      options: Mapping[str, Any]) -> None:
    """Refuse ``seed_options`` beside a ``seed_mapper`` instance (they configure the
    ``seed_method`` the hybrid would build), saying where they came from: the options, the
    ``preset`` (``real`` sets them; ``seed_options=None`` drops them) or a ``config=``.

    Raises
    ------
    ConfigError
        ``seed_mapper`` given and ``seed_options`` set, or a ``seed_mapper`` that is not a
        mapper (:func:`~bomgraph.method_limits.check_mapper_option`).
    """
    check_mapper_option("seed_mapper", seed_mapper)
    if seed_mapper is None or not seed_options:
        return
    if "seed_options" in options:
        fix = "pass them to seed_mapper's constructor instead"
    elif preset is not None:
        fix = (f"preset {preset!r} sets them: give seed_options=None beside seed_mapper (and "
               f"pass any options to seed_mapper's constructor)")
    else:
        fix = "give a config= with seed_options=None (pass them to seed_mapper's constructor)"
    raise ConfigError(f"{owner}: seed_options={dict(seed_options)} apply to seed_method, not to "
                      f"a seed_mapper; {fix}")


# --------------------------------------------------------------------------------------------
# The mapper
# --------------------------------------------------------------------------------------------

class HybridMapper(ScheduledSolver):
    """``hybrid``: LM on the bearing factor graph, started from the BOM-STMDS map, every
    ``solve_every`` steps (:class:`~baselines.factor_graph.ScheduledSolver`).

    Parameters
    ----------
    header : StreamHeader
    start_pose : (x_m, y_m, psi_rad)
        The map frame (first pose).
    seed_mapper : Mapper, optional
        A seed mapper instance to use instead of building ``seed_method`` (fed the same
        steps; its map may be in any frame, mirrored or not).
    config : HybridConfig, optional
    preset : str, optional
        A :class:`HybridConfig` preset.
    **options
        Fields of :class:`HybridConfig` (with ``preset``, not with ``config``).
    """

    def __init__(self, header: StreamHeader, *,
                 start_pose: Sequence[float] = (0.0, 0.0, 0.0),
                 seed_mapper: Mapper | None = None,
                 config: HybridConfig | None = None, preset: str | None = None,
                 **options: Any) -> None:
        self.config = resolve(HybridConfig, config, preset, options)
        self.header = header
        self.state = BatchState(header, self.config, start_pose)
        check_seed_mapper("HybridConfig", seed_mapper, self.config.seed_options, preset,
                          options)
        self.seed = seed_mapper if seed_mapper is not None else create_mapper(
            self.config.seed_method, header, **dict(self.config.seed_options or {}))
        self._have_solution = False

    def _feed(self, step: Step) -> None:
        self.state.add_step(step)
        self.seed.step(step)

    # -- seeding --------------------------------------------------------------------------
    def _seed_map(self) -> tuple[SeedAlignment | None, dict[str, Any]]:
        """The seed map aligned into the odometry frame (:func:`~baselines.seeding.align_seed`:
        on the previous solution's landmarks if there is one), or None (and why)."""
        try:
            seed = self.seed.estimate()
        except BomgraphError as exc:
            return None, {"seed": f"seed mapper failed: {exc}"}
        if len(seed) < 3:
            return None, {"seed": f"seed map has {len(seed)} landmarks (< 3)"}
        try:
            aligned = align_seed(self.state, seed, use_solution=self._have_solution,
                                 align_steps=self.config.align_steps,
                                 trim=self.config.align_trim)
        except TooFewLandmarksError:
            return None, {"seed": "fewer than 3 landmarks to align the seed map on"}
        return aligned, {"seed": "ok", "seed_reflected": aligned.alignment.reflected,
                         "seed_landmarks": len(seed)}

    def _seed_start(self, aligned: SeedAlignment) -> SeedStart | None:
        """Every pose resected against the aligned seed map, the whole start moved rigidly so
        that the first pose is ``start_pose`` (:func:`~baselines.seeding.seed_start`); None if
        no pose sees 3 seed landmarks."""
        cfg = self.config
        try:
            return seed_start(self.state, aligned, n_headings=cfg.n_headings,
                              huber_k=cfg.resection_huber_k, map_sigma_m=cfg.map_sigma_m,
                              prior_sigma=cfg.prior_sigma)
        except TooFewLandmarksError:
            return None

    def _with_landmarks(self, values: gtsam.Values, where: dict[int, np.ndarray]
                        ) -> gtsam.Values:
        """``values`` completed with every graph landmark it lacks: at ``where[id]`` if
        given, else at the current values."""
        state = self.state
        for lid in state.problem.landmark_ids:
            key = landmark_key(lid)
            if not values.exists(key):
                xy = where.get(lid)
                if xy is None:
                    xy = state.values.atPoint2(key)
                values.insert(key, gtsam.Point2(float(xy[0]), float(xy[1])))
        return values

    def _enter_at_seed(self, seed_map: dict[int, np.ndarray]) -> None:
        """The seed map places the landmarks the rays alone do not yet determine (too little
        parallax): pending ones with 2 rays or more enter at their seed position."""
        problem = self.state.problem
        for lid, n_rays in problem.pending().items():
            if n_rays >= 2 and lid in seed_map:
                problem.enter(lid, seed_map[lid])

    # -- estimate -------------------------------------------------------------------------
    def _update(self) -> MapEstimate:
        """Seed map, starts, LM from each start solved, the lower cost kept (module
        docstring). Once there is a solution the warm start is solved first and the seed
        start (resection of every pose) only when it could lead elsewhere
        (``start_tol_m``)."""
        state = self.state
        found, info = self._seed_map()
        seed: SeedStart | None = None
        seed_map: dict[int, np.ndarray] = {}
        warm = gtsam.Values(state.values)
        solved: list[tuple[str, gtsam.Values, SolveReport]] = []
        # the graph each start's solve solved (BatchState.solved_graph: past lag_after_steps
        # a whole-graph solve leaves out the near bearings, a window solve does not): the
        # kept solution's covariances are that graph's
        graph_of: dict[str, gtsam.NonlinearFactorGraph] = {}
        starts: list[str] = []
        incremental = found is not None and self.config.warm_start and self._have_solution
        if found is not None and not incremental:
            seed = self._seed_start(found)
            if seed is None:
                info = {"seed": "no pose sees 3 landmarks of the seed map"}
        if seed is not None:
            seed_map = seed.landmarks
            self._enter_at_seed(seed_map)
            resected = seed.poses
            state.absorb(lambda ts: resected[np.asarray(ts, dtype=np.int64)])
        else:
            if incremental:
                assert found is not None
                seed_map = dict(zip(found.landmark_ids.tolist(), found.landmarks_xy))
                self._enter_at_seed(seed_map)
            state.absorb()
        if seed is None or (self.config.warm_start and self._have_solution):
            # previous solution + odometry predictions + new landmarks' intersections
            starts.append("warm")
            solved.append(("warm", *state.solve(self._with_landmarks(warm, {}),
                                                warm=self._have_solution)))
            graph_of["warm"] = state.solved_graph
        if incremental:
            assert found is not None
            # the seed start only where it could lead elsewhere than the warm solution
            gap = self._start_gap_m(seed_map, solved[0][1])
            info["start_gap_m"] = gap
            if gap > self.config.start_tol_m or state.looks_off(solved[0][1]):
                seed = self._seed_start(found)
        if seed is not None:
            starts.append("seed")
            # the two starts must solve the same problem for their costs to compare: a warm
            # whole-graph solve sets the graph's last whole size to now, after which the
            # schedule would send the seed start to a window, whose cost (the window's
            # factors and its marginal) is not the whole graph's and is always the lower
            whole = bool(solved) and solved[0][2].passes[:1] != ("window",)
            previous, state.whole_only = state.whole_only, state.whole_only or whole
            try:
                solved.append(("seed", *state.solve(self._with_landmarks(seed.values(),
                                                                         seed.landmarks))))
            finally:
                state.whole_only = previous
            graph_of["seed"] = state.solved_graph
        # a start whose solution puts landmarks out of the sensor's reach of every pose (a
        # weakly seen landmark slid far along its rays: a converged but wrong minimum) loses
        # to one that does not, whatever the costs
        far_of = {name: state.out_of_reach(values) for name, values, _ in solved}
        name, values, report = min(solved, key=lambda s: (far_of[s[0]].size > 0,
                                                           s[2].final_error))
        state.set_values(values)
        state.solved_graph = graph_of[name]
        self._have_solution = True
        info.update(report.as_info())
        info["start"] = name
        info["starts"] = starts
        info["start_costs"] = {s[0]: s[2].final_error for s in solved}
        far = far_of[name]
        # still there in the best solution: not determined yet (too little parallax); left
        # out of the map, and moved back to their seed position (if any) for the next warm
        # start
        est = state.to_estimate(values, info, far)
        for lid in far.tolist():
            if lid in seed_map:
                xy = seed_map[lid]
                state.values.update(landmark_key(lid), gtsam.Point2(float(xy[0]), float(xy[1])))
        return est

    def _start_gap_m(self, seed_map: dict[int, np.ndarray], values: gtsam.Values) -> float:
        """Largest gap (metres) between a seed landmark and the same landmark in ``values``."""
        ids, xy = self.state.landmark_arrays(values)
        have = np.array([int(i) in seed_map for i in ids], dtype=bool)
        if not have.any():
            return 0.0
        seed_xy = np.array([seed_map[int(i)] for i in ids[have]])
        return float(np.max(np.hypot(*(seed_xy - xy[have]).T)))


__all__ = ["HybridConfig", "HybridMapper", "SeedStart", "check_seed", "trimmed_align",
           "triangulate_arrays"]
