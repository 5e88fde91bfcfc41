"""The bearing-only SLAM problem as a GTSAM factor graph, grown one step at a time.

The paper (section IV, Exp. 2) compares BOM-STMDS with a filtering BOSLAM method; the GTSAM
baselines (:mod:`baselines.factor_graph`, :mod:`baselines.hybrid`) solve the same problem as a
factor graph, the maximum-likelihood estimate over all poses and landmarks given every
measurement. This module builds that graph; the solvers and mappers live in
:mod:`baselines.factor_graph`. The graph holds

* ``Pose2`` robot poses ``x_t`` (one per step), ``Point2`` landmarks ``l_i``;
* a prior on ``x_0`` that fixes the map frame (``start_pose``, the origin by default);
* two odometry factors per step (*Odometry noise* below);
* one ``BearingFactor2D`` per bearing, std. dev. ``header.bearing_sigma_rad``;
* one ``RangeFactor2`` (point-to-point distance) per known prior distance
  (``header.priors``, the paper's Exp. 3).

**Odometry noise.** The stream's increment ``u = [dx, dy, dpsi]`` carries independent noise on
its three components (``Step.odometry_sigma``; the simulator's move-then-turn model has
``sigma_dy = 0``). ``BetweenFactorPose2`` measures its error as ``Logmap(U^-1 (x_{t-1}^-1
x_t))``, in the frame *after* the turn, where the translation noise is rotated by ``dpsi`` and
mixed with the heading noise through the ``SE(2)`` log map, so one between factor with a
diagonal ``(sdx, sdy, sdpsi)`` is the wrong model. The graph uses the exact one: each step
passes through an intermediate pose ``m_t`` (after the move, before the turn) with two between
factors, ``x_{t-1} -> m_t`` measuring ``Pose2(dx, dy, 0)`` with sigmas ``(sdx, sdy, floor)``
and ``m_t -> x_t`` measuring ``Pose2(0, 0, dpsi)`` with sigmas ``(floor, floor, sdpsi)``. At
the truth both errors are exactly minus the component noise (the log map of a pure translation
or a pure rotation is exact), so chi^2 at the truth follows its nominal law. Zero sigmas are
clamped to ``sigma_floor_m`` / ``sigma_floor_rad``.

**Landmarks** enter the graph only once at least two of their bearings intersect with enough
parallax (:func:`bomgraph.geometry.intersect_rays` on the current pose estimates, inside the
sensor range if the header gives one); until then their bearings are buffered, and all of them
become factors when the landmark enters. A landmark seen once never enters (one bearing leaves
it indeterminate and breaks iSAM2).

Measured effects of the settings: ``docs/measurements.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, ClassVar, Mapping, Sequence

import gtsam
import numpy as np

from bomgraph.config import Presets, requirement
from bomgraph.errors import ConfigError, StreamFormatError
from bomgraph.geometry import compose, intersect_ray_groups
from bomgraph.method_limits import MAX_SIGMA, Reach, checked_header
from bomgraph.stream import Prior, Step, StreamHeader

from .bearing_log import BearingLog
from .graph_values import landmark_key, mid_key, points_at, pose_key, poses_at

# --------------------------------------------------------------------------------------------
# Configuration
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class FactorGraphConfig(Presets):
    """Options of the factor-graph baselines (graph, Levenberg-Marquardt, iSAM2).

    Presets (:meth:`Presets.preset`): ``"paper"`` (the defaults; Gaussian factors),
    ``"robust"`` (Cauchy kernels with threshold 3 on the odometry and the bearings) and
    ``"real"``, the recording setting (issue 15: one per method), the same kernels: the
    setting chosen on MRCLAM6 and reported unchanged on other streams by
    ``scripts/bench_generality.py``.

    Attributes
    ----------
    sigma_floor_m, sigma_floor_rad : float
        Lower bound of every odometry sigma and the sigma of the rigid directions of the split
        factors (the simulator's ``sigma_dy = 0``); also the sigma of the prior on the first
        pose. The rigid residuals are exactly 0 at the truth whatever the floor, so it only
        trades stiffness for conditioning.
    min_parallax_rad : float
        A landmark enters once its rays span at least this angle (with too little, iSAM2's
        Gauss-Newton steps send poorly initialised landmarks to infinity).
    range_gate : float
        With a known ``header.sensor_range_m``, the initial point must lie within
        ``range_gate * sensor_range_m`` of every pose that saw it.
    huber_k : float or None
        Huber threshold (whitened units) of a robust pass on the bearing factors before the
        plain pass of ``gtsam-batch``; None skips it.
    odometry_cauchy_k : float or None
        Cauchy kernel (whitened threshold) on every odometry factor, in every pass; None keeps
        them Gaussian (the simulator's odometry is). Recordings have odometry outliers (a
        collision, a slip) the Gaussian model cannot absorb.
    bearing_cauchy_k : float or None
        Cauchy kernel on the bearing factors of the plain pass (the Huber pre-pass keeps its
        own kernel); None keeps them Gaussian. With robust odometry a gross bearing outlier
        can otherwise bend the trajectory it no longer pays for.
    max_iterations, relative_error_tol, absolute_error_tol, lambda_upper_bound,
    diagonal_damping :
        Levenberg-Marquardt settings. The upper bound on lambda must be large: the rigid
        directions have information ``1 / sigma_floor^2`` and GTSAM's LM stops silently,
        returning its input, once lambda exceeds the bound.
    decrease_tol : float
        A solution counts as converged when a Gauss-Newton step at it predicts less than this
        decrease of the error (GTSAM's error, chi^2 / 2), or when LM stopped on its
        tolerances (:class:`baselines.factor_graph.SolveReport`). It is the definition of
        convergence (a large value calls more solutions converged; the report gives the
        predicted decrease beside ``converged``), so it must be finite.
    covariances : bool
        Fill ``landmark_cov`` and ``pose_cov`` through ``gtsam.Marginals`` (costs time; an
        SVD of the whole graph where it fails, all-NaN blocks where a marginal is not
        defined: :func:`baselines.lm_report.marginal_covariances`).
    warm_relative_error_tol : float
        ``relative_error_tol`` of the scheduled solves of ``gtsam-batch``, ``oracle`` and
        ``hybrid`` (warm starts a few steps apart; 1e-8 cost 3x the iterations for the same
        minimum, ``docs/measurements.md``); ``relative_error_tol`` serves the other solves.
    solve_every : int
        The LM mappers (``gtsam-batch``, ``oracle``, ``hybrid``) admit landmarks and solve on
        this internal schedule (every ``solve_every`` steps), whatever the caller's
        ``estimate()`` cadence; an ``estimate()`` between two scheduled solves catches up.
    robust_trigger : float
        A Huber pass (``huber_k``) and a Gauss-Newton check run only when the plain solution
        leaves a whitened bearing residual above this (or a landmark out of reach).
    near_range_m : float or None
        Past ``lag_after_steps`` steps, a whole-graph LM solve (``gtsam-batch``, ``oracle``,
        ``hybrid``) and its plausibility checks leave out the bearings whose landmark lies
        within this many metres of the pose that took them (after a loop closure such a
        bearing flips by pi under LM's steps and stalls it, :mod:`baselines.near_range`).
        None: the stream's odometry translation sigma, ``hypot(sigma_dx, sigma_dy)`` of its
        header; 0: keep every bearing.
    lag_after_steps, lag_steps, full_growth, long_ordering :
        Long recordings (``gtsam-batch``, ``oracle``, ``hybrid``): past ``lag_after_steps``
        steps a scheduled solve relinearises only the last ``lag_steps`` poses and the
        landmarks they see (fixed-lag: the older poses held, their bearings folded into one
        Gaussian prior per landmark), and the whole graph is solved again each time it has
        grown by the factor ``full_growth`` (:class:`baselines.factor_graph.BatchState`,
        :mod:`baselines.lm_window`); those whole-graph solves eliminate in the ordering
        ``long_ordering`` (``"metis"`` or ``"colamd"``, :data:`baselines.lm_report.ORDERINGS`;
        every other solve in COLAMD's).
    lag_marginal_landmarks : int
        The older poses of a window are eliminated into a marginal on the boundary pose and
        the landmarks while the graph has at most this many landmarks (the window solve is
        then the whole-graph solution to first order); beyond, and with 0, the old bearings
        are conditioned on the held poses instead (:mod:`baselines.lm_window`).
    warm_presolve_sigma_m : float or None
        Before a warm-started whole-graph solve (``gtsam-batch``, the hybrid's warm start),
        the poses added since the last solution are solved alone, the landmarks held near
        their points by an isotropic prior of this std. dev. (m); the whole-graph LM then
        starts near its minimum. None: no pre-solve.
    presolved_relative_error_tol : float
        ``relative_error_tol`` of a whole-graph solve after the warm pre-solve: LM starts so
        near its minimum that ``warm_relative_error_tol`` stops it short
        (``docs/measurements.md``).
    relinearize_threshold, relinearize_skip, checkpoint_updates :
        iSAM2 (:class:`baselines.isam2.Isam2Config`): relinearise a variable whose delta
        exceeds the threshold, check every ``relinearize_skip`` updates, and run this many
        extra updates after each internal update. GTSAM's default threshold 0.1 is far above
        the 1 cm accuracy.
    """

    PRESETS: ClassVar[Mapping[str, Mapping[str, Any]]] = {
        "paper": {},
        "robust": {"odometry_cauchy_k": 3.0, "bearing_cauchy_k": 3.0},
        "real": {"odometry_cauchy_k": 3.0, "bearing_cauchy_k": 3.0},
    }

    sigma_floor_m: float = 1e-3
    sigma_floor_rad: float = 1e-3
    min_parallax_rad: float = 0.3
    range_gate: float = 1.5
    huber_k: float | None = 1.345
    odometry_cauchy_k: float | None = None
    bearing_cauchy_k: float | None = None
    max_iterations: int = 100
    relative_error_tol: float = 1e-8
    absolute_error_tol: float = 1e-12
    lambda_upper_bound: float = 1e16
    diagonal_damping: bool = True
    decrease_tol: float = 1.0
    covariances: bool = False
    warm_relative_error_tol: float = 1e-5
    solve_every: int = 10
    lag_after_steps: int = 500
    lag_steps: int = 100
    full_growth: float = 1.25
    long_ordering: str = "metis"
    lag_marginal_landmarks: int = 200
    warm_presolve_sigma_m: float | None = 3e-3
    presolved_relative_error_tol: float = 1e-6
    robust_trigger: float = 5.0
    near_range_m: float | None = None
    relinearize_threshold: float = 0.001
    relinearize_skip: int = 1
    checkpoint_updates: int = 2

    def __post_init__(self) -> None:
        need = requirement(type(self).__name__)

        need(0 < self.sigma_floor_m <= MAX_SIGMA and 0 < self.sigma_floor_rad <= MAX_SIGMA,
             f"sigma floors must be in (0, {MAX_SIGMA:g}] (above, no odometry factor carries "
             f"information, and the graph's scale is free)")
        need(0 < self.min_parallax_rad < math.pi / 2, "min_parallax_rad must be in (0, pi/2)")
        need(self.range_gate >= 1.0, "range_gate must be >= 1")
        need(self.huber_k is None or self.huber_k > 0, "huber_k must be > 0 or None")
        need(self.odometry_cauchy_k is None or self.odometry_cauchy_k > 0,
             "odometry_cauchy_k must be > 0 or None")
        need(self.bearing_cauchy_k is None or self.bearing_cauchy_k > 0,
             "bearing_cauchy_k must be > 0 or None")
        need(self.max_iterations >= 1, "max_iterations must be >= 1")
        need(self.relative_error_tol >= 0 and self.absolute_error_tol >= 0,
             "error tolerances must be >= 0")
        need(self.lambda_upper_bound > 0, "lambda_upper_bound must be > 0")
        need(0 < self.decrease_tol < math.inf, "decrease_tol must be finite and > 0 (it is "
             "the convergence test: infinity would call any solution converged)")
        need(self.warm_relative_error_tol >= 0, "warm_relative_error_tol must be >= 0")
        need(self.solve_every >= 1, "solve_every must be >= 1")
        need(self.lag_steps >= 2 and self.lag_after_steps >= self.lag_steps,
             "lag_steps must be >= 2 and lag_after_steps >= lag_steps")
        need(self.full_growth > 1, "full_growth must be > 1")
        need(self.long_ordering in ("metis", "colamd"), "long_ordering must be 'metis' or 'colamd'")
        need(self.lag_marginal_landmarks >= 0, "lag_marginal_landmarks must be >= 0")
        need(self.warm_presolve_sigma_m is None or self.warm_presolve_sigma_m > 0,
             "warm_presolve_sigma_m must be > 0 or None")
        need(self.presolved_relative_error_tol >= 0, "presolved_relative_error_tol must be >= 0")
        need(self.robust_trigger > 0, "robust_trigger must be > 0")
        need(self.near_range_m is None or self.near_range_m >= 0,
             "near_range_m must be >= 0 or None")
        need(self.relinearize_threshold > 0, "relinearize_threshold must be > 0")
        need(self.relinearize_skip >= 1, "relinearize_skip must be >= 1")
        need(self.checkpoint_updates >= 0, "checkpoint_updates must be >= 0")


# --------------------------------------------------------------------------------------------
# Factors
# --------------------------------------------------------------------------------------------

def odometry_factors(t: int, odom: np.ndarray, sigma: np.ndarray,
                     config: FactorGraphConfig) -> list[gtsam.NonlinearFactor]:
    """The two split odometry factors of step ``t`` (module docstring): ``x_{t-1} -> m_t``
    and ``m_t -> x_t``.

    Parameters
    ----------
    t : int
        Step index, >= 1.
    odom : array of shape (3,)
        ``[dx_m, dy_m, dpsi_rad]`` in the frame of pose ``t-1``.
    sigma : array of shape (3,)
        Std. dev. of the three components (zeros are clamped to the floors).
    config : FactorGraphConfig
        The floors and ``odometry_cauchy_k``.
    """
    fm, fr = config.sigma_floor_m, config.sigma_floor_rad
    s = np.maximum(np.asarray(sigma, dtype=float), [fm, fm, fr])
    dx, dy, dpsi = (float(v) for v in odom)
    a, b, m = pose_key(t - 1), pose_key(t), mid_key(t)

    def robust(model: gtsam.noiseModel.Base) -> gtsam.noiseModel.Base:
        if config.odometry_cauchy_k is None:
            return model
        return gtsam.noiseModel.Robust.Create(
            gtsam.noiseModel.mEstimator.Cauchy.Create(config.odometry_cauchy_k), model)

    return [gtsam.BetweenFactorPose2(a, m, gtsam.Pose2(dx, dy, 0.0),
                                     robust(gtsam.noiseModel.Diagonal.Sigmas([s[0], s[1], fr]))),
            gtsam.BetweenFactorPose2(m, b, gtsam.Pose2(0.0, 0.0, dpsi),
                                     robust(gtsam.noiseModel.Diagonal.Sigmas([fm, fm, s[2]])))]


def bearing_noise(header: StreamHeader, huber_k: float | None = None, *,
                  cauchy_k: float | None = None) -> gtsam.noiseModel.Base:
    """The bearing noise model: isotropic with the header's sigma, optionally under a Huber
    (``huber_k``) or a Cauchy (``cauchy_k``) kernel (whitened thresholds)."""
    base = gtsam.noiseModel.Isotropic.Sigma(1, float(header.bearing_sigma_rad))
    if huber_k is not None and cauchy_k is not None:
        raise ConfigError("bearing_noise: give huber_k or cauchy_k, not both")
    if huber_k is not None:
        return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(huber_k),
                                              base)
    if cauchy_k is not None:
        return gtsam.noiseModel.Robust.Create(
            gtsam.noiseModel.mEstimator.Cauchy.Create(cauchy_k), base)
    return base


def prior_factor(prior: Prior) -> gtsam.NonlinearFactor:
    """A known distance between two landmarks as a point-to-point ``RangeFactor2``."""
    return gtsam.RangeFactor2(landmark_key(prior.i), landmark_key(prior.j),
                              float(prior.distance_m),
                              gtsam.noiseModel.Isotropic.Sigma(1, float(prior.sigma_m)))


def poses_from_values(values: gtsam.Values, ts: Sequence[int] | np.ndarray) -> np.ndarray:
    """Robot poses ``x_t`` read from ``values``, shape ``(len(ts), 3)`` (in bulk:
    :func:`baselines.graph_values.poses_at`)."""
    return poses_at(values, ts)


def landmarks_from_values(values: gtsam.Values, ids: Sequence[int] | np.ndarray) -> np.ndarray:
    """Landmark positions read from ``values``, shape ``(len(ids), 2)`` (in bulk:
    :func:`baselines.graph_values.points_at`)."""
    return points_at(values, ids)


def insert_pose(values: gtsam.Values, t: int, pose: np.ndarray,
                previous_pose: np.ndarray | None) -> None:
    """Insert (or overwrite) ``x_t = pose`` and, for ``t > 0``, the intermediate pose ``m_t``
    at the position of ``x_t`` with the heading of ``x_{t-1}`` (``previous_pose``), which
    satisfies both rigid directions of the split factors."""
    _put(values, pose_key(t), gtsam.Pose2(*(float(v) for v in pose)))
    if t > 0:
        if previous_pose is None:
            raise ConfigError(f"insert_pose: step {t} needs the previous pose")
        _put(values, mid_key(t), gtsam.Pose2(float(pose[0]), float(pose[1]),
                                             float(previous_pose[2])))


def _put(values: gtsam.Values, key: int, value: Any) -> None:
    if values.exists(key):
        values.update(key, value)
    else:
        values.insert(key, value)


# --------------------------------------------------------------------------------------------
# The growing problem
# --------------------------------------------------------------------------------------------

@dataclass
class NewFactors:
    """What :meth:`BearingGraph.take_new` hands over since its last call.

    ``core`` holds the odometry factors and the bearings of landmarks already in the graph;
    ``landmark`` the factors of landmarks that entered now (all their buffered bearings and
    the priors they complete), whose initial points are in ``landmark_values``. ``robust``
    mirrors ``core + landmark`` with Huber bearing factors (None without a Huber pass).
    ``bearing_rows`` (k, 5) places each bearing factor: ``(t, landmark id, 1 if in core else
    0, index there, index in robust or -1)`` (:class:`baselines.near_range.BearingFactors`).
    """

    core: gtsam.NonlinearFactorGraph
    landmark: gtsam.NonlinearFactorGraph
    robust: gtsam.NonlinearFactorGraph | None
    landmark_ids: list[int]
    landmark_values: gtsam.Values
    bearing_rows: np.ndarray


class BearingGraph:
    """The factors of a bearing-only SLAM problem, grown one step at a time.

    Holds the measurements, decides when a landmark enters (module docstring) and emits the
    new factors in batches (:meth:`take_new`); the caller owns the values and the solver.

    Parameters
    ----------
    header : StreamHeader
    config : FactorGraphConfig
    start_pose : array of shape (3,)
        The pose ``x_0`` is tied to (the map frame).
    """

    def __init__(self, header: StreamHeader, config: FactorGraphConfig,
                 start_pose: np.ndarray) -> None:
        self.header = header
        self.config = config
        checked_header(header, "GTSAM")   # refusals name the stream's file and line
        self._reach = Reach(start_pose, "GTSAM")
        self.start_pose = self._reach.start_pose
        self._noise = bearing_noise(header, cauchy_k=config.bearing_cauchy_k)
        self._robust_noise = (bearing_noise(header, config.huber_k)
                              if config.huber_k is not None else None)
        self.n_steps = 0
        self.odoms: list[np.ndarray | None] = []
        self.landmark_ids: list[int] = []           # in the graph, in order of entry
        self._in_graph: set[int] = set()
        self._rays: dict[int, tuple[list[int], list[float]]] = {}   # pending: (ts, bearings)
        self._fresh: set[int] = set()               # pending with a bearing since last try
        self._waiting_priors: list[Prior] = list(header.priors)
        self.n_prior_factors = 0
        self.n_bearing_factors = 0
        self._core = gtsam.NonlinearFactorGraph()
        self._landmark = gtsam.NonlinearFactorGraph()
        self._robust = gtsam.NonlinearFactorGraph() if self._robust_noise else None
        self._new_ids: list[int] = []
        self._new_values = gtsam.Values()
        self._rows: list[tuple[int, int, int, int, int]] = []     # NewFactors.bearing_rows
        self._entered: dict[int, tuple[list[int], list[float]]] = {}
        self._last_batch: dict[int, tuple[list[int], list[float]]] = {}
        self._log = BearingLog()                    # every bearing, for bearings()

    # -- measurements ---------------------------------------------------------------------
    def add_step(self, step: Step) -> None:
        """Record one step: odometry factors, bearings to landmarks in the graph as factors,
        the other bearings buffered."""
        if step.t != self.n_steps:
            raise StreamFormatError(f"step t = {step.t} arrived, expected t = {self.n_steps}; "
                                    f"feed the steps in order 0, 1, 2, ...", key="t")
        if step.t == 0:
            pose0 = gtsam.Pose2(*(float(v) for v in self.start_pose))
            fm, fr = self.config.sigma_floor_m, self.config.sigma_floor_rad
            self._add(gtsam.PriorFactorPose2(pose_key(0), pose0,
                                             gtsam.noiseModel.Diagonal.Sigmas([fm, fm, fr])))
            self.odoms.append(None)
        else:
            if step.odom is None or np.shape(step.odom) != (3,):
                raise StreamFormatError(f"step {step.t}: odometry [dx, dy, dpsi] is required "
                                        f"after t = 0", key="odom")
            self._reach.advance(step)
            for f in odometry_factors(step.t, step.odom, step.odometry_sigma(self.header),
                                      self.config):
                self._add(f)
            self.odoms.append(np.array(step.odom, dtype=float))
        t = step.t
        for lid, brg in zip(step.landmark_ids.tolist(), step.bearings_rad.tolist()):
            if lid in self._in_graph:
                self._add_bearing(t, lid, brg, self._core)
            else:
                ts, bs = self._rays.setdefault(lid, ([], []))
                ts.append(t)
                bs.append(brg)
                self._fresh.add(lid)
        self._log.add(step)
        self.n_steps += 1

    def predict_pose(self, t: int, previous_pose: np.ndarray) -> np.ndarray:
        """``x_t`` predicted from ``x_{t-1}`` and the odometry of step ``t``, shape (3,)."""
        if t == 0:
            return self.start_pose.copy()
        return compose(previous_pose, self.odoms[t])

    def bearings(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every bearing so far, of landmarks in the graph and pending ones, in step order:
        owner step (int64), landmark id (int64), bearing (rad, float64), each ``(J,)``."""
        return self._log.arrays()

    # -- landmarks ------------------------------------------------------------------------
    def pending(self) -> dict[int, int]:
        """Landmarks not in the graph and how many bearings each has buffered."""
        return {lid: len(ts) for lid, (ts, _) in self._rays.items()}

    def admit(self, pose_at: Callable[[np.ndarray], np.ndarray], *,
              only_fresh: bool = False) -> list[int]:
        """Let in every pending landmark whose rays now intersect well (:meth:`initial_points`
        on ``pose_at(ts)``, the current estimates of poses ``ts``, shape (k, 3)); with
        ``only_fresh`` only those that got a bearing since the last call (incremental use).
        Returns the ids that entered now; their factors and points wait in :meth:`take_new`."""
        cand = self._fresh if only_fresh else set(self._rays)
        cand = sorted(lid for lid in cand if len(self._rays[lid][0]) >= 2)
        self._fresh = set()
        xy, ok = self.initial_points(*self.rays_of(cand, pose_at))
        entered = [lid for lid, good in zip(cand, ok.tolist()) if good]
        for lid, point in zip(entered, xy[ok]):
            self.enter(lid, point)
        return entered

    def rays_of(self, ids: Sequence[int], pose_at: Callable[[np.ndarray], np.ndarray],
                source: Mapping[int, tuple[list[int], list[float]]] | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """The rays of landmarks ``ids`` (buffered here, or in ``source``) on the poses
        ``pose_at(ts)``, one call: ``(poses (R, 3), bearings_rad (R,), owner (R,), m)``."""
        rays = [(self._rays if source is None else source)[lid] for lid in ids]
        if not rays:
            return np.zeros((0, 3)), np.zeros(0), np.zeros(0, np.int64), 0
        owner = np.repeat(np.arange(len(rays)), [len(ts) for ts, _ in rays])
        poses = pose_at(np.concatenate([np.asarray(ts, np.int64) for ts, _ in rays]))
        return poses, np.concatenate([np.asarray(bs, float) for _, bs in rays]), owner, len(rays)

    def initial_points(self, poses: np.ndarray, bearings_rad: np.ndarray, owner: np.ndarray,
                       m: int) -> tuple[np.ndarray, np.ndarray]:
        """The ray intersections of ``m`` landmarks, ray ``k`` from ``poses[k]`` (R, 3) with
        ``bearings_rad[k]`` for landmark ``owner[k]``: ``(points (m, 2), ok (m,))``, ok False
        (and NaN) where the parallax, a ray's depth or the range gate refuses the point."""
        xy, ok = intersect_ray_groups(poses[:, :2], poses[:, 2] + bearings_rad, owner, m,
                                      min_parallax_rad=self.config.min_parallax_rad)
        rng = self.header.sensor_range_m
        if rng is not None and m:
            far = np.hypot(*(poses[:, :2] - xy[owner]).T) > self.config.range_gate * rng
            ok &= np.bincount(owner, weights=far, minlength=m) == 0
        return xy, ok

    def enter(self, lid: int, xy: np.ndarray) -> None:
        """Put pending landmark ``lid`` in the graph at ``xy`` with all its buffered bearings.

        Raises
        ------
        ConfigError
            If ``lid`` is not pending or has fewer than two bearings.
        """
        if lid not in self._rays or len(self._rays[lid][0]) < 2:
            raise ConfigError(f"landmark {lid} cannot enter the graph: it needs at least two "
                              f"buffered bearings")
        ts, bs = self._rays.pop(lid)
        self._entered[lid] = (ts, bs)
        self._fresh.discard(lid)
        for t, b in zip(ts, bs):
            self._add_bearing(t, lid, b, self._landmark)
        self._in_graph.add(lid)
        self.landmark_ids.append(lid)
        self._new_ids.append(lid)
        self._new_values.insert(landmark_key(lid), gtsam.Point2(float(xy[0]), float(xy[1])))
        still = []
        for p in self._waiting_priors:
            if p.i in self._in_graph and p.j in self._in_graph:
                self._add(prior_factor(p), self._landmark)
                self.n_prior_factors += 1
            else:
                still.append(p)
        self._waiting_priors = still

    def withdraw(self, ids: Sequence[int]) -> None:
        """Undo the entry of ``ids``, landmarks of the batch last handed out by
        :meth:`take_new` whose factors were never used: they go back to pending with their
        bearings and are tried again after their next bearing. (iSAM2 uses it when the
        update that brought them in failed.)

        Raises
        ------
        ConfigError
            If an id did not enter in the last batch.
        """
        for lid in (int(i) for i in ids):
            if lid not in self._last_batch:
                raise ConfigError(f"landmark {lid} did not enter in the last batch; only "
                                  f"those can be withdrawn")
            ts, bs = self._last_batch.pop(lid)
            self._rays[lid] = (ts, bs)
            self.n_bearing_factors -= len(ts)
            self._in_graph.discard(lid)
            self.landmark_ids.remove(lid)
        self._waiting_priors = [p for p in self.header.priors
                                if not (p.i in self._in_graph and p.j in self._in_graph)]
        self.n_prior_factors = len(self.header.priors) - len(self._waiting_priors)

    # -- hand-over ------------------------------------------------------------------------
    def take_new(self) -> NewFactors:
        """The factors and landmark points added since the last call (buffers are reset)."""
        out = NewFactors(self._core, self._landmark, self._robust, self._new_ids,
                         self._new_values, np.array(self._rows, np.int64).reshape(-1, 5))
        self._rows = []
        self._core = gtsam.NonlinearFactorGraph()
        self._landmark = gtsam.NonlinearFactorGraph()
        self._robust = gtsam.NonlinearFactorGraph() if self._robust_noise else None
        self._new_ids = []
        self._new_values = gtsam.Values()
        self._last_batch, self._entered = self._entered, {}
        return out

    def entered_last(self) -> dict[int, tuple[list[int], list[float]]]:
        """The landmarks that entered in the batch last handed out by :meth:`take_new`: id ->
        (steps, bearings) of the buffered bearings they entered with."""
        return self._last_batch

    def _add(self, f: gtsam.NonlinearFactor,
             graph: gtsam.NonlinearFactorGraph | None = None) -> None:
        (self._core if graph is None else graph).add(f)
        if self._robust is not None:
            self._robust.add(f)

    def _add_bearing(self, t: int, lid: int, brg: float,
                     graph: gtsam.NonlinearFactorGraph) -> None:
        x, l, r = pose_key(t), landmark_key(lid), gtsam.Rot2(brg)
        graph.add(gtsam.BearingFactor2D(x, l, r, self._noise))
        if self._robust is not None:
            self._robust.add(gtsam.BearingFactor2D(x, l, r, self._robust_noise))
        self._rows.append((t, lid, int(graph is self._core), int(graph.size()) - 1,
                           -1 if self._robust is None else int(self._robust.size()) - 1))
        self.n_bearing_factors += 1


__all__ = ["FactorGraphConfig", "BearingGraph", "BearingLog", "NewFactors",
           "odometry_factors", "bearing_noise", "prior_factor", "pose_key", "mid_key",
           "landmark_key", "poses_from_values", "landmarks_from_values", "insert_pose"]
