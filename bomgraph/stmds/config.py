"""Options of BOM-STMDS (paper section III) and its named presets.

One frozen, flat dataclass: every field is an option name a user passes as ``--option
name=value`` (or a factory keyword), so nesting the fields in groups would only add a second
spelling of each. The defaults reproduce the paper (with the corrected fusion rule);
:data:`StmdsConfig.PRESETS` names every other variant the experiments and the README use.
Measured numbers behind the choices are in ``docs/measurements.md``.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any, ClassVar, Mapping

import numpy as np

from ..checks import is_integer
from ..config import Presets, requirement
from .distances import FUSION_RULES

METHODS = ("cs", "smacof")
WEIGHTS = ("binary", "inverse-variance")
INITS = ("best", "previous", "classical")
TRI_METHODS = ("pair", "lsq", "ba")
ROBOT_RANGES = ("pairwise", "all-poses")

#: Windowed triangulation on the paper's simulation (``scripts/bench_stmds_window.py``).
_WINDOW: dict[str, Any] = {"tri_window": 6, "tri_stride": 1, "fusion": "scale-free",
                           "weights": "inverse-variance", "min_count": 3,
                           "max_range_factor": 1.3, "robot_ranges": "all-poses"}

#: What the recording settings share: fuse every window estimate, inverse-variance weights,
#: SMACOF from both starts at every map (the lower weighted stress kept; the runner-up is a
#: start of the next map too).
_RECORDING: dict[str, Any] = {"fusion": "scale-free", "weights": "inverse-variance",
                              "min_count": 1, "robot_ranges": "all-poses",
                              "smacof_restart_every": 1, "smacof_keep": 2}



def _whole(v: Any) -> bool:
    """A whole number (an integer, or a finite float with no fraction), not a bool: what the
    integer options accept without ``int()`` raising on NaN, infinity, None or a string."""
    return (isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_))
            and math.isfinite(v) and float(v).is_integer())

@dataclass(frozen=True)
class StmdsConfig(Presets):
    """Options of BOM-STMDS; the defaults are the paper's (with the corrected fusion rule).

    Attributes
    ----------
    method : {"cs", "smacof"}
        Method 1 (DMC-SPL + classical scaling, III-D.1) or Method 2 (weighted SMACOF from
        ``smacof_from_t``, III-D.2). Method 1 places the robot positions by trilateration
        against the landmark map, Method 2 reconstructs them jointly (eq. 7).
    smacof_from_t : int
        First step at which Method 2 uses SMACOF (the paper: 50; classical scaling before).
    fusion : str
        Distance fusion rule (III-C), one of ``distances.FUSION_RULES``: ``"paper"`` is eq. 3-4
        taken literally, ``"relative"`` and ``"scale-free"`` (the default) the corrected rules.
    min_count : int
        Instantaneous estimates a pair needs (without a prior) to count as known.
    baseline_steps : tuple of int
        Step gaps ``k`` to triangulate over (III-B): the pose ``k`` steps back and now, with the
        chained odometry and its covariance. The paper uses consecutive steps, ``(1,)``.
    min_parallax_rad : float
        Gate: least angle between a landmark's two rays (radians).
    max_range_factor : float
        Gate: largest depth as a multiple of the header's ``sensor_range_m`` (ignored when the
        header has none, unless ``max_range_m`` is given).
    max_range_m : float or None
        Gate: largest depth in metres (overrides ``max_range_factor``).
    max_relative_range_sigma : float
        Gate: largest first-order relative std. dev. of a landmark's depth (``inf``: off).
        With ``tri_method="ba"`` windows: a landmark is mapped once some window triangulates
        it with its point's largest std. dev. (its 2 x 2 block of the bundle's covariance:
        the rays' actual geometry and the window's bearing sigma) at most this fraction of
        its mean range (``bundle.relative_range_sigma``); its pairs from every window are
        fused either way. Off in every preset (``docs/measurements.md``: on MRCLAM6 robot 4
        it maps 9 landmarks at 7.8 cm instead of 13 at 34 cm, but it widens the keyframing
        ratios).
    weights : {"binary", "inverse-variance"}
        SMACOF weights: 1 for every known pair (the paper) or 1 / variance of the fused
        distance (normalised to mean 1).
    smacof_init : {"best", "previous", "classical"}
        Warm start of SMACOF: the previous scheduled map (the method's own, made every
        ``mapper.WARM_EVERY`` steps whether or not ``estimate()`` was called; landmarks new to
        it placed by the classical-scaling map aligned onto it), the DMC-SPL classical-scaling
        map (the paper), or both, keeping the lower weighted stress ("best"; the classical
        start is tried at the first scheduled SMACOF map and every ``smacof_restart_every``-th
        after it).
    smacof_restart_every : int
        With ``smacof_init="best"``: SMACOF also starts from the classical-scaling map when
        the number of scheduled SMACOF maps made before is a multiple of this, keeping the
        start that reaches the lower weighted stress (the objective SMACOF minimises). 1 (the
        recording settings): every map tries both starts, so the local minimum kept depends
        on the data alone, not on where a map falls in a count; 5 is the paper setting's.
    smacof_keep : {1, 2}
        SMACOF maps kept as warm starts of the next map: the lowest-stress one, or also the
        runner-up of its starts (2, the recording settings: a beam of two local minima, as
        the lower stress now can lead to a higher one later; ``docs/measurements.md``).
    landmark_mds_above : int
        Method 2 maps with more landmarks than this start SMACOF from landmark MDS (shortest
        paths from ``n_pivots`` pivots only) instead of the full DMC-SPL + classical scaling.
    n_pivots : int
        Pivots of landmark MDS.
    smacof_max_iter, smacof_tol, smacof_relaxation
        SMACOF iterations, relative stress tolerance, over-relaxation in (0, 2) (de Leeuw and
        Heiser: the same stationary points in about half the iterations; 1.0 is the textbook
        Guttman step).
    min_degree : int
        Landmarks need this many known distances (a ``min_degree``-core of the graph) to be
        mapped; 3 locates a point in the plane.
    map_unobserved : bool
        Also map landmarks held by priors alone (off: priors only constrain the landmarks the
        robot has triangulated).
    localise : bool
        Extend the matrix with the last ``n_robot_poses`` robot positions (III-E), return poses.
    n_robot_poses : int
        The paper's p (6): robot positions in the localisation.
    robot_ranges : {"pairwise", "all-poses"}
        Robot-landmark distances from the two-pose triangulations, fused per (pose, landmark)
        (the paper), or from one triangulation of each landmark over all ``n_robot_poses``
        dead-reckoned poses. Windowed triangulation (``tri_window``) needs ``"all-poses"``.
    tri_window : int or None
        Windowed triangulation in place of ``baseline_steps``: windows of ``tri_window`` poses
        (``window.triangulate_window``), every pair of a window's landmarks gives one squared
        distance with its first-order variance over the whole odometry chain and the bearings.
        ``2`` is the paper's consecutive rule exactly; ``None`` (default) uses
        ``baseline_steps``. Takes the relative depth gate with ``tri_method="ba"`` only.
    tri_stride : int or None
        Steps between windows; ``None``: ``tri_window - 1`` (windows share their end pose).
        With overlapping windows every reading enters ``c = ceil((tri_window - 1) /
        tri_stride)`` windows and each estimate's variance is inflated by ``c``.
    tri_method : {"pair", "lsq", "ba"}
        How a window triangulates a landmark: its two rays furthest apart ("pair"), all its
        rays by least squares on the bearings ("lsq", ``window.triangulate_window_lsq``), or a
        local bundle adjustment of the window's poses and landmarks ("ba",
        ``bundle.bundle_adjust_window``).
    tri_outlier_sigma : float or None
        ``tri_method="ba"``: rays whose residual exceeds this many bearing std. devs. are
        dropped (the worst first, the window solved again); None keeps every ray.
    tri_grow : int
        ``tri_method="ba"``: the window is solved on prefixes growing by this many poses.
    tri_min_depth_m : float
        ``tri_method="ba"``: landmarks closer than this (metres) to a pose that saw them are
        refused.
    tri_estimate_sigma : bool
        ``tri_method="ba"``: each window re-estimates the bearing std. dev. from its own
        residuals (a robust scale, ``bundle.bundle_adjust_window``), so its weights, outlier
        test and covariance do not depend on how the stream's sigma was calibrated.
    tri_robust_start : bool
        ``tri_method="ba"``: a landmark the window's starting triangulation refuses is started
        again without the one ray that points away from where its other rays put it, seen
        from further than the robot's own step (``bundle.bundle_adjust_window``'s
        ``robust_start``): one misidentified detection no longer refuses its landmark from
        every window that holds it (issue 15, MRCLAM6 robot 5, ``docs/measurements.md``).
    tri_parallax_rad : float or None
        Windows measured in geometry, not in keyframes (in place of ``tri_window``, issue 15):
        a window closes once the ``tri_parallax_quantile`` of the parallax of the landmarks it
        saw (``geometry.direction_span`` of their dead-reckoned ray directions, at least three
        landmarks) reaches this angle, and no sooner than ``1 / tri_overlap`` of the last
        window's path after its end (``window.WindowSchedule``).
    tri_parallax_quantile : float
        Geometric windows: the quantile of the landmarks' parallax that must reach
        ``tri_parallax_rad`` (0.5: the median landmark; 0.25: three landmarks in four).
    tri_window_m : float or None
        Windows measured in geometry: a window also closes once the path across it reaches
        this many metres (alone: windows of a fixed path length).
    tri_overlap : float
        Geometric windows: the next window starts ``1 / tri_overlap`` of the window's path
        further on, so every reading enters about ``ceil(tri_overlap)`` windows (and each
        estimate's variance is inflated by that).
    tri_max_poses : int
        Geometric windows: at most this many poses (caps the bundle's cost on any keyframing).
    tri_prefixes : int
        Geometric windows with ``tri_method="ba"``: the bundle grows on prefixes ending every
        ``1 / tri_prefixes`` of the last closed window's path (in a first window: each
        ``j / tri_prefixes`` of ``tri_parallax_rad`` reached; ``tri_grow`` measured in path, not
        poses), fixed as the steps arrive so an estimate resumes the open window's bundle
        from its last prefix (``window.WindowSchedule.prefix_ends``).
    """

    #: name -> field overrides; "paper" is the defaults.
    PRESETS: ClassVar[Mapping[str, Mapping[str, Any]]] = {
        "paper": {},
        # 4-step triangulation, the "relative" rule, inverse-variance weights, 1.3 x range gate
        "improved": {"baseline_steps": (4,), "fusion": "relative",
                     "weights": "inverse-variance", "max_range_factor": 1.3},
        "window": _WINDOW,
        "window-lsq": {**_WINDOW, "tri_method": "lsq", "tri_window": 10},
        # the README's best row
        "window-ba": {**_WINDOW, "tri_method": "ba", "tri_window": 10, "tri_stride": 3},
        # 100-pose bundle windows, a new one every 50 steps, a pair known from its second
        # window estimate (issue 15's paper target; chosen on the design of seed 1, reported
        # on seed 0 by `bomgraph compare --config long-windows`)
        "window-ba-long": {**_WINDOW, "tri_method": "ba", "tri_window": 100, "tri_stride": 50,
                           "min_count": 2},
        # recordings (issue 15): windows measured in geometry -- one closes when three in four
        # of the landmarks it saw have rays spanning 0.3 rad (17 degrees) of directions,
        # windows start and end a sixth of their path apart -- solved by local bundle
        # adjustment with the bearing sigma re-estimated per window: the same windows and
        # weights on any keyframing and any sigma calibration; a ray pointing away from its
        # landmark's other rays is an outlier of the start, not a reason to refuse the landmark
        "real": {"tri_parallax_rad": 0.3, "tri_parallax_quantile": 0.25, "tri_overlap": 6.0,
                 "tri_method": "ba", "tri_estimate_sigma": True, "tri_robust_start": True,
                 **_RECORDING},
        # issue 8's recording setting, counted in keyframes (60 of them, a new one every 10):
        # tuned on MRCLAM6 as `bomgraph import mrclam` keyframes it, 5-10x worse on a denser
        # keyframing of the same data
        "real-keyframes": {"tri_window": 60, "tri_stride": 10, "tri_method": "ba",
                           "tri_grow": 3, **_RECORDING},
    }

    method: str = "smacof"
    smacof_from_t: int = 50
    fusion: str = "scale-free"
    min_count: int = 5
    min_degree: int = 3
    baseline_steps: tuple[int, ...] = (1,)
    min_parallax_rad: float = math.radians(1.0)
    max_range_factor: float = 2.0
    max_range_m: float | None = None
    max_relative_range_sigma: float = math.inf
    weights: str = "binary"
    smacof_init: str = "best"
    smacof_restart_every: int = 5
    smacof_keep: int = 1
    landmark_mds_above: int = 300
    n_pivots: int = 50
    smacof_max_iter: int = 300
    smacof_tol: float = 1e-5
    smacof_relaxation: float = 1.8
    map_unobserved: bool = False
    localise: bool = False
    n_robot_poses: int = 6
    robot_ranges: str = "pairwise"
    tri_window: int | None = None
    tri_stride: int | None = None
    tri_method: str = "pair"
    tri_outlier_sigma: float | None = 4.0
    tri_min_depth_m: float = 0.05
    tri_grow: int = 5
    tri_estimate_sigma: bool = False
    tri_robust_start: bool = False
    tri_parallax_rad: float | None = None
    tri_parallax_quantile: float = 0.5
    tri_window_m: float | None = None
    tri_overlap: float = 6.0
    tri_max_poses: int = 400
    tri_prefixes: int = 20

    @property
    def windowed(self) -> bool:
        """Windowed triangulation, counted in keyframes or measured in geometry."""
        return self.tri_window is not None or self.geometric_windows

    @property
    def geometric_windows(self) -> bool:
        """Windows measured in parallax and / or path (``tri_parallax_rad``, ``tri_window_m``)."""
        return self.tri_parallax_rad is not None or self.tri_window_m is not None

    def __post_init__(self) -> None:
        need = requirement("StmdsConfig")

        need(self.method in METHODS, f"method must be one of {METHODS}, got {self.method!r}")
        need(self.fusion in FUSION_RULES,
             f"fusion must be one of {FUSION_RULES}, got {self.fusion!r}")
        need(self.weights in WEIGHTS, f"weights must be one of {WEIGHTS}, got {self.weights!r}")
        need(self.smacof_init in INITS,
             f"smacof_init must be one of {INITS}, got {self.smacof_init!r}")
        # integers as resolve() takes them (a direct StmdsConfig(...) too: no int(nan) raised)
        every = self.smacof_restart_every
        need(is_integer(every) and every >= 1,
             f"smacof_restart_every must be an integer >= 1, got {every!r:.40}")
        need(is_integer(self.smacof_keep) and self.smacof_keep in (1, 2),
             f"smacof_keep must be 1 or 2, got {self.smacof_keep!r:.40}")
        need(self.smacof_from_t >= 0, "smacof_from_t must be >= 0")
        need(self.min_count >= 1, "min_count must be >= 1")
        need(self.min_degree >= 1, "min_degree must be >= 1")
        need(isinstance(self.baseline_steps, (tuple, list, np.ndarray))
             and all(_whole(k) for k in self.baseline_steps),
             f"baseline_steps must be whole numbers of steps, got {self.baseline_steps!r:.60}")
        object.__setattr__(self, "baseline_steps", tuple(int(k) for k in self.baseline_steps))
        need(len(self.baseline_steps) >= 1 and all(k >= 1 for k in self.baseline_steps)
             and len(set(self.baseline_steps)) == len(self.baseline_steps),
             "baseline_steps must be distinct step gaps >= 1, e.g. (1,) or (5,)")
        need(0 <= self.min_parallax_rad < math.pi / 2, "min_parallax_rad must be in [0, pi/2)")
        need(self.max_range_factor > 0, "max_range_factor must be > 0")
        need(self.max_range_m is None or self.max_range_m > 0, "max_range_m must be > 0")
        need(self.max_relative_range_sigma > 0, "max_relative_range_sigma must be > 0")
        need(self.smacof_max_iter >= 0, "smacof_max_iter must be >= 0")
        need(self.landmark_mds_above >= 3, "landmark_mds_above must be >= 3")
        need(self.n_pivots >= 3, "n_pivots must be >= 3")
        need(self.smacof_tol >= 0, "smacof_tol must be >= 0")
        need(0 < self.smacof_relaxation < 2, "smacof_relaxation must be in (0, 2)")
        need(self.n_robot_poses >= 2, "n_robot_poses (p) must be >= 2")
        need(self.robot_ranges in ROBOT_RANGES,
             f"robot_ranges must be one of {ROBOT_RANGES}, got {self.robot_ranges!r}")
        need(self.tri_stride is None or self.tri_window is not None,
             "tri_stride needs tri_window")
        need(self.tri_method in TRI_METHODS,
             f"tri_method must be one of {TRI_METHODS}, got {self.tri_method!r}")
        need(self.tri_method == "pair" or self.windowed,
             f"tri_method={self.tri_method!r} needs tri_window (or tri_parallax_rad / "
             f"tri_window_m)")
        need(self.tri_parallax_rad is None or 0 < self.tri_parallax_rad <= math.pi / 2,
             "tri_parallax_rad must be in (0, pi/2] (effective parallax)")
        need(0 <= self.tri_parallax_quantile <= 1, "tri_parallax_quantile must be in [0, 1]")
        need(self.tri_window_m is None or self.tri_window_m > 0, "tri_window_m must be > 0")
        need(self.tri_overlap >= 1, "tri_overlap must be >= 1 (windows per reading)")
        need(_whole(self.tri_max_poses) and self.tri_max_poses >= 2,
             "tri_max_poses must be an integer >= 2")
        need(_whole(self.tri_prefixes) and self.tri_prefixes >= 1,
             "tri_prefixes must be an integer >= 1")
        need(not (self.geometric_windows and self.tri_window is not None),
             "give tri_window (keyframes) or tri_parallax_rad / tri_window_m (geometry), not "
             "both")
        need(self.tri_min_depth_m >= 0, "tri_min_depth_m must be >= 0")
        need(_whole(self.tri_grow) and self.tri_grow >= 1,
             "tri_grow must be an integer >= 1")
        need(self.tri_outlier_sigma is None or self.tri_outlier_sigma > 0,
             "tri_outlier_sigma must be > 0 or None")
        if self.tri_window is not None:
            need(_whole(self.tri_window) and self.tri_window >= 2,
                 f"tri_window must be an integer >= 2 (poses per window), got "
                 f"{self.tri_window!r}")
            object.__setattr__(self, "tri_window", int(self.tri_window))
        if self.windowed:
            need(self.baseline_steps == (1,),
                 "tri_window replaces baseline_steps: leave baseline_steps=(1,)")
            if self.tri_stride is not None and self.tri_window is not None:
                need(_whole(self.tri_stride)
                     and 1 <= self.tri_stride <= self.tri_window,
                     f"tri_stride must be an integer in [1, tri_window], got "
                     f"{self.tri_stride!r}")
                object.__setattr__(self, "tri_stride", int(self.tri_stride))
            need(self.tri_method == "ba" or not math.isfinite(self.max_relative_range_sigma),
                 "windowed triangulation uses the relative depth gate with tri_method='ba' "
                 "only: leave max_relative_range_sigma=inf")
            need(not self.localise or self.robot_ranges == "all-poses",
                 "with tri_window, localisation needs robot_ranges='all-poses'")


__all__ = ["StmdsConfig", "METHODS", "WEIGHTS", "INITS", "TRI_METHODS", "ROBOT_RANGES"]
