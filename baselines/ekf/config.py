"""Configurations of the EKF baselines ``ekf`` and ``ekf-invdepth`` (paper section IV, Exp. 2).

:class:`BearingEkfConfig` holds the fields both filters share; :class:`EkfConfig` (Bailey's
constrained initialisation) and :class:`InverseDepthConfig` (Civera's undelayed inverse depth)
add their own. Each names its presets in one ``PRESETS`` dict (:class:`bomgraph.config.Presets`):
``"paper"``, the defaults, reproduce the paper's setup; ``"real"`` is for recordings (MRCLAM6,
the g2o set): every bearing used whatever its nonlinearity index (after a blind turn the
bearings to mapped landmarks are the ones that bring the heading back), two iterations of the
update, restarts after three gated bearings in a row, for ``ekf`` inverse-depth
candidates, and for ``ekf-invdepth`` the depth's relative std. dev. in the test that puts a
feature on the map. The measurements behind them are in docs/measurements.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Mapping

import numpy as np

from bomgraph.config import Presets
from bomgraph.errors import ConfigError

from .range_prior import RHO_PRIORS
from .refusals import MAX_EKF_SIGMA
from .robust import ROBUST_UPDATES


#: The linearisations of :attr:`BearingEkfConfig.jacobians`.
JACOBIANS = ("oc", "fej", "plain")

#: The choices of :attr:`BearingEkfConfig.bearing_variance_scale`.
BEARING_VARIANCE_SCALES = ("fixed", "innovation")


@dataclass(frozen=True)
class BearingEkfConfig(Presets):
    """The fields both EKF baselines share.

    gate_probability : chi-square 1-dof probability of the per-bearing Mahalanobis gate
        (threshold ``chi2.ppf(p, 1)``; 1 disables the gate). Gated bearings are counted in
        ``info["gated_bearings"]``.
    initial_pose_sigma : std. dev. ``(sigma_x_m, sigma_y_m, sigma_psi_rad)`` of the first pose
        (zeros anchor the map frame to it).
    max_bearing_nonlinearity : bearings with a larger nonlinearity index
        ``(C_rr C_pp)^(1/4) / |r|`` (:func:`~baselines.ekf.models.second_order_variance`) are
        not used (``inf``: all are); counted in ``info["nonlinear_bearings"]``.
    rho_init_per_m, rho_sigma_per_m : prior inverse depth of a new inverse-depth feature and
        its std. dev., 1/m; None derives them from the header's sensor range ``R``: ``2/R``
        and ``1/R``, so the 2-sigma interval runs from infinity (Civera's rule) to ``R/4``;
        Civera's ``0.1`` and ``0.5`` per metre when the range is unknown.
    rho_prior : ``"range"`` (every preset): that prior. ``"empirical"``: the header's range is
        not used; the prior starts at Civera's ``0.1 +- 0.5`` per m (or the two options above)
        and, once one feature is Euclidean (``EMPIRICAL_MIN``), is estimated from the inverse
        depths of the converted features at conversion, the features still in inverse depth
        moved to it by a pseudo-measurement (:mod:`baselines.ekf.range_prior`).
    iterations : 1: the EKF update; more: the iterated EKF
        (:meth:`~baselines.ekf.filter.BearingEkf.update`).
    max_state : the largest filter state allowed (robot pose, landmarks ``[x, y]``, pose
        clones, inverse-depth features ``[x0, y0, theta, rho]``); the covariance is dense,
        ``8 n^2`` bytes (4000: 128 MB) and an update costs ``O(n^2)`` per bearing. A step that
        would exceed it is refused (:class:`~baselines.ekf.filter.StateLimitError`, before
        anything is allocated); raise it with ``--option max_state=N``.
    restart_after_gated : an inverse-depth feature whose bearings fail the gate this many
        times in a row is dropped and started again from the current sighting (its first
        bearing was an outlier); counted in ``info["restarted"]``. None: never. Only steps at
        which another bearing passed the gate count (a step whose bearings all fail leaves
        the count as it is): when every bearing fails, the robot's predicted pose is the
        likelier culprit (an odometry fault), and a restart would anchor the feature there.
    correlated_fraction : ``c`` in ``[0, 1)``, the share of the bearing variance that is a
        per-landmark error correlated between sightings from similar viewing geometry
        (:mod:`baselines.ekf.coloured`: a Gauss-Markov state per landmark, augmented into the
        filter); 0: white bearing errors (the paper's simulation).
    correlation_length_rad : ``L``, the change of viewing geometry (parallax at the landmark
        plus the robot's turn, rad) over which that correlation falls by ``e``.
    jacobians : how the predict and the bearing rows are linearised against the spurious
        information of EKF-SLAM (Huang, Mourikis and Roumeliotis): ``"oc"``, the
        observability-constrained EKF (IJRR 2010; rows near the model's Jacobian at the
        current estimate, constrained to ``h N = 0``, :meth:`~baselines.ekf.slam.EkfSlam.
        _constrain`); ``"fej"``, first-estimate Jacobians (ICRA 2008, ISER 2008: a Euclidean
        landmark's row evaluated at its first estimate and the pose's prior, inverse-depth
        rows as in ``"oc"``); both with the first-estimate predict. ``"plain"``: the model's
        own Jacobians at the current estimate (the standard EKF, which gains information
        along global rotation).
    max_predict_turn_rad : a step whose odometry turns by more than this is predicted in
        ``k = ceil(|dpsi| / max_predict_turn_rad)`` equal sub-steps along its
        constant-curvature arc (:func:`bomgraph.geometry.arc_root`), each with the step's
        sigma over ``sqrt(k)``: the heading noise then enters along the turn, not as one
        linearisation of a large rotation (recordings keyframed sparsely have blind steps of
        2-3 rad). None (every preset): one predict per step.
    path_heading_noise : the odometry covariance of a step also gets the translation error
        its heading error makes when it accumulates along the step's chord
        (:func:`~baselines.ekf.models.path_heading_noise`, ``sigma_psi^2 l^2 / 3`` across the
        chord, correlated with the heading): for streams whose per-component odometry
        sigmas leave it out (keyframed recordings with long blind steps). False (every
        preset): ``Sigma_u = diag(sigma_u^2)``.
    wide_prior_heading_sd_rad : a bearing update whose prior robot heading std. dev. (rad)
        exceeds this is iterated ``wide_prior_iterations`` times instead of ``iterations``
        (the iterated EKF of :meth:`~baselines.ekf.filter.BearingEkf.update`: iterates with
        the model's own Jacobians, the last step with the observability-constrained rows):
        Gauss-Newton where the prior is wide, the plain update elsewhere. None (every
        preset): ``iterations`` for every update.
    wide_prior_iterations : the iterations of such an update (an integer >= 1).
    bearing_variance_scale : ``"fixed"`` (every preset): a bearing's variance in the gate and
        the update is the header's ``sigma^2`` (times ``1 - c`` with coloured errors) plus the
        second-order term. ``"innovation"``: the ``sigma^2`` part is multiplied by a scale
        ``lambda >= 1`` estimated online by covariance matching on the normalised innovation
        squared (NIS). Every usable bearing ``k`` (within ``max_bearing_nonlinearity``, before
        the gate) keeps its squared innovation ``y_k^2`` (rad^2) and ``a_k = H_k P H_k^T +
        var_k - sigma^2`` (rad^2: the predicted-state and second-order parts, which the scale
        leaves alone) from its own update. ``lambda`` solves ``median_k(y_k^2 / (a_k + lambda
        sigma^2)) = chi2.ppf(0.5, 1) = 0.4549`` (the median NIS of a consistent filter) over
        all bearings so far, by one fixed-point step per update, ``lambda <- max(1, lambda *
        median_k(NIS_k(lambda)) / 0.4549)``, from ``lambda = 1``, with this step's bearings
        included; the step's gate and update then use ``var_k + (lambda - 1) sigma^2``. (With
        ``a_k = 0`` one step solves it; the map ``lambda -> lambda NIS(lambda)`` grows more
        slowly than ``lambda``, so the steps approach the root.) The median (not the mean)
        keeps the outliers from inflating it; the floor at 1 only ever inflates; only the data
        seen so far are used, vectorised over them (``O(n)`` per update), deterministic. With
        coloured errors only the white part is scaled.
        Its last value is ``info["bearing_variance_scale"]``, its largest
        ``info["bearing_variance_scale_max"]``.
    robust_update : ``"none"`` (every preset): every bearing that passes the gate is used with
        its variance ``var_i``. ``"huber"``: an M-estimation update (:mod:`baselines.ekf.
        robust`). With ``S_i = H_i P H_i^T + var_i`` at the prior and ``y_n = y_i /
        sqrt(S_i)``, a bearing with ``|y_n| > robust_k`` gets the variance ``var_i + (|y_n| /
        robust_k - 1) S_i`` (its innovation variance becomes ``S_i |y_n| / robust_k``, so its
        correction follows Huber's psi, Karlgaard and Schaub's Huber-based filter written as
        a variance inflation); one with ``|y_n| <= robust_k`` is used exactly as before. It
        acts after ``bearing_variance_scale`` and before the gate, which stays the last line
        and decides as without it: a bearing past the gate on ``S_i`` keeps ``var_i`` and is
        gated (inflating it too would widen the gate to ``|y_n| > chi2.ppf(p, 1) /
        robust_k``; measured worse on simulated streams, docs/measurements.md). With
        ``robust_k >= sqrt(chi2.ppf(p, 1))`` (3.29 at 0.999) nothing changes. The weights
        are taken once at the prior (also for ``iterations > 1``). The bearings used with an
        inflated variance are counted in ``info["robust_downweighted"]``.
    robust_k : Huber's threshold, in units of the bearing's own innovation std. dev.
        ``sqrt(S_i)`` (a finite number > 0; used only with ``robust_update="huber"``).
    """

    gate_probability: float = 0.999
    initial_pose_sigma: tuple[float, float, float] = (0.0, 0.0, 0.0)
    max_bearing_nonlinearity: float = 0.2
    rho_init_per_m: float | None = None
    rho_sigma_per_m: float | None = None
    rho_prior: str = "range"
    iterations: int = 1
    restart_after_gated: int | None = None
    max_state: int = 4000
    correlated_fraction: float = 0.0
    correlation_length_rad: float = 0.05
    jacobians: str = "oc"
    max_predict_turn_rad: float | None = None
    path_heading_noise: bool = False
    wide_prior_heading_sd_rad: float | None = None
    wide_prior_iterations: int = 10
    bearing_variance_scale: str = "fixed"
    robust_update: str = "none"
    robust_k: float = 2.0

    def __post_init__(self) -> None:
        if self.robust_update not in ROBUST_UPDATES:
            raise ConfigError(f"robust_update must be one of {', '.join(ROBUST_UPDATES)} (every "
                              f"bearing at its variance; Huber's weights), got "
                              f"{self.robust_update!r}")
        rk = self.robust_k
        if isinstance(rk, bool) or not isinstance(rk, (int, float, np.integer, np.floating)) \
                or not (math.isfinite(rk) and rk > 0):
            raise ConfigError(f"robust_k must be a finite number > 0 (Huber's threshold in "
                              f"innovation std. devs.), got {rk!r}")
        if self.bearing_variance_scale not in BEARING_VARIANCE_SCALES:
            raise ConfigError(f"bearing_variance_scale must be one of "
                              f"{', '.join(BEARING_VARIANCE_SCALES)} (the header's sigma; "
                              f"scaled online from the innovations), got "
                              f"{self.bearing_variance_scale!r}")
        wide = self.wide_prior_heading_sd_rad
        if wide is not None and not (math.isfinite(wide) and wide >= 0):
            raise ConfigError(f"wide_prior_heading_sd_rad must be a finite number >= 0 or None "
                              f"(never), got {wide}")
        turn = self.max_predict_turn_rad
        if turn is not None and not (math.isfinite(turn) and turn > 0):
            raise ConfigError(f"max_predict_turn_rad must be a finite number > 0 or None (one "
                              f"predict per step), got {turn}")
        if self.jacobians not in JACOBIANS:
            raise ConfigError(f"jacobians must be one of {', '.join(JACOBIANS)} "
                              f"(observability-constrained, first estimates, the model's own), "
                              f"got {self.jacobians!r}")
        if not (math.isfinite(self.correlated_fraction) and 0 <= self.correlated_fraction < 1):
            raise ConfigError(f"correlated_fraction must be in [0, 1) (0: white bearing "
                              f"errors), got {self.correlated_fraction}")
        if not (math.isfinite(self.correlation_length_rad) and self.correlation_length_rad > 0):
            raise ConfigError(f"correlation_length_rad must be a finite number > 0, got "
                              f"{self.correlation_length_rad}")
        if not 0 < self.gate_probability <= 1:
            raise ConfigError(f"gate_probability must be in (0, 1] (1 disables the gate), got "
                              f"{self.gate_probability}")
        if len(self.initial_pose_sigma) != 3 or not all(     # as the odometry's (h151)
                0 <= s <= MAX_EKF_SIGMA for s in self.initial_pose_sigma):
            raise ConfigError(f"initial_pose_sigma must be 3 numbers in [0, "
                              f"{MAX_EKF_SIGMA:g}] (sigma_x_m, sigma_y_m, sigma_psi_rad), got "
                              f"{list(self.initial_pose_sigma)}")
        if not self.max_bearing_nonlinearity > 0:
            raise ConfigError(f"max_bearing_nonlinearity must be > 0 (inf: no limit), got "
                              f"{self.max_bearing_nonlinearity}")
        if self.rho_prior not in RHO_PRIORS:
            raise ConfigError(f"rho_prior must be one of {', '.join(RHO_PRIORS)} (from the "
                              f"header's sensor range; from the depths converged in the run), "
                              f"got {self.rho_prior!r}")
        for name in ("rho_init_per_m", "rho_sigma_per_m"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ConfigError(f"{name} must be a finite number > 0 or None (from the "
                                  f"sensor range), got {value}")
        for name in ("iterations", "restart_after_gated", "max_state", "wide_prior_iterations"):
            value = getattr(self, name)
            if not ((value is None and name == "restart_after_gated")
                    or (isinstance(value, (int, np.integer)) and value >= 1)):
                raise ConfigError(f"{name} must be an integer >= 1, got {value!r}")


#: The overrides of the ``"real"`` preset both filters share.
_REAL = {"max_bearing_nonlinearity": math.inf, "iterations": 2, "restart_after_gated": 3}


@dataclass(frozen=True)
class EkfConfig(BearingEkfConfig):
    """Options of ``ekf`` (Bailey's constrained initialisation), beside the shared ones.

    init_kl_max : a candidate is initialised when the KL divergence (nats) between the
        unscented and the linearised Gaussian of its Euclidean estimate is below this
        (Bailey's test: of the two-ray triangulation, or with ``candidates="inverse-depth"``
        of the feature's conversion to ``[x, y]``).
    inconsistent_parallax_rad : rays crossing behind the robot at more than this parallax
        make the candidate restart from the current sighting (an outlier anchor).
    max_pending_steps : a candidate still not initialised after this many steps restarts.
    candidates : ``"clones"`` (Bailey: a pose clone per sighting, the bearings wait until the
        candidate is initialised) or ``"inverse-depth"`` (the candidate is an inverse-depth
        feature, as in ``ekf-invdepth``, updated by every bearing at once; it joins the map
        as ``[x, y]`` when Bailey's test passes on its conversion).
    anchor_test : True (needs ``candidates="inverse-depth"``, as preset ``real``; False in
        every preset): each inverse-depth candidate's first (anchor) bearing, which no gate
        can test, is tested once the later sightings know its error at least as well as the
        anchor does (its leave-one-out residual, at the gate; before or after the feature
        joins the map), and a failing one is taken out of the filter
        (:mod:`baselines.ekf.anchor`).
    """

    PRESETS: ClassVar[Mapping[str, Mapping[str, Any]]] = {
        "paper": {},
        "real": {"candidates": "inverse-depth", **_REAL},
    }

    init_kl_max: float = 0.01
    inconsistent_parallax_rad: float = math.radians(15.0)
    max_pending_steps: int = 30
    candidates: str = "clones"
    anchor_test: bool = False

    def __post_init__(self) -> None:
        super().__post_init__()
        if not isinstance(self.anchor_test, (bool, np.bool_)):
            raise ConfigError(f"anchor_test must be true or false, got {self.anchor_test!r}")
        if self.anchor_test and self.candidates == "clones":
            raise ConfigError("anchor_test=true needs candidates='inverse-depth' (preset "
                              "'real'): the clone candidates keep their bearings outside the "
                              "filter")
        if not (self.init_kl_max > 0):
            raise ConfigError(f"init_kl_max must be > 0, got {self.init_kl_max}")
        if not 0 < self.inconsistent_parallax_rad < math.pi:
            raise ConfigError("inconsistent_parallax_rad must be in (0, pi)")
        if self.max_pending_steps < 1:
            raise ConfigError(f"max_pending_steps must be >= 1, got {self.max_pending_steps}")
        if self.correlated_fraction > 0 and self.candidates == "clones":
            raise ConfigError("correlated_fraction > 0 needs candidates='inverse-depth' (the "
                              "clone candidates keep their bearings outside the filter)")
        if self.rho_prior != "range" and self.candidates == "clones":
            raise ConfigError(f"rho_prior={self.rho_prior!r} needs candidates='inverse-depth' "
                              f"(preset 'real'): the clone candidates have no inverse depth")
        if self.candidates not in ("clones", "inverse-depth"):
            raise ConfigError(f"candidates must be 'clones' (Bailey: pose clones, the bearings "
                              f"wait) or 'inverse-depth' (updated at once, made Euclidean when "
                              f"Gaussian), got {self.candidates!r}")


@dataclass(frozen=True)
class InverseDepthConfig(BearingEkfConfig):
    """Options of ``ekf-invdepth`` (undelayed inverse depth), beside the shared ones.

    linearity_max : Civera's linearity index ``4 sigma_d / d |cos alpha|`` below which a
        feature becomes Euclidean.
    relative_depth_check : a feature still in inverse depth is on the map once the bearings
        have halved its prior std. dev. of ``rho`` (with a baseline across its ray); with
        True (preset ``"real"``) also its relative std. dev. ``sigma_rho / rho``, the
        depth's, against the prior's. ``sigma_rho`` is set by the parallax and hardly by
        ``rho``, so a feature whose ``rho`` is small (a far landmark, or one an update pulled
        towards 0) passed the first test alone with its depth as uncertain, relatively, as
        the prior's. The prior's ratio is 1/2 with ``"range"`` from a stated sensor range
        (so ``sigma_rho / rho <= 0.25``) and 5 with Civera's range-free ``0.1 +- 0.5`` per m,
        where the test admits nearly every feature. False (``"paper"``): the first test
        only, as the paper's runs were made.
    conversion_kl_max : a number (nats; preset ``"real"``: 0.01, the ``init_kl_max`` of
        ``ekf``'s candidates, not tuned here): a feature becomes Euclidean once Civera's index
        passes and Bailey's Gaussianity test on the conversion, the KL divergence between the
        unscented and the linearised Gaussian of ``[x, y]``, is at most this; None (preset
        ``"paper"``, as the paper's runs were made): Civera's index alone. The test is
        :func:`~baselines.ekf.models.invdepth_conversion_kl`, as the inverse-depth
        candidates of ``ekf`` use it. Civera's index asks whether the bearing is
        linear in ``[x, y]`` seen from the current pose (it passes whenever the robot views
        the anchor ray side-on or from afar, e.g. after a long blind step), not whether the
        feature's Gaussian survives the conversion: one converted with its depth still
        uncertain (``sigma_rho / rho`` 0.2-0.35) becomes an overconfident ``[x, y]`` block
        (docs/measurements.md, h159).
    """

    PRESETS: ClassVar[Mapping[str, Mapping[str, Any]]] = {
        "paper": {},
        "real": {**_REAL, "relative_depth_check": True, "conversion_kl_max": 0.01},
    }

    linearity_max: float = 0.1
    relative_depth_check: bool = False
    conversion_kl_max: float | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.linearity_max > 0:
            raise ConfigError("linearity_max must be > 0")
        kl = self.conversion_kl_max
        if kl is not None and (isinstance(kl, bool) or not isinstance(
                kl, (int, float, np.integer, np.floating)) or not (math.isfinite(kl) and kl > 0)):
            raise ConfigError(f"conversion_kl_max must be a finite number > 0 (nats) or None "
                              f"(Civera's index alone), got {kl!r}")
        if not isinstance(self.relative_depth_check, (bool, np.bool_)):
            raise ConfigError(f"relative_depth_check must be true or false, got "
                              f"{self.relative_depth_check!r}")


__all__ = ["BEARING_VARIANCE_SCALES", "BearingEkfConfig", "EkfConfig", "InverseDepthConfig", "JACOBIANS"]
