"""GTSAM bearing-only SLAM baselines: batch Levenberg-Marquardt, incremental iSAM2, the oracle.

The paper (section IV, Exp. 2) compares BOM-STMDS with a filtering BOSLAM method; these
baselines solve the same problem as a factor graph, i.e. the maximum-likelihood estimate over
all poses and landmarks given every measurement:

* ``Pose2`` robot poses ``x_t`` (one per step), ``Point2`` landmarks ``l_i``;
* a prior on ``x_0`` that fixes the map frame (``start_pose``, the origin by default);
* one odometry factor per step (see *Odometry noise* below);
* one ``BearingFactor2D`` per bearing, std. dev. ``header.bearing_sigma_rad``;
* one ``RangeFactor2`` (point-to-point distance) per known prior distance
  (``header.priors``, the paper's Exp. 3).

**Odometry noise.** The stream's increment ``u = [dx, dy, dpsi]`` carries independent noise on
its three components (``Step.odometry_sigma``; the simulator's move-then-turn model has
``sigma_dy = 0``). ``BetweenFactorPose2`` measures its error as ``Logmap(U^-1 (x_{t-1}^-1
x_t))``, in the frame *after* the turn, where the translation noise is rotated by ``dpsi`` and
mixed with the heading noise through the ``SE(2)`` log map. A diagonal ``(sdx, sdy, sdpsi)``
there is wrong (chi^2 per residual far above 1 at the truth). The default model, ``"split"``,
is exact: each step passes through an intermediate pose ``m_t`` (after the move, before the
turn) with two between factors, ``x_{t-1} -> m_t`` measuring ``Pose2(dx, dy, 0)`` with sigmas
``(sdx, sdy, floor)`` and ``m_t -> x_t`` measuring ``Pose2(0, 0, dpsi)`` with sigmas ``(floor,
floor, sdpsi)``. At the truth both errors are exactly minus the component noise (the log map of
a pure translation or a pure rotation is exact), so chi^2 at the truth follows its nominal law.
``"transformed"`` keeps one between factor with the first-order covariance
``blockdiag(R(dpsi)^T diag(sdx^2, sdy^2) R(dpsi), sdpsi^2)``; it is right to first order only
(a second-order term ``~ n_dx n_dpsi / 2`` falls in the direction a zero ``sdy`` makes rigid,
so it needs a floor near 1 mm). ``"naive"`` is the wrong diagonal, kept as a regression check.
Zero sigmas are clamped to ``sigma_floor_m`` / ``sigma_floor_rad``.

**Landmarks** enter the graph only once at least two of their bearings intersect with enough
parallax (:func:`bomgraph.geometry.intersect_rays` on the current pose estimates, inside the
sensor range if the header gives one); until then their bearings are buffered, and all of them
become factors when the landmark enters. A landmark seen once never enters (one bearing leaves
it indeterminate and breaks iSAM2).

Mappers (registered in :mod:`bomgraph.mapper`): :class:`BatchMapper` (``gtsam-batch``),
:class:`Isam2Mapper` (``gtsam-isam2``) and :class:`OracleMapper` (``oracle``, started from the
ground truth; a benchmark bound, never a method for real data).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Callable, Sequence

import gtsam
import numpy as np

from bomgraph.errors import ConfigError, StreamFormatError
from bomgraph.geometry import compose
from bomgraph.mapper import MapEstimate
from bomgraph.stream import Prior, Step, StreamHeader, Truth
from bomgraph.geometry import intersect_rays

ODOMETRY_MODELS = ("split", "transformed", "naive")


# --------------------------------------------------------------------------------------------
# Keys
# --------------------------------------------------------------------------------------------

def pose_key(t: int) -> int:
    """GTSAM key of the robot pose at step ``t``."""
    return gtsam.symbol("x", int(t))


def mid_key(t: int) -> int:
    """GTSAM key of the intermediate pose of step ``t`` (after the move, before the turn)."""
    return gtsam.symbol("m", int(t))


def landmark_key(landmark_id: int) -> int:
    """GTSAM key of landmark ``landmark_id``."""
    return gtsam.symbol("l", int(landmark_id))


# --------------------------------------------------------------------------------------------
# Configuration
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class FactorGraphConfig:
    """Options of the factor-graph baselines (graph, Levenberg-Marquardt, iSAM2).

    Attributes
    ----------
    odometry_model : {"split", "transformed", "naive"}
        How the odometry noise enters (module docstring); ``"split"`` is exact.
    sigma_floor_m, sigma_floor_rad : float
        Lower bound of every odometry sigma and of the rigid directions of the split factors
        (the simulator's ``sigma_dy = 0``); also the sigma of the prior on the first pose.
        With the split model the rigid residuals are exactly 0 at the truth whatever the
        floor, so it only trades stiffness for conditioning: 1 mm / 1 mrad gave the same
        MPE on the paper setup as 0.1 mm (1.07 vs 1.10 cm, 25 runs) at half the LM time and
        reproducible to 1e-7 under relabelling (0.1 mm: 1e-4).
    min_parallax_rad : float
        A landmark enters once its rays span at least this angle (0.3 rad, 17 deg: with less,
        iSAM2's Gauss-Newton steps sent poorly initialised landmarks to infinity).
    range_gate : float
        With a known ``header.sensor_range_m``, the initial point must lie within
        ``range_gate * sensor_range_m`` of every pose that saw it.
    huber_k : float or None
        Huber threshold (whitened units) of a robust pass on the bearing factors before the
        plain pass; None skips it.
    odometry_cauchy_k : float or None
        Cauchy kernel (whitened threshold) on every odometry factor, in every pass; None
        (default: the simulator's odometry is Gaussian) keeps them Gaussian. Recordings have
        odometry outliers the Gaussian model cannot absorb (MRCLAM6 robot 5: steps 4-7 sigma
        off against the ground truth, a collision or a slip). Measured with 3.0 on MRCLAM6
        r1-r5 (gtsam-batch): landmark MPE 21.1 / 23.1 / 7.0 / 11.2 / 32.3 cm against
        20.9 / 24.5 / 7.2 / 13.6 / 74.3 cm Gaussian. Not with ``gtsam-isam2`` (refused:
        see :class:`Isam2Mapper`).
    bearing_cauchy_k : float or None
        Cauchy kernel on the bearing factors of the plain pass (the Huber pre-pass keeps its
        own kernel); None keeps them Gaussian. With robust odometry a gross bearing outlier
        (MRCLAM6 robot 5 has one 178 sigma off) can otherwise bend the trajectory it no longer
        pays for.
    max_iterations, relative_error_tol, absolute_error_tol, lambda_upper_bound,
    diagonal_damping :
        Levenberg-Marquardt settings. The upper bound on lambda must be large: the rigid
        directions have information ``1 / sigma_floor^2`` and GTSAM's LM stops silently,
        returning its input, once lambda exceeds the bound.
    decrease_tol : float
        A solution counts as converged when a Gauss-Newton step at it predicts less than this
        decrease of the error (GTSAM's error, chi^2 / 2), or when LM stopped on its
        tolerances (see :class:`SolveReport`).
    covariances : bool
        Fill ``landmark_cov`` and ``pose_cov`` through ``gtsam.Marginals`` (costs time).
    relinearize_threshold, relinearize_skip, checkpoint_updates :
        iSAM2: relinearise a variable whose delta exceeds the threshold, check every
        ``relinearize_skip`` updates, and run this many extra updates at each estimate().
        GTSAM's 0.1 is far above the 1 cm accuracy; 0.01 left iSAM2 short of the batch
        minimum in 4 of 10 paper runs, 0.001 in 1 of 10.
    isam2_factorization, isam2_dogleg :
        iSAM2's linear solver (``"CHOLESKY"`` or ``"QR"``) and Powell's dogleg instead of
        Gauss-Newton (a trust region: plain Gauss-Newton diverged on early, weakly
        constrained landmarks).
    """

    odometry_model: str = "split"
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
    relinearize_threshold: float = 0.001
    relinearize_skip: int = 1
    checkpoint_updates: int = 2
    isam2_factorization: str = "CHOLESKY"
    isam2_dogleg: bool = True

    def __post_init__(self) -> None:
        def need(ok: bool, msg: str) -> None:
            if not ok:
                raise ConfigError(f"FactorGraphConfig: {msg}")

        need(self.odometry_model in ODOMETRY_MODELS,
             f"odometry_model must be one of {ODOMETRY_MODELS}, got {self.odometry_model!r}")
        need(self.sigma_floor_m > 0 and self.sigma_floor_rad > 0, "sigma floors must be > 0")
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
        need(self.decrease_tol > 0, "decrease_tol must be > 0")
        need(self.relinearize_threshold > 0, "relinearize_threshold must be > 0")
        need(self.relinearize_skip >= 1, "relinearize_skip must be >= 1")
        need(self.checkpoint_updates >= 0, "checkpoint_updates must be >= 0")
        need(self.isam2_factorization in ("QR", "CHOLESKY"),
             "isam2_factorization must be 'QR' or 'CHOLESKY'")


def config_from(config: FactorGraphConfig | None,
                options: dict[str, Any]) -> FactorGraphConfig:
    """``config``, or a :class:`FactorGraphConfig` built from ``options`` (not both)."""
    if config is not None and options:
        raise ConfigError(f"pass either config= or options, not both (got {sorted(options)})")
    try:
        return config or FactorGraphConfig(**options)
    except TypeError as exc:
        raise ConfigError(f"unknown factor-graph option: {exc}") from None


# --------------------------------------------------------------------------------------------
# Factors
# --------------------------------------------------------------------------------------------

def odometry_factors(t: int, odom: np.ndarray, sigma: np.ndarray,
                     config: FactorGraphConfig) -> list[gtsam.NonlinearFactor]:
    """The odometry factor(s) of step ``t`` (pose ``t-1`` to pose ``t``).

    Parameters
    ----------
    t : int
        Step index, >= 1.
    odom : array of shape (3,)
        ``[dx_m, dy_m, dpsi_rad]`` in the frame of pose ``t-1``.
    sigma : array of shape (3,)
        Std. dev. of the three components (zeros are clamped to the floors).
    config : FactorGraphConfig
        ``odometry_model`` chooses the factor (module docstring).
    """
    fm, fr = config.sigma_floor_m, config.sigma_floor_rad
    s = np.maximum(np.asarray(sigma, dtype=float), [fm, fm, fr])
    dx, dy, dpsi = (float(v) for v in odom)
    a, b = pose_key(t - 1), pose_key(t)

    def robust(model: gtsam.noiseModel.Base) -> gtsam.noiseModel.Base:
        if config.odometry_cauchy_k is None:
            return model
        return gtsam.noiseModel.Robust.Create(
            gtsam.noiseModel.mEstimator.Cauchy.Create(config.odometry_cauchy_k), model)

    if config.odometry_model == "split":
        m = mid_key(t)
        return [gtsam.BetweenFactorPose2(a, m, gtsam.Pose2(dx, dy, 0.0),
                                         robust(gtsam.noiseModel.Diagonal.Sigmas(
                                             [s[0], s[1], fr]))),
                gtsam.BetweenFactorPose2(m, b, gtsam.Pose2(0.0, 0.0, dpsi),
                                         robust(gtsam.noiseModel.Diagonal.Sigmas(
                                             [fm, fm, s[2]])))]
    if config.odometry_model == "transformed":
        return [gtsam.BetweenFactorPose2(a, b, gtsam.Pose2(dx, dy, dpsi),
                                         robust(gtsam.noiseModel.Gaussian.Covariance(
                                             transformed_odometry_covariance(odom, s))))]
    return [gtsam.BetweenFactorPose2(a, b, gtsam.Pose2(dx, dy, dpsi),
                                     robust(gtsam.noiseModel.Diagonal.Sigmas(s)))]


def transformed_odometry_covariance(odom: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """First-order covariance of ``BetweenFactorPose2``'s error for component noise.

    The error ``Logmap(Pose2(u + n)^-1 Pose2(u))`` has Jacobian ``-blockdiag(R(dpsi)^T, 1)``
    with respect to the component noise ``n`` at ``n = 0``, hence
    ``blockdiag(R(dpsi)^T diag(sdx^2, sdy^2) R(dpsi), sdpsi^2)``, shape (3, 3).
    """
    c, s = math.cos(float(odom[2])), math.sin(float(odom[2]))
    r = np.array([[c, -s], [s, c]])
    cov = np.zeros((3, 3))
    cov[:2, :2] = r.T @ np.diag(np.asarray(sigma[:2], dtype=float) ** 2) @ r
    cov[2, 2] = float(sigma[2]) ** 2
    return cov


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
    """Robot poses ``x_t`` read from ``values``, shape ``(len(ts), 3)``."""
    out = np.empty((len(ts), 3))
    for k, t in enumerate(ts):
        p = values.atPose2(pose_key(int(t)))
        out[k] = (p.x(), p.y(), p.theta())
    return out


def landmarks_from_values(values: gtsam.Values, ids: Sequence[int] | np.ndarray) -> np.ndarray:
    """Landmark positions read from ``values``, shape ``(len(ids), 2)``."""
    out = np.empty((len(ids), 2))
    for k, i in enumerate(ids):
        out[k] = values.atPoint2(landmark_key(int(i)))
    return out


def insert_pose(values: gtsam.Values, t: int, pose: np.ndarray,
                previous_pose: np.ndarray | None, config: FactorGraphConfig) -> None:
    """Insert (or overwrite) ``x_t = pose`` and, for the split model and ``t > 0``, the
    intermediate pose ``m_t`` at the position of ``x_t`` with the heading of ``x_{t-1}``
    (``previous_pose``), which satisfies both rigid directions of the split factors."""
    _put(values, pose_key(t), gtsam.Pose2(*(float(v) for v in pose)))
    if config.odometry_model == "split" and t > 0:
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
    """

    core: gtsam.NonlinearFactorGraph
    landmark: gtsam.NonlinearFactorGraph
    robust: gtsam.NonlinearFactorGraph | None
    landmark_ids: list[int]
    landmark_values: gtsam.Values


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
        self.start_pose = np.asarray(start_pose, dtype=float).reshape(3)
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
        self._entered: dict[int, tuple[list[int], list[float]]] = {}
        self._last_batch: dict[int, tuple[list[int], list[float]]] = {}

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
        self.n_steps += 1

    def predict_pose(self, t: int, previous_pose: np.ndarray) -> np.ndarray:
        """``x_t`` predicted from ``x_{t-1}`` and the odometry of step ``t``, shape (3,)."""
        if t == 0:
            return self.start_pose.copy()
        return compose(previous_pose, self.odoms[t])

    # -- landmarks ------------------------------------------------------------------------
    def pending(self) -> dict[int, int]:
        """Landmarks not in the graph and how many bearings each has buffered."""
        return {lid: len(ts) for lid, (ts, _) in self._rays.items()}

    def admit(self, pose_at: Callable[[np.ndarray], np.ndarray], *,
              only_fresh: bool = False) -> list[int]:
        """Let in every pending landmark whose rays now intersect well.

        Parameters
        ----------
        pose_at : callable
            ``pose_at(ts)`` returns the current estimates of poses ``ts``, shape (k, 3).
        only_fresh : bool
            Only try landmarks that got a bearing since the last call (incremental use).

        Returns
        -------
        list of int
            Ids that entered now; their factors and initial points wait in :meth:`take_new`.
        """
        cand = self._fresh if only_fresh else set(self._rays)
        cand = sorted(lid for lid in cand if len(self._rays[lid][0]) >= 2)
        self._fresh = set()
        entered = []
        for lid in cand:
            ts, bs = self._rays[lid]
            xy = self.initial_point(pose_at(np.asarray(ts)), np.asarray(bs))
            if xy is not None:
                self.enter(lid, xy)
                entered.append(lid)
        return entered

    def initial_point(self, poses: np.ndarray, bearings_rad: np.ndarray) -> np.ndarray | None:
        """The ray intersection, or None if not determined (parallax, behind, out of range)."""
        xy, ok = intersect_rays(poses[:, :2], poses[:, 2] + bearings_rad,
                                min_parallax_rad=self.config.min_parallax_rad)
        if not ok:
            return None
        rng = self.header.sensor_range_m
        if rng is not None and np.any(np.hypot(*(poses[:, :2] - xy).T)
                                      > self.config.range_gate * rng):
            return None
        return xy

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
                         self._new_values)
        self._core = gtsam.NonlinearFactorGraph()
        self._landmark = gtsam.NonlinearFactorGraph()
        self._robust = gtsam.NonlinearFactorGraph() if self._robust_noise else None
        self._new_ids = []
        self._new_values = gtsam.Values()
        self._last_batch, self._entered = self._entered, {}
        return out

    def _add(self, f: gtsam.NonlinearFactor,
             graph: gtsam.NonlinearFactorGraph | None = None) -> None:
        (self._core if graph is None else graph).add(f)
        if self._robust is not None:
            self._robust.add(f)

    def _add_bearing(self, t: int, lid: int, brg: float,
                     graph: gtsam.NonlinearFactorGraph) -> None:
        graph.add(gtsam.BearingFactor2D(pose_key(t), landmark_key(lid), gtsam.Rot2(brg),
                                        self._noise))
        if self._robust is not None:
            self._robust.add(gtsam.BearingFactor2D(pose_key(t), landmark_key(lid),
                                                   gtsam.Rot2(brg), self._robust_noise))
        self.n_bearing_factors += 1


# --------------------------------------------------------------------------------------------
# Solving
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class SolveReport:
    """How a Levenberg-Marquardt solve went.

    ``stop`` is why the plain pass ended: ``"tolerance"`` (the error stopped decreasing),
    ``"lambda_bound"`` (no damped step decreased the error up to ``lambda_upper_bound``: LM
    gave up), ``"max_iterations"``, or ``"failed"`` (it raised). ``converged`` is True only if
    the error did not grow and either LM stopped on its tolerance or a Gauss-Newton step at the
    result predicts less than ``decrease_tol`` of further decrease; an LM run that gave up far
    from a minimum is never reported as converged.
    """

    converged: bool
    iterations: int
    initial_error: float
    final_error: float
    gn_step: float
    predicted_decrease: float
    stop: str
    passes: tuple[str, ...]
    message: str = ""

    def as_info(self) -> dict[str, Any]:
        return {"converged": self.converged, "iterations": self.iterations,
                "initial_cost": self.initial_error, "cost": self.final_error,
                "gn_step": self.gn_step, "predicted_decrease": self.predicted_decrease,
                "stop": self.stop, "passes": list(self.passes),
                **({"message": self.message} if self.message else {})}


def lm_params(config: FactorGraphConfig) -> gtsam.LevenbergMarquardtParams:
    """GTSAM LM parameters from the config (tight tolerances, a large lambda bound)."""
    p = gtsam.LevenbergMarquardtParams()
    p.setMaxIterations(config.max_iterations)
    p.setRelativeErrorTol(config.relative_error_tol)
    p.setAbsoluteErrorTol(config.absolute_error_tol)
    p.setlambdaUpperBound(config.lambda_upper_bound)
    p.setDiagonalDamping(config.diagonal_damping)
    return p


def gauss_newton_check(graph: gtsam.NonlinearFactorGraph,
                       values: gtsam.Values) -> tuple[float, float]:
    """The Gauss-Newton step at ``values``: its max-norm (metres or radians) and the decrease
    of the error (``graph.error``, i.e. chi^2 / 2) its linear model predicts; ``(inf, inf)``
    if the linear system is singular."""
    try:
        linear = graph.linearize(values)
        delta = linear.optimize()
    except RuntimeError:
        return math.inf, math.inf
    zero = gtsam.VectorValues(delta)
    zero.setZero()
    v = delta.vector()
    step = float(np.max(np.abs(v))) if v.size else 0.0
    return step, float(linear.error(zero) - linear.error(delta))


def solve_lm(graph: gtsam.NonlinearFactorGraph, initial: gtsam.Values,
             config: FactorGraphConfig,
             robust_graph: gtsam.NonlinearFactorGraph | None = None
             ) -> tuple[gtsam.Values, SolveReport]:
    """Levenberg-Marquardt on ``graph`` from ``initial``, after a robust pass if given.

    The robust result is kept only if it lowers the plain error. Never raises on a failed
    solve: returns the best values reached and a report saying why (:class:`SolveReport`).
    """
    params = lm_params(config)
    e0 = float(graph.error(initial))
    values = initial
    iterations = 0
    passes: list[str] = []
    message = ""
    stop = "failed"
    for name, g in (("huber", robust_graph), ("plain", graph)):
        if g is None:
            continue
        try:
            opt = gtsam.LevenbergMarquardtOptimizer(g, values, params)
            result = opt.optimize()
        except RuntimeError as exc:
            message = f"{name} pass failed: {_first_line(exc)}"
            continue
        n_it = int(opt.iterations())
        iterations += n_it
        passes.append(name)
        if name == "plain":
            values = result
            stop = ("max_iterations" if n_it >= config.max_iterations else
                    "lambda_bound" if float(opt.lambda_()) >= config.lambda_upper_bound else
                    "tolerance")
        elif float(graph.error(result)) <= float(graph.error(values)):
            values = result
    e1 = float(graph.error(values))
    step, decrease = gauss_newton_check(graph, values)
    converged = bool(stop != "failed" and math.isfinite(e1)
                     and e1 <= e0 * (1 + 1e-12) + 1e-12
                     and (stop == "tolerance" or decrease <= config.decrease_tol))
    if not converged and not message:
        message = (f"LM stopped on {stop}; a Gauss-Newton step would still lower the error by "
                   f"{decrease:.3g} (> decrease_tol {config.decrease_tol:g})")
    return values, SolveReport(converged, iterations, e0, e1, step, decrease, stop,
                               tuple(passes), message)


def marginal_covariances(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values,
                         pose_t: np.ndarray, landmark_ids: np.ndarray
                         ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Marginal covariances ``(n, 2, 2)`` of the landmarks and ``(m, 3, 3)`` of the poses
    (pose covariances in GTSAM's body frame convention), or ``(None, None)`` if singular."""
    try:
        marg = gtsam.Marginals(graph, values)
        lc = np.array([marg.marginalCovariance(landmark_key(int(i))) for i in landmark_ids])
        pc = np.array([marg.marginalCovariance(pose_key(int(t))) for t in pose_t])
    except RuntimeError:
        return None, None
    return lc.reshape(-1, 2, 2), pc.reshape(-1, 3, 3)


def _first_line(exc: BaseException) -> str:
    """The gist of a GTSAM exception: one line, without the generic help text."""
    text = " ".join(str(exc).split())
    text = text.split(" Thrown when")[0]
    return text[:300] if text else type(exc).__name__


def estimate_from_values(graph: BearingGraph, values: gtsam.Values,
                         solved: gtsam.NonlinearFactorGraph, info: dict[str, Any],
                         covariances: bool) -> MapEstimate:
    """The MapEstimate of a solution: every pose, the landmarks in the graph (sorted by id),
    ``info`` plus the graph's counts, and marginal covariances of ``solved`` if asked."""
    ids = np.array(sorted(graph.landmark_ids), dtype=np.int64)
    pose_t = np.arange(graph.n_steps, dtype=np.int64)
    poses = poses_from_values(values, pose_t)
    xy = landmarks_from_values(values, ids)
    info = dict(info)
    info.update({"n_landmarks": int(ids.size), "pending": len(graph.pending()),
                 "n_bearing_factors": graph.n_bearing_factors,
                 "n_prior_factors": graph.n_prior_factors, "n_factors": int(solved.size()),
                 "odometry_model": graph.config.odometry_model})
    lc = pc = None
    if covariances and ids.size:
        lc, pc = marginal_covariances(solved, values, pose_t, ids)
        info["covariances"] = lc is not None
    if ids.size == 0:
        info.setdefault("reason", "no landmark has two bearings with enough parallax yet")
    return MapEstimate(ids, xy, pose_t=pose_t, poses=poses, landmark_cov=lc, pose_cov=pc,
                       info=info)


# --------------------------------------------------------------------------------------------
# Batch LM
# --------------------------------------------------------------------------------------------

class BatchMapper:
    """``gtsam-batch``: Levenberg-Marquardt on the whole graph at each ``estimate()``.

    Warm-started from the previous solution; poses added since then are predicted by
    composing the odometry onto the last solved pose. A Huber pass on the bearings precedes
    the plain pass (``huber_k``).

    Parameters
    ----------
    header : StreamHeader
    start_pose : (x_m, y_m, psi_rad)
        The map frame: the first pose is tied here (the origin by default).
    config : FactorGraphConfig, optional
    **options
        Fields of :class:`FactorGraphConfig` (instead of ``config``).
    """

    def __init__(self, header: StreamHeader, *,
                 start_pose: Sequence[float] = (0.0, 0.0, 0.0),
                 config: FactorGraphConfig | None = None, **options: Any) -> None:
        self.config = config_from(config, options)
        self.header = header
        self.problem = BearingGraph(header, self.config, np.asarray(start_pose, dtype=float))
        self.graph = gtsam.NonlinearFactorGraph()
        self.robust_graph = (gtsam.NonlinearFactorGraph() if self.config.huber_k is not None
                             else None)
        self.values = gtsam.Values()
        self._solved_upto = -1          # poses 0.._solved_upto hold solved values
        self._last: MapEstimate | None = None

    def step(self, step: Step) -> None:
        self.problem.add_step(step)
        t = step.t
        prev = (poses_from_values(self.values, [t - 1])[0] if t > 0 else None)
        insert_pose(self.values, t, self.problem.predict_pose(t, prev), prev, self.config)

    def _pose_at(self, ts: np.ndarray) -> np.ndarray:
        return poses_from_values(self.values, ts)

    def absorb(self) -> NewFactors:
        """Let in the landmarks now determined and move all new factors and landmark points
        into ``graph`` / ``values`` (what ``estimate()`` does before solving)."""
        self.problem.admit(self._pose_at)
        new = self.problem.take_new()
        self.graph.push_back(new.core)
        self.graph.push_back(new.landmark)
        if self.robust_graph is not None and new.robust is not None:
            self.robust_graph.push_back(new.robust)
        self.values.insert(new.landmark_values)
        return new

    def initial_values(self) -> gtsam.Values:
        """The values LM starts from (previous solution + odometry predictions)."""
        return self.values

    def estimate(self) -> MapEstimate:
        if self.problem.n_steps == 0:
            return MapEstimate.empty(reason="no steps yet")
        self.absorb()
        values, report = solve_lm(self.graph, self.initial_values(), self.config,
                                  self.robust_graph)
        self.values = values
        return estimate_from_values(self.problem, values, self.graph, report.as_info(),
                                     self.config.covariances)


class OracleMapper(BatchMapper):
    """``oracle``: LM started from the ground truth at each ``estimate()`` (benchmarks only).

    The truth (poses and landmarks) is moved into the map frame (the first true pose onto
    ``start_pose``); landmarks enter by the same rule as the other mappers, judged on the true
    poses, so the graph matches theirs. The converged result is the maximum-likelihood
    estimate reached from the best possible start: the accuracy bound of the baselines.

    Parameters
    ----------
    header : StreamHeader
    truth : Truth
        Must have poses.
    """

    def __init__(self, header: StreamHeader, *, truth: Truth,
                 start_pose: Sequence[float] = (0.0, 0.0, 0.0),
                 config: FactorGraphConfig | None = None, **options: Any) -> None:
        if truth is None or truth.poses is None:
            raise ConfigError("the oracle needs the true poses (truth.poses)")
        cfg = config_from(config, options)
        super().__init__(header, start_pose=start_pose, config=replace(cfg, huber_k=None))
        p0 = truth.poses[0]
        s = np.asarray(start_pose, dtype=float)
        r = _rot(s[2] - p0[2])
        self._true_poses = np.column_stack([(truth.poses[:, :2] - p0[:2]) @ r.T + s[:2],
                                            truth.poses[:, 2] - p0[2] + s[2]])
        self._true_xy = {int(i): (xy - p0[:2]) @ r.T + s[:2]
                         for i, xy in zip(truth.landmark_ids, truth.landmarks_xy)}

    def step(self, step: Step) -> None:
        if step.t >= len(self._true_poses):
            raise ConfigError(f"the truth has {len(self._true_poses)} poses; step {step.t} "
                              f"has none")
        super().step(step)

    def _pose_at(self, ts: np.ndarray) -> np.ndarray:
        return self._true_poses[np.asarray(ts, dtype=np.int64)]

    def initial_values(self) -> gtsam.Values:
        v = gtsam.Values()
        for t in range(self.problem.n_steps):
            insert_pose(v, t, self._true_poses[t], self._true_poses[t - 1] if t else None,
                        self.config)
        for lid in self.problem.landmark_ids:
            xy = self._true_xy.get(lid)
            if xy is None:
                xy = self.values.atPoint2(landmark_key(lid))
            v.insert(landmark_key(lid), gtsam.Point2(float(xy[0]), float(xy[1])))
        return v


def _rot(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


# --------------------------------------------------------------------------------------------
# iSAM2
# --------------------------------------------------------------------------------------------

class Isam2Mapper:
    """``gtsam-isam2``: one iSAM2 update per step with only the new factors and values.

    The new factors and values are collected in buffers, handed to ``isam.update`` and
    cleared (GTSAM's ``IMUKittiExampleGPS.py`` pattern); the whole graph is kept only to
    rebuild after a failure. If an update raises (e.g. an indeterminate linear system), the
    solver is rebuilt from the factors accepted so far and the last good estimate, the step's
    odometry and the bearings to known landmarks are applied again, and the landmarks that had
    just entered go back to the pending buffer (they retry with their next bearing); external
    factors of that update are dropped. Each event is counted in ``info``.

    iSAM2 never iterates to convergence; ``info["converged"]`` says whether a Gauss-Newton
    step on the whole graph at the current estimate would lower the error by less than
    ``decrease_tol`` (computed at each ``estimate()``; ``checkpoint_updates`` extra updates
    run before it).

    Parameters
    ----------
    header : StreamHeader
    start_pose : (x_m, y_m, psi_rad)
    config : FactorGraphConfig, optional
    **options
        Fields of :class:`FactorGraphConfig`.
    """

    def __init__(self, header: StreamHeader, *,
                 start_pose: Sequence[float] = (0.0, 0.0, 0.0),
                 config: FactorGraphConfig | None = None, **options: Any) -> None:
        self.config = config_from(config, options)
        if (self.config.odometry_cauchy_k is not None
                or self.config.bearing_cauchy_k is not None):
            raise ConfigError(
                "gtsam-isam2 does not take Cauchy kernels (odometry_cauchy_k, "
                "bearing_cauchy_k): where a kernel switches off every factor of a variable, "
                "iSAM2's undamped linear solve finds the system indeterminate and so does its "
                "rebuild (measured on MRCLAM6 robots 2 and 5); use gtsam-batch, whose damped "
                "Levenberg-Marquardt copes")
        self.header = header
        self.problem = BearingGraph(header, self.config, np.asarray(start_pose, dtype=float))
        self.accepted = gtsam.NonlinearFactorGraph()   # every factor iSAM2 holds
        self.estimate_values = gtsam.Values()          # after the last good update
        self._isam = self._new_isam()
        self._external = gtsam.NonlinearFactorGraph()
        self._external_values = gtsam.Values()
        self.failures: list[str] = []
        self.rebuilds = 0
        self.dropped_external = 0
        self.withdrawn: list[int] = []

    def _new_isam(self) -> gtsam.ISAM2:
        p = gtsam.ISAM2Params()
        p.setRelinearizeThreshold(self.config.relinearize_threshold)
        p.relinearizeSkip = self.config.relinearize_skip
        p.setFactorization(self.config.isam2_factorization)
        if self.config.isam2_dogleg:
            p.setOptimizationParams(gtsam.ISAM2DoglegParams())
        return gtsam.ISAM2(p)

    def add_factors(self, factors: gtsam.NonlinearFactorGraph,
                    values: gtsam.Values | None = None) -> None:
        """Queue external factors (and initial values of new variables they bring) for the
        next update, e.g. known constraints. If they make the update fail they are dropped
        and counted in ``info["dropped_external_factors"]``."""
        self._external.push_back(factors)
        if values is not None:
            self._external_values.insert(values)

    def step(self, step: Step) -> None:
        self.problem.add_step(step)
        t = step.t
        prev = (self.estimate_values.atPose2(pose_key(t - 1)) if t > 0 else None)
        prev_np = None if prev is None else np.array([prev.x(), prev.y(), prev.theta()])
        new_poses = gtsam.Values()
        insert_pose(new_poses, t, self.problem.predict_pose(t, prev_np), prev_np, self.config)
        lookup = _Lookup(self.estimate_values, new_poses)
        self.problem.admit(lookup.poses, only_fresh=True)
        new = self.problem.take_new()
        self._update(new, new_poses)

    def _update(self, new: NewFactors, new_poses: gtsam.Values) -> None:
        factors = gtsam.NonlinearFactorGraph()
        factors.push_back(new.core)
        factors.push_back(new.landmark)
        factors.push_back(self._external)
        values = gtsam.Values(new_poses)
        values.insert(new.landmark_values)
        values.insert(self._external_values)
        try:
            self._isam.update(factors, values)
            self._accept(factors)
        except RuntimeError as exc:
            self.failures.append(_first_line(exc))
            # iSAM2 is unusable after a failed update: rebuild from what it held before,
            # then apply only the odometry and bearings to known landmarks.
            self._rebuild(self.accepted, self.estimate_values)
            if new.landmark_ids:
                self.problem.withdraw(new.landmark_ids)
                self.withdrawn.extend(new.landmark_ids)
            self.dropped_external += int(self._external.size())
            try:
                self._isam.update(new.core, new_poses)
                self._accept(new.core)
            except RuntimeError as exc2:        # even the core fails: solve it in batch
                self.failures.append(_first_line(exc2))
                full = gtsam.NonlinearFactorGraph(self.accepted)
                full.push_back(new.core)
                start = gtsam.Values(self.estimate_values)
                start.insert(new_poses)
                values_lm, _ = solve_lm(full, start, self.config)
                self._rebuild(full, values_lm)
                self.accepted = full
                self.estimate_values = self._isam.calculateEstimate()
        self._external = gtsam.NonlinearFactorGraph()
        self._external_values = gtsam.Values()

    def _accept(self, factors: gtsam.NonlinearFactorGraph) -> None:
        self.estimate_values = self._isam.calculateEstimate()
        self.accepted.push_back(factors)

    def _rebuild(self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> None:
        self.rebuilds += 1
        self._isam = self._new_isam()
        self._isam.update(graph, values)

    def estimate(self) -> MapEstimate:
        if self.problem.n_steps == 0:
            return MapEstimate.empty(reason="no steps yet")
        try:
            for _ in range(self.config.checkpoint_updates):
                self._isam.update()
            self.estimate_values = self._isam.calculateEstimate()
        except RuntimeError as exc:
            self.failures.append(_first_line(exc))
            self._rebuild(self.accepted, self.estimate_values)
        step, decrease = gauss_newton_check(self.accepted, self.estimate_values)
        info = {"converged": bool(decrease <= self.config.decrease_tol),
                "cost": float(self.accepted.error(self.estimate_values)), "gn_step": step,
                "predicted_decrease": decrease,
                "update_failures": len(self.failures), "rebuilds": self.rebuilds,
                "withdrawn_landmarks": list(self.withdrawn),
                "dropped_external_factors": self.dropped_external}
        if self.failures:
            info["last_failure"] = self.failures[-1]
        return estimate_from_values(self.problem, self.estimate_values, self.accepted, info,
                                     self.config.covariances)


class _Lookup:
    """Pose estimates from the solver's values, the newest pose from the prediction."""

    def __init__(self, values: gtsam.Values, extra: gtsam.Values) -> None:
        self.values, self.extra = values, extra

    def poses(self, ts: np.ndarray) -> np.ndarray:
        out = np.empty((len(ts), 3))
        for k, t in enumerate(ts):
            key = pose_key(int(t))
            p = (self.values if self.values.exists(key) else self.extra).atPose2(key)
            out[k] = (p.x(), p.y(), p.theta())
        return out


__all__ = ["FactorGraphConfig", "BearingGraph", "NewFactors", "SolveReport", "BatchMapper",
           "Isam2Mapper", "OracleMapper", "odometry_factors", "transformed_odometry_covariance",
           "bearing_noise", "prior_factor", "solve_lm", "lm_params", "gauss_newton_check",
           "marginal_covariances", "pose_key", "mid_key", "landmark_key", "poses_from_values",
           "landmarks_from_values", "insert_pose", "config_from", "estimate_from_values",
           "ODOMETRY_MODELS"]
