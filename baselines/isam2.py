"""``gtsam-isam2``: the bearing-only graph of :mod:`baselines.bearing_graph` solved incrementally.

One iSAM2 update per step with only the new factors and values; a failed update is recovered
by a rebuild, and a rebuild that fails hands over to batch Levenberg-Marquardt
(:func:`baselines.factor_graph.solve_lm`). The paper's section IV, Exp. 2 comparison.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Any, ClassVar, Mapping, Sequence

import gtsam
import numpy as np

from bomgraph.config import requirement, resolve
from bomgraph.mapper import MapEstimate
from bomgraph.stream import Step, StreamHeader

from .bearing_graph import (BearingGraph, BearingLog, FactorGraphConfig, insert_pose, landmark_key,
                            mid_key, pose_key)
from .lm_report import GTSAM_ERRORS, estimate_from_values, gtsam_error_line, solve_lm
from .isam2_normal import NormalModeCheck
from .isam2_window import WindowLongMode
from .lm_report import plain_gaussian, polish
from .lm_window import StepChunks


#: The relinearisation settings the recording presets were validated with (``docs/measurements.md``,
#: "gtsam-isam2: schedule, polish, robust kernels"); the paper defaults are cheaper (issue 14).
_VALIDATED_RELINEARISATION = {"relinearize_threshold": 0.001, "checkpoint_updates": 2}


@dataclass(frozen=True)
class Isam2Config(FactorGraphConfig):
    """:class:`FactorGraphConfig` plus the iSAM2 schedule (``gtsam-isam2``).

    Presets: ``"paper"`` (the defaults), ``"robust"`` (Cauchy kernels with threshold 3 on the
    odometry and the bearings, as for ``gtsam-batch``, and a weak 100 m prior on each landmark
    so that no kernel or weak geometry leaves the undamped solve indeterminate) and
    ``"real"`` (the recording setting: the same values, validated unchanged on MRCLAM6
    and MRCLAM1 streams with other keyframings and sigma calibrations,
    ``docs/measurements.md``, and ``isam2_polish`` 10: on MRCLAM1 robots 3-5 the map asked
    for 6-9 dead-reckoned keyframes after the last update needed more than 3 steps to reach
    the minimum, and was reported unconverged; the polish stops as soon as a step predicts at
    most ``decrease_tol``, so a converged map is unchanged).

    Attributes
    ----------
    isam2_update_every : int
        Steps per iSAM2 update (the buffered steps go in together; an internal schedule,
        independent of ``estimate()``).
    isam2_update_on_entry : bool
        Also update at a step where landmarks entered (before the next step reads poses
        from the solver: a landmark entering on poses dead-reckoned for up to
        ``isam2_update_every`` steps left early maps worse, 3.5 -> 3.6 cm MPE at t = 50).
    isam2_optimizer : str
        ``"dogleg"`` (Powell's trust region: plain Gauss-Newton diverged on early, weakly
        constrained landmarks) or ``"gauss-newton"``.
    isam2_partial_check : bool
        GTSAM's ``enablePartialRelinearizationCheck``.
    isam2_polish : int
        At most this many Gauss-Newton steps on the whole graph polish the map at each
        ``estimate()`` (on a copy; 0: only the convergence check).
    landmark_prior_sigma_m : float or None
        A weak prior (this sigma, metres) on each landmark at its entry point: it keeps the
        undamped iSAM2 solve determinate where the bearings leave a landmark's range
        unobserved (small parallax) or a robust kernel switches its factors off, at a cost
        of ``(d / sigma)^2 / 2`` for a displacement ``d``. None: no prior.
    relinearize_threshold, checkpoint_updates :
        As in :class:`FactorGraphConfig`, with cheaper defaults here (0.01 and 1; the
        ``robust`` and ``real`` presets keep 0.001 and 2, with which they were validated on
        recordings).
    long_after_steps : int or None
        Long recordings: from the first scheduled update at or past this many steps the
        mapper goes *long* (None: never): iSAM2 runs Gauss-Newton (Powell's dogleg evaluates
        the whole graph's error and gradient at every update: O(T) per update) on a bounded
        window (``long_window``, the default) or, with ``long_window`` False, over the whole
        history with poses older than ``long_lag_steps`` not relinearised (ISAM2's
        ``noRelinKeys``; they still move with the linear solution) except at an update
        where the graph has grown by ``long_growth`` since the last full check. Either way
        the whole graph is checked (Gauss-Newton) each time it has grown ``long_growth``x;
        ``estimate()`` no longer polishes the whole graph (it reports the last check), so
        the whole-graph work adds up to a geometric series.
    long_lag_steps : int
        Poses relinearised in long mode (the latest this many): with ``long_window`` the
        shortest window (50; with ``long_window`` False the session-7 value was 100).
    long_relinearize_threshold : float
        ``relinearize_threshold`` in long mode (the poses that would drift past it are held
        by ``long_lag_steps``).
    long_growth : float
        Growth factor of the graph (in steps) between two whole-graph relinearisations and
        convergence checks in long mode (each check is a whole-graph linearisation and
        solve, plus a whole-graph LM solve when it fails; 2 measured cheaper than 1.25 at
        the same final map, ``docs/measurements.md``).
    long_wildfire_threshold : float
        Gauss-Newton wildfire threshold in long mode (0: full back-substitution). GTSAM's
        0.001 left deltas stale by up to 1e-3 on the rigid split-odometry directions (sigma
        1e-3), which the whole-graph check saw as ~100-2,700 units of predicted decrease.
    long_checkpoint_updates : int
        ``checkpoint_updates`` in long mode (0 measured faster but left the final map
        128 units above the minimum, ``docs/measurements.md``).
    long_window : bool
        Long mode with a bounded iSAM2 (the default): iSAM2 holds only the last
        ``long_lag_steps`` to ``long_lag_steps + long_shift_steps`` poses and the landmarks;
        the older steps are eliminated into the Gaussian marginal of
        :class:`baselines.lm_window.StepChunks` (the fixed-lag machinery of ``gtsam-batch``),
        on the boundary pose and the landmarks. When the window would exceed its length, or
        new factors reach a variable outside it (a bearing from an eliminated pose, a
        landmark seen again after it left), iSAM2 is rebuilt on the window that ends at the
        newest step. At each whole-graph check (``long_growth``) the whole graph gets up to
        ``isam2_polish`` Gauss-Newton steps (each kept only if it lowers the error) before
        the check, and the marginal is rebuilt at the new values. Poses older than the window
        are back-substituted from the window's solution through the conditionals they were
        eliminated into (:meth:`Isam2Mapper.current_values`; held at their last estimate
        past ``lag_marginal_landmarks`` landmarks, where the chunks fold instead of
        eliminating). False: the session-7 long mode, one iSAM2 over the
        whole history with the old poses in ``noRelinKeys`` (per-update cost growing with
        the run).
    long_shift_steps : int
        How far the window's end moves before iSAM2 is rebuilt on a new window (each rebuild
        eliminates these steps into the marginal and factorises the window once).
    restart_cost_ratio : float or None
        Normal mode: a map whose polish at a scheduled update (or at the end of the run) is
        unconverged and costs more than this times the cost expected at the minimum is
        solved by Levenberg-Marquardt on the whole graph and iSAM2 rebuilt there. The
        expected cost is the chi-square mean, half the residual dimensions less the
        variables' (a ratio, no units; :meth:`Isam2Mapper._restart_if_stuck`). Measured: a
        map out of the basin 8.5-38x (MRCLAM6 r3 at 0.5 m / 0.5 rad: 59 cm, 10 of 15
        landmarks without the restart); the paper setup's unconverged maps (seeds 3-4, 22-24
        of 30 checkpoints) at most 1.21x, whose restarts cost up to 8x the run. 0: every
        unconverged check restarts; None: none does (nor is the check made at the updates).
    """

    PRESETS: ClassVar[Mapping[str, Mapping[str, Any]]] = {
        "paper": {},
        "robust": {"odometry_cauchy_k": 3.0, "bearing_cauchy_k": 3.0,
                   "landmark_prior_sigma_m": 100.0, **_VALIDATED_RELINEARISATION},
        "real": {"odometry_cauchy_k": 3.0, "bearing_cauchy_k": 3.0,
                 "landmark_prior_sigma_m": 100.0, "isam2_polish": 10,
                 **_VALIDATED_RELINEARISATION},
    }

    relinearize_threshold: float = 0.01
    checkpoint_updates: int = 1

    isam2_update_every: int = 10
    isam2_update_on_entry: bool = True
    isam2_optimizer: str = "dogleg"
    isam2_partial_check: bool = False
    isam2_polish: int = 3
    landmark_prior_sigma_m: float | None = None
    long_after_steps: int | None = 500
    long_lag_steps: int = 50
    long_relinearize_threshold: float = 0.001
    long_growth: float = 2.0
    long_wildfire_threshold: float = 0.0
    long_checkpoint_updates: int = 1
    long_window: bool = True
    long_shift_steps: int = 50
    restart_cost_ratio: float | None = 2.0

    def __post_init__(self) -> None:
        super().__post_init__()
        need = requirement(type(self).__name__)
        need(self.isam2_update_every >= 1, "isam2_update_every must be >= 1")
        need(self.isam2_optimizer in ("dogleg", "gauss-newton"),
             "isam2_optimizer must be 'dogleg' or 'gauss-newton'")
        need(self.isam2_polish >= 0, "isam2_polish must be >= 0")
        need(self.landmark_prior_sigma_m is None or self.landmark_prior_sigma_m > 0,
             "landmark_prior_sigma_m must be > 0 or None")
        need(self.long_after_steps is None or self.long_after_steps >= 1,
             "long_after_steps must be >= 1 or None")
        need(self.long_lag_steps >= 1, "long_lag_steps must be >= 1")
        need(self.long_relinearize_threshold > 0, "long_relinearize_threshold must be > 0")
        need(self.long_growth > 1, "long_growth must be > 1")
        need(self.long_shift_steps >= 1, "long_shift_steps must be >= 1")
        need(self.restart_cost_ratio is None or self.restart_cost_ratio >= 0,
             "restart_cost_ratio must be >= 0 or None")


def isam2_params(config: FactorGraphConfig | None = None, *,
                 long: bool = False) -> gtsam.ISAM2Params:
    """``gtsam-isam2``'s iSAM2 settings for ``config`` (:class:`Isam2Config`, None: ``paper``, a
    :class:`FactorGraphConfig`: iSAM2 fields at their defaults), ``long``: long mode's. Not in
    them: ``checkpoint_updates`` empty ``isam.update()`` calls after one with new factors."""
    plain = isinstance(config, FactorGraphConfig) and not isinstance(config, Isam2Config)
    cfg = resolve(Isam2Config, Isam2Config(**asdict(config)) if plain else config)
    p = gtsam.ISAM2Params()
    p.setRelinearizeThreshold(cfg.long_relinearize_threshold if long else cfg.relinearize_threshold)
    p.relinearizeSkip = cfg.relinearize_skip
    p.enablePartialRelinearizationCheck = cfg.isam2_partial_check
    p.setFactorization("CHOLESKY")
    if cfg.isam2_optimizer == "dogleg" and not long:
        p.setOptimizationParams(gtsam.ISAM2DoglegParams())
    else:
        p.setOptimizationParams(gtsam.ISAM2GaussNewtonParams(
            cfg.long_wildfire_threshold if long else 0.001))
    return p


class Isam2Mapper(WindowLongMode, NormalModeCheck):
    """``gtsam-isam2``: iSAM2 updates with only the new factors and values, on an internal
    schedule (every ``isam2_update_every`` steps, and at a step where landmarks entered).

    Each step's factors and values (odometry, bearings, entering landmarks: the graph of
    :class:`BearingGraph`) go to a buffer; every ``isam2_update_every`` steps the buffer is
    handed to ``isam.update`` and cleared (GTSAM's ``IMUKittiExampleGPS.py`` pattern),
    followed by ``checkpoint_updates`` extra updates (relinearisation only) and one
    ``calculateEstimate``. Poses since the last update are predicted by composing the
    odometry onto the latest estimate. ``estimate()`` changes no state: it polishes the
    solver's estimate (with the buffered steps) by up to ``isam2_polish`` Gauss-Newton steps
    on the whole graph, each kept only if it lowers the error, so the map at step ``T``
    does not depend on how often it was asked for. ``info["converged"]`` says whether the
    last Gauss-Newton step predicted a decrease of at most ``decrease_tol`` and was finite.
    At each scheduled update that polish is made and, where it fails far above the expected
    cost (``restart_cost_ratio``), the whole graph solved by Levenberg-Marquardt
    and iSAM2 rebuilt there (:meth:`_restart_if_stuck`).
    Past ``long_after_steps`` the mapper runs in long mode (:class:`Isam2Config`; bounded
    work per update, no whole-graph polish per estimate, ``info["mode"] = "isam2-long"``
    and ``info["checked_at_step"]``, the step of the whole-graph check it reports; with the
    window also ``info["window_start"]``, its held pose, and ``info["window_rebuilds"]``).
    In long mode with the window, the map's older poses are back-substituted from the
    window's solution (:meth:`current_values`). At the end of a run, :meth:`finish` (called
    by :func:`bomgraph.mapper.run`) tries every pending landmark once more (those it lets in:
    ``info["entered_at_finish"]``) and checks the whole graph once more in long mode.

    If an update raises (e.g. an indeterminate linear system), the external factors of that
    update (:meth:`add_factors`) are dropped and the solver is rebuilt from the factors held
    so far; if that fails too, the whole graph is solved by (damped) Levenberg-Marquardt and
    iSAM2 restarted from its solution; if even that fails the mapper goes on in batch
    (Levenberg-Marquardt at each internal update and at ``estimate()``, ``info["mode"]``).
    Each event is counted in ``info``; nothing raises.

    Parameters
    ----------
    header : StreamHeader
    start_pose : (x_m, y_m, psi_rad)
    config : Isam2Config or FactorGraphConfig, optional
        A plain :class:`FactorGraphConfig` runs with the iSAM2 fields at their defaults.
    preset : str, optional
        An :class:`Isam2Config` preset (``"paper"``, ``"robust"``, ``"real"``).
    **options
        Fields of :class:`Isam2Config` (with ``preset``, not with ``config``).
    """

    def __init__(self, header: StreamHeader, *,
                 start_pose: Sequence[float] = (0.0, 0.0, 0.0),
                 config: Isam2Config | FactorGraphConfig | None = None,
                 preset: str | None = None, **options: Any) -> None:
        if config is not None and not isinstance(config, Isam2Config):
            if not isinstance(config, FactorGraphConfig):
                resolve(Isam2Config, config, preset, options)   # raises, naming the type
            config = Isam2Config(**asdict(config))               # iSAM2 fields at defaults
        self.config = resolve(Isam2Config, config, preset, options)
        self.header = header
        self.problem = BearingGraph(header, self.config, start_pose)
        self.accepted = gtsam.NonlinearFactorGraph()   # every factor the solver holds
        self.estimate_values = gtsam.Values()          # its estimate after the last update
        self._long = False   # long mode (Isam2Config.long_after_steps)
        self._isam = self._new_isam()
        self._buffer = gtsam.NonlinearFactorGraph()    # steps since the last update
        self._buffer_values = gtsam.Values()
        self._external = gtsam.NonlinearFactorGraph()
        self._external_values = gtsam.Values()
        # every factor so far plain Gaussian (lm_report.plain_gaussian): the polish reads the
        # errors from its linearisations
        self._gaussian = True
        self.failures: list[str] = []
        self.rebuilds = 0
        self.updates = 0
        self._batch = False  # set when iSAM2 cannot be rebuilt (see _recover)
        self.dropped_external = 0
        self.lm_restarts = 0
        self._long_full = 0  # steps at the last whole-graph relinearisation and check
        self._long_check: dict[str, Any] = {}
        self._old = gtsam.KeyList()  # what long mode does not relinearise
        self._old_upto = 0
        self._old_landmarks: set[int] = set()
        # long_window: every step's factors filed by step (the fixed-lag machinery of
        # gtsam-batch), every bearing as arrays (the chunks' conditional folds), the held
        # pose of the window iSAM2 holds (0: iSAM2 holds the whole graph)
        cfg = self.config
        self._chunks: StepChunks | None = None
        if cfg.long_window and cfg.long_after_steps is not None:
            span = cfg.long_lag_steps + cfg.long_shift_steps
            self._chunks = StepChunks(header, replace(
                cfg, lag_steps=max(span, 2),
                lag_after_steps=max(cfg.lag_after_steps, span, 2)), keep_conditionals=True)
        self._log = BearingLog()
        self._window_b = 0
        self._window_fresh: list[int] = []
        self.window_rebuilds = 0
        self._at_check = False   # the estimate is the one the last whole-graph check checked
        # the normal mode's polished map (_polish) and what it was computed from
        self._polished: tuple[tuple[Any, ...], Any, Any, dict[str, Any]] | None = None
        self._checked: tuple[Any, ...] | None = None   # the state the last check left alone
        self._dims = (0, 0)   # factors of ``accepted`` counted, their residual dimensions
        self._finished_n = -1   # the step count at the last finish() (a second one: nothing)
        self._finish_entered: list[int] = []   # the landmarks finish() let in

    def _new_isam(self) -> gtsam.ISAM2:
        """A fresh iSAM2 with :func:`isam2_params` (long mode's settings in long mode)."""
        return gtsam.ISAM2(isam2_params(self.config, long=self._long))

    def add_factors(self, factors: gtsam.NonlinearFactorGraph,
                    values: gtsam.Values | None = None) -> None:
        """Queue external factors (and initial values of new variables they bring) for the
        next update, e.g. known constraints. If they make the update fail they are dropped
        and counted in ``info["dropped_external_factors"]``."""
        self._gaussian = self._gaussian and plain_gaussian(factors)
        self._external.push_back(factors)
        if values is not None:
            self._external_values.insert(values)

    # -- stepping -------------------------------------------------------------------------
    def _pose(self, t: int) -> np.ndarray:
        """The current estimate of pose ``t``, shape (3,): predicted if ``t`` came after the
        last update, else the solver's estimate at that update."""
        key = pose_key(t)
        src = self._buffer_values if self._buffer_values.exists(key) else self.estimate_values
        p = src.atPose2(key)
        return np.array([p.x(), p.y(), p.theta()])

    def _poses(self, ts: np.ndarray) -> np.ndarray:
        return np.array([self._pose(int(t)) for t in ts]).reshape(-1, 3)

    def step(self, step: Step) -> None:
        self._finish_entered = []
        self.problem.add_step(step)
        t = step.t
        prev = self._pose(t - 1) if t > 0 else None
        insert_pose(self._buffer_values, t, self.problem.predict_pose(t, prev), prev)
        self.problem.admit(self._poses, only_fresh=True)
        entered = self._take_new(step)
        scheduled = t % self.config.isam2_update_every == 0
        if (scheduled or self._external.size()
                or (self.config.isam2_update_on_entry and entered)):
            self._flush(extra=scheduled)

    def _take_new(self, step: Step | None) -> list[int]:
        """The graph's new factors and values into the buffer (with the weak landmark priors)
        and, for long mode's window, filed with ``step`` (None: at :meth:`finish`, filed with
        the last step). Returns the ids of the landmarks that entered."""
        new = self.problem.take_new()
        self._gaussian = (self._gaussian and plain_gaussian(new.core)
                          and plain_gaussian(new.landmark))
        self._buffer.push_back(new.core)
        self._buffer.push_back(new.landmark)
        self._buffer_values.insert(new.landmark_values)
        sigma = self.config.landmark_prior_sigma_m
        weak = gtsam.NonlinearFactorGraph()
        if sigma is not None and new.landmark_ids:
            noise = gtsam.noiseModel.Isotropic.Sigma(2, float(sigma))
            for lid in new.landmark_ids:
                key = landmark_key(lid)
                weak.add(gtsam.PriorFactorPoint2(key, new.landmark_values.atPoint2(key), noise))
            self._buffer.push_back(weak)
        if self._chunks is not None:
            self._file(step, new.core, weak, new.landmark_ids)
        return list(new.landmark_ids)

    def _flush(self, extra: bool = True) -> None:
        """Hand the buffer (and queued external factors) to the solver; with ``extra``, the
        ``checkpoint_updates`` extra updates follow (on the schedule only)."""
        factors, values = self._buffer, self._buffer_values
        external, ext_values = self._external, self._external_values
        self._buffer, self._buffer_values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        self._external, self._external_values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        if self._batch:
            self.accepted.push_back(factors)
            self.accepted.push_back(external)
            start = gtsam.Values(self.estimate_values)
            start.insert(values)
            start.insert(ext_values)
            self.estimate_values, _ = solve_lm(self.accepted, start, self.config)
            return
        graph = gtsam.NonlinearFactorGraph(factors)
        graph.push_back(external)
        both = gtsam.Values(values)
        both.insert(ext_values)
        try:
            if self._long and self._window_b:
                if external.size():     # filed with the newest step's chunk
                    assert self._chunks is not None
                    self._chunks.add(self.problem.n_steps - 1, external, {})
                self._update_window(graph, both, extra)
                return
            full = self._long and self.problem.n_steps >= self.config.long_growth * self._long_full
            params = self._update_params(full)
            self._isam.update(graph, both, params)
            n_extra = (self.config.long_checkpoint_updates if self._long
                       else self.config.checkpoint_updates)
            for _ in range(n_extra if extra else 0):
                self._isam.update(gtsam.NonlinearFactorGraph(), gtsam.Values(), params)
            self.updates += 1
            self.accepted.push_back(graph)
            self.estimate_values = self._isam.calculateEstimate()
            if full:
                self._check_long()
            elif (extra and not self._long and self.config.long_after_steps is not None
                  and self.problem.n_steps >= self.config.long_after_steps):
                self._go_long()
            elif extra and not self._long and self.config.restart_cost_ratio is not None:
                self._restart_if_stuck(True)
            return
        except GTSAM_ERRORS as exc:
            self.failures.append(gtsam_error_line(exc))
        self.dropped_external += int(external.size())
        start = gtsam.Values(self.estimate_values)
        start.insert_or_assign(values)   # (a window update may have inserted them)
        if self._window_b:               # the whole graph from here on (long_window off)
            self._leave_window()
        self._recover(factors, start)

    # -- long recordings ------------------------------------------------------------------
    def _update_params(self, full: bool) -> gtsam.ISAM2UpdateParams:
        """The update's parameters: in long mode (unless ``full``) the poses older than
        ``long_lag_steps`` are not relinearised."""
        params = gtsam.ISAM2UpdateParams()
        if self._long and not full:
            upto = self.problem.n_steps - self.config.long_lag_steps
            for t in range(self._old_upto, max(upto, self._old_upto)):
                self._old.push_back(pose_key(t))
                if t > 0:
                    self._old.push_back(mid_key(t))
            self._old_upto = max(upto, self._old_upto)
            params.noRelinKeys = self._old
        elif self._long:   # the landmarks held from now until the next full update
            for lid in self.problem.landmark_ids:
                if lid not in self._old_landmarks:
                    self._old_landmarks.add(lid)
                    self._old.push_back(landmark_key(lid))
        return params

    def _go_long(self) -> None:
        """Enter long mode: with ``long_window``, the first whole-graph check and the window
        iSAM2 (:meth:`_check_window`); else (or if that fails) iSAM2 rebuilt with
        Gauss-Newton over the whole graph from the current estimate (one batch elimination),
        then the first check. If the rebuild fails, the mapper stays in its normal mode (a
        rebuild with the previous optimizer, :meth:`_recover`)."""
        self._long = True
        if self._chunks is not None:
            values = self.estimate_values
            try:
                self._check_window()
                return
            except GTSAM_ERRORS as exc:
                self.failures.append(gtsam_error_line(exc))
                self.estimate_values = values
                self._leave_window()
        self._isam = self._new_isam()
        try:
            self._isam.update(self.accepted, self.estimate_values)
            self.estimate_values = self._isam.calculateEstimate()
        except GTSAM_ERRORS as exc:
            self.failures.append(gtsam_error_line(exc))
            self._long = False
            self._recover(gtsam.NonlinearFactorGraph(), gtsam.Values(self.estimate_values))
            return
        self._check_long()

    def _check_long(self) -> None:
        """The whole-graph Gauss-Newton check of long mode (no step taken, what ``estimate()``
        reports until the graph changes), and the restart where it fails
        (:meth:`_restart_if_stuck`: iSAM2's Gauss-Newton can cycle between two points where a
        bearing is strongly nonlinear, e.g. a pose passing close to a landmark)."""
        self._long_full = self.problem.n_steps
        self._long_check = {**self._restart_if_stuck(False),
                            "checked_at_step": self.problem.n_steps}

    def _long_report(self, unbuffered: bool) -> dict[str, Any]:
        """What ``estimate()`` says of convergence in long mode (no whole-graph work per
        estimate): the last whole-graph check if it was made on this very graph and
        estimate, else ``converged`` None (not known) with the last check under ``last_*``
        and the reason in ``convergence``."""
        c = self._long_check
        if unbuffered and c["checked_at_step"] == self.problem.n_steps:
            return {**c, "convergence": "whole-graph Gauss-Newton check of this estimate"}
        return {"converged": None, "checked_at_step": c["checked_at_step"],
                "last_converged": c["converged"], "last_cost": c["cost"],
                "last_predicted_decrease": c["predicted_decrease"],
                "convergence": (f"not checked: long mode checks the whole graph when it has "
                                f"grown {self.config.long_growth:g}x (last at step "
                                f"{c['checked_at_step']}: "
                                f"{'passed' if c['converged'] else 'failed'})")}

    def _recover(self, factors: gtsam.NonlinearFactorGraph, start: gtsam.Values) -> None:
        """After a failed update (iSAM2 is unusable then): a new iSAM2 holding the accepted
        graph and ``factors`` at ``start``; if its undamped solve finds the system
        indeterminate, the graph is solved by (damped) LM and iSAM2 started from there; if
        that fails too, the mapper goes on in batch from the LM solution."""
        self.accepted.push_back(factors)
        self.rebuilds += 1
        for attempt in range(2):
            self._isam = self._new_isam()
            try:
                self._isam.update(self.accepted, start)
                self.estimate_values = self._isam.calculateEstimate()
                return
            except GTSAM_ERRORS as exc:
                self.failures.append(gtsam_error_line(exc))
            if attempt == 0:
                start, _ = solve_lm(self.accepted, start, self.config)
        self._batch = True
        self.estimate_values = gtsam.Values(start)

    # -- the map --------------------------------------------------------------------------
    def finish(self) -> None:
        """After the last step (:func:`bomgraph.mapper.run`). Every landmark still pending is
        tried once more on the current estimate (a step tries only those it saw, so one refused
        at its last sighting would stay out; ``gtsam-batch`` tries every one), and those let in
        go to the solver as at a step where landmarks entered. Long mode: the buffered steps in
        and the whole graph polished and checked once more, LM if it fails (:meth:`_check_window`,
        :meth:`_check_long`), unless just done on this graph (``info["converged"]`` never None;
        h161: the last step's check was kept after landmarks entered here). Normal mode:
        if the map :meth:`estimate` gives is unconverged (:meth:`_polish`), the buffered steps
        in as at a scheduled update, with its check and restart (not repeated where the last
        step's scheduled update already checked this very state, :meth:`_checked_here`).
        Batch mode: factors queued by :meth:`add_factors` go in (LM, as at an update).
        A second call with no step between does nothing (the first one's check moves the
        poses, so its admission made again could let in more landmarks)."""
        n = self.problem.n_steps
        if n == 0 or self._finished_n == n:
            return
        self._finish(n)
        self._finished_n = n

    def _finish(self, n: int) -> None:
        """:meth:`finish` after ``n`` steps."""
        graph_size = self.accepted.size()   # what this adds is checked, even after a check at n
        self._finish_entered = sorted(self.problem.admit(self._poses))   # every pending one
        if self._finish_entered:
            entered = self._take_new(None)    # (in batch, estimate() solves with the buffer)
            if not self._batch and (self._long or self._external.size()
                                    or (self.config.isam2_update_on_entry and entered)):
                self._flush(extra=False)
        if self._batch:
            if self._external.size():   # queued factors into the map, as at an update
                self._flush()
            return
        if not self._long:
            if self._external.size() or not self._polish()[2]["converged"]:
                if self._buffer_values.size() or self._external.size():
                    self._flush(extra=True)
                elif (self.config.restart_cost_ratio is not None
                      and not self._checked_here()):   # the last step updated, unchecked
                    self._restart_if_stuck(True)
            return
        if self._buffer.size() or self._buffer_values.size() or self._external.size():
            self._flush(extra=True)
        if self._batch or not self._long or (self._long_check.get("checked_at_step") == n
                                             and self.accepted.size() == graph_size):
            return   # (h161: landmarks let in here were reported checked, by the last step's)
        if self._window_b:
            try:
                self._check_window()
            except GTSAM_ERRORS as exc:   # as in _update_window: the whole graph from here on
                self.failures.append(gtsam_error_line(exc))
                self._leave_window()
                self._recover(gtsam.NonlinearFactorGraph(), gtsam.Values(self.estimate_values))
                if not self._batch:   # the recovered whole graph, checked as promised
                    self._check_long()
        else:
            self._check_long()

    def estimate(self) -> MapEstimate:
        if self.problem.n_steps == 0:
            return MapEstimate.empty(reason="no steps yet")
        report = None
        if self._batch:
            graph, values = self._with_buffer()
            values, report = solve_lm(graph, values, self.config)
            values, check = self._polish_check(graph, values)
        elif self._long:
            graph, values = self._with_buffer()
            check = self._long_report(graph is self.accepted)
        else:
            graph, values, check = self._polish()
        if report is not None:
            check["converged"] = check["converged"] and report.converged
        mode = "batch" if self._batch else ("isam2-long" if self._long else "isam2")
        if self._long and self._window_b:
            check.update({"window_start": self._window_b,
                          "window_rebuilds": self.window_rebuilds})
        info = {**check, "mode": mode, "isam2_updates": self.updates,
                "update_failures": len(self.failures), "rebuilds": self.rebuilds,
                "lm_restarts": self.lm_restarts,
                "dropped_external_factors": self.dropped_external}
        if self._finish_entered:
            info["entered_at_finish"] = list(self._finish_entered)
        if self.failures:
            info["last_failure"] = self.failures[-1]
        if self._chunks is not None and self._chunks.marginal_failure:
            info["window_marginal_failure"] = self._chunks.marginal_failure
        return estimate_from_values(self.problem, values, graph, info,
                                     self.config.covariances)


__all__ = ["Isam2Config", "Isam2Mapper", "isam2_params", "polish"]
