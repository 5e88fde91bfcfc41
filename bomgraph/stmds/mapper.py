"""BOM-STMDS as a Mapper: the online schedule of the paper (Algorithm 1, sections III-B to III-E).

Every step: triangulate the landmarks seen at ``t-1`` and ``t`` (III-B; ``baselines`` can
also pair ``t-k`` with ``t`` over the chained odometry), gate degenerate geometry, and fuse
every pair's instantaneous squared distance into the distance store (III-C; priors from the
stream header are the initial estimates). At every ``estimate()`` call: take the known pairs
(a prior, or ``min_count`` estimates), keep the landmarks with ``min_degree`` triangulated
distances (the 3-core: a point in the plane needs three) in the largest connected piece
(landmarks left out are named in ``info["left_out"]``), and reconstruct coordinates (III-D):

* Method 1 (``method="cs"``): DMC-SPL (shortest paths on distances) + classical scaling.
* Method 2 (``method="smacof"``): Method 1 while ``t < smacof_from_t`` (t = 10..40 with the
  paper's checkpoints), weighted SMACOF on the known pairs from ``t >= smacof_from_t`` (t = 50
  on), warm-started from the previous map (landmarks new to it are placed by the
  classical-scaling map aligned onto the previous one) and, every few maps, also from the
  classical-scaling map, keeping the lower stress.

Localisation (III-E, ``localise=True``): the last ``window`` (the paper's p = 6) robot
positions. Robot-robot distances come from dead reckoning the odometry inside the window;
robot-landmark distances are the triangulation depths ``r1`` (from pose ``t-k``) and ``r2``
(from pose ``t``), fused per (pose, landmark) with the same rule as the landmark pairs.
Method 2 reconstructs them jointly with the landmarks (the paper's extended matrix, eq. 7);
Method 1 by default maps the landmarks alone and then trilaterates each position against that
map (``robot_placement``), because DMC-SPL over the sparse robot rows distorts the map. A
heading is then found for every pose in the window by resection: the circular mean of
``atan2(landmark - robot) - bearing`` over the landmarks it saw. MDS cannot tell a map from its
mirror image; the bearings can, so a localising mapper reflects its output when the mirrored
resection fits the bearings better, and every pose is returned in a frame with the measured
(counter-clockwise) bearing convention.

``estimate().info`` reports: method, t, fusion, the numbers of stored / known / mapped pairs,
of triangulated and gated landmarks, the landmarks left out, the number of components, the
reconstruction used, SMACOF's iterations and start, Stress-1, and (localising) whether the
frame was reflected.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from ..angles import angle_residual, wrap_angle
from ..errors import ConfigError
from ..evaluate import align
from ..geometry import dead_reckon
from ..mapper import MapEstimate
from ..stream import Step, StreamHeader
from .bundle import WindowBundle, bundle_adjust_window, bundle_pair_squared_distances
from .completion import (largest_component, pivot_shortest_paths, prune_low_degree,
                         shortest_path_completion)
from .distances import (FUSION_RULES, DistanceStore, IdIndex, estimate_weights,
                        fused_from_sums)
from .mds import (LaplacianSolver, classical_scaling, landmark_scaling, smacof, stress1,
                  trilaterate)
from .triangulation import (compose_odometry, gate_points, pair_squared_distances,
                            range_variances, triangulate_rays, triangulate_window,
                            triangulate_window_lsq, window_pair_squared_distances)

METHODS = ("cs", "smacof")
WEIGHTS = ("binary", "inverse-variance")
INITS = ("best", "previous", "classical")
TRI_METHODS = ("pair", "lsq", "ba")


@dataclass(frozen=True)
class StmdsConfig:
    """Options of BOM-STMDS; the defaults are the paper's (with the corrected fusion rule).

    Attributes
    ----------
    method : {"cs", "smacof"}
        Method 1 (DMC-SPL + classical scaling) or Method 2 (SMACOF from ``smacof_from_t``).
    smacof_from_t : int
        First step at which Method 2 uses SMACOF (the paper: 50; classical scaling before).
    fusion : str
        Distance fusion rule, one of ``distances.FUSION_RULES``; ``"paper"`` is eq. 3-4 taken
        literally (it collapses, see the benchmark); the default is the corrected rule.
    min_count : int
        Instantaneous estimates a pair needs (without a prior) to count as known.
    baselines : tuple of int
        Step gaps ``k`` to triangulate over: the pose ``k`` steps back and now, with the
        chained odometry and its covariance. The paper uses consecutive steps, ``(1,)``; a
        longer baseline gives more parallax per unit of odometry noise.
    min_parallax_rad : float
        Gate: least angle between a landmark's two rays.
    max_range_factor : float
        Gate: largest depth as a multiple of the header's ``sensor_range_m`` (ignored when the
        header has none, unless ``max_range_m`` is given).
    max_range_m : float or None
        Gate: largest depth in metres (overrides ``max_range_factor``).
    max_relative_range_sigma : float
        Gate: largest first-order relative std. dev. of a landmark's depth (``inf``: off).
    weights : {"binary", "inverse-variance"}
        SMACOF weights: 1 for every known pair (the paper) or 1 / variance of the fused
        distance (normalised to mean 1).
    smacof_init : {"best", "previous", "classical"}
        Warm start of SMACOF: the previous map (landmarks new to it placed by the
        classical-scaling map aligned onto it), the DMC-SPL classical-scaling map (the paper),
        or both, keeping the result with the lower stress ("best": a fold-over carried along
        from an early map cannot persist). "best" restarts from the classical-scaling map at
        the first SMACOF estimate and every ``smacof_restart_every`` estimates after it.
    smacof_restart_every : int
        See ``smacof_init``.
    landmark_mds_above : int
        Method 2 maps with more landmarks than this start SMACOF from landmark MDS (shortest
        paths from ``n_pivots`` pivots only) instead of the full DMC-SPL + classical scaling;
        Method 1 always uses the full matrix (it is its answer, not a start).
    n_pivots : int
        Pivots of landmark MDS.
    smacof_max_iter, smacof_tol, smacof_relaxation
        SMACOF iterations, relative stress tolerance, over-relaxation in (0, 2). The
        over-relaxed Guttman step (de Leeuw and Heiser) converges to the same stationary
        points, never increases the stress and needs about half the iterations; 1.0 is the
        textbook step. (Measured: the same MPE to 0.01 cm on the 25 paper runs.)
    min_degree : int
        Landmarks need this many known distances (a ``min_degree``-core of the graph, see
        ``completion.prune_low_degree``) to be mapped; 3 locates a point in the plane.
    map_unobserved : bool
        Also map landmarks held by priors alone. Off by default: a landmark is mapped once it
        has ``min_degree`` triangulated distances (the map covers what the robot has measured)
        and priors only constrain the mapped landmarks; early on, landmarks hung on a few
        long prior edges are poorly determined and make the map worse, not better.
    dmc_keep_known : bool
        DMC-SPL replaces only the missing entries (True, the paper) or every entry by its
        shortest path (False, ISOMAP).
    localise : bool
        Extend the matrix with the last ``window`` robot positions (III-E) and return poses.
    window : int
        The paper's p (6).
    robot_ranges : {"pairwise", "window"}
        Robot-landmark distances from the sequential (two-pose) triangulations, fused per
        (pose, landmark) (the paper), or from one triangulation of each landmark over all the
        window's dead-reckoned poses (a longer baseline).
    tri_window : int or None
        Windowed triangulation (issue 8), in place of ``baselines``: the steps are cut into
        windows of ``tri_window`` poses, consecutive windows sharing their end pose (a new
        window every ``tri_window - 1`` steps). In each window every landmark seen from two of
        its poses or more is triangulated from its pair of rays with the largest parallax that
        passes the gates (``min_parallax_rad``, the depth gate), in the frame of the window's
        first pose, and every pair of landmarks of the window gives one squared distance with
        its first-order variance over the whole odometry chain and the four bearings
        (``triangulation.triangulate_window``). ``2`` is the paper's consecutive rule exactly;
        ``None`` (default) uses ``baselines``. The per-step cost is bounded by the window.
        Not combined with the relative depth gate nor with the pairwise robot ranges of
        localisation (use ``robot_ranges="window"``).
    tri_stride : int or None
        Steps between windows. ``tri_window``: disjoint windows (the increment between two
        windows is not used), independent estimates, and the fused variance matches a Monte
        Carlo of the estimator within 10 % (test). ``None`` (default): ``tri_window - 1``,
        windows that share their end pose (with ``tri_window=2`` the paper's rule): no
        odometry reading is used twice but the shared pose's bearings enter two windows with
        opposite signs in the parallax, so consecutive estimates are negatively correlated
        and the fused variance is conservative (measured up to 1.5x the actual spread). A
        shorter stride makes the windows overlap: every odometry reading (and most bearings)
        enters ``c = ceil((tri_window - 1) / tri_stride)`` windows, so each estimate's variance
        is inflated by ``c`` (the same information is not counted ``c`` times; with fully
        correlated repeats this is exact, with partly correlated ones conservative). The
        inflation scales all weights of a pair alike, so it changes the fused variance (and
        inverse-variance SMACOF weights between pairs only through the count), not the mean.
    tri_method : {"pair", "lsq"}
        How ``tri_window`` triangulates a landmark: from its two rays furthest apart in the
        window ("pair", :func:`~bomgraph.stmds.triangulation.triangulate_window`) or from all
        its rays in the window by least squares on the bearings ("lsq",
        :func:`~bomgraph.stmds.triangulation.triangulate_window_lsq`; the parallax gate is
        then on the angular span of the rays, the depth gate on every ray). The variance of a
        pair's squared distance is first order over every increment of the window and every
        bearing used, in both cases. "ba": the window's poses are estimated with its
        landmarks from the odometry and every bearing of the window (a local bundle
        adjustment, :func:`~bomgraph.stmds.bundle.bundle_adjust_window`), so the bearings
        correct the odometry's heading drift inside the window; the variance of a pair is that
        of the joint estimate (shared poses included); gross bearing outliers are dropped
        (``tri_outlier_sigma``).
    tri_outlier_sigma : float or None
        ``tri_method="ba"``: rays whose residual exceeds this many bearing std. devs. are
        dropped (the worst first, the window solved again); None keeps every ray.
    tri_grow : int
        ``tri_method="ba"``: the window is solved on prefixes growing by this many poses, each
        started from the one before (one solve from the whole odometry chain of a long window
        falls into wrong minima when the drift exceeds the parallax). Consecutive windows
        start from each other's solution for the poses they share.
    tri_min_depth_m : float
        ``tri_method="ba"``: landmarks estimated closer than this to a pose that saw them are
        refused (a landmark straight ahead has nearly collinear rays along which the fit can
        slide it onto the path).
    robot_placement : {"auto", "joint", "trilateration"}
        "joint" (the paper): the robot positions are rows of the extended matrix, reconstructed
        with the landmarks. "trilateration": the landmarks are mapped alone and each window
        position is then placed against them from its ranges (linear least squares + Gauss-
        Newton). "auto" is joint for Method 2 and trilateration for Method 1, where DMC-SPL
        over the robot rows (most robot-landmark entries are missing) distorts the landmark
        map (measured: landmark MPE 24.9 cm joint vs 12.4 cm without robots, 25 paper runs).
    """

    method: str = "smacof"
    smacof_from_t: int = 50
    fusion: str = "scale-free"
    min_count: int = 5
    min_degree: int = 3
    baselines: tuple[int, ...] = (1,)
    min_parallax_rad: float = math.radians(1.0)
    max_range_factor: float = 2.0
    max_range_m: float | None = None
    max_relative_range_sigma: float = math.inf
    weights: str = "binary"
    smacof_init: str = "best"
    smacof_restart_every: int = 5
    landmark_mds_above: int = 300
    n_pivots: int = 50
    smacof_max_iter: int = 300
    smacof_tol: float = 1e-5
    smacof_relaxation: float = 1.8
    map_unobserved: bool = False
    dmc_keep_known: bool = True
    localise: bool = False
    window: int = 6
    robot_ranges: str = "pairwise"
    robot_placement: str = "auto"
    tri_window: int | None = None
    tri_stride: int | None = None
    tri_method: str = "pair"
    tri_outlier_sigma: float | None = 4.0
    tri_min_depth_m: float = 0.05
    tri_grow: int = 5

    def __post_init__(self) -> None:
        def need(ok: bool, msg: str) -> None:
            if not ok:
                raise ConfigError(f"StmdsConfig: {msg}")

        need(self.method in METHODS, f"method must be one of {METHODS}, got {self.method!r}")
        need(self.fusion in FUSION_RULES,
             f"fusion must be one of {FUSION_RULES}, got {self.fusion!r}")
        need(self.weights in WEIGHTS, f"weights must be one of {WEIGHTS}, got {self.weights!r}")
        need(self.smacof_init in INITS,
             f"smacof_init must be one of {INITS}, got {self.smacof_init!r}")
        need(self.smacof_from_t >= 0, "smacof_from_t must be >= 0")
        need(self.min_count >= 1, "min_count must be >= 1")
        need(self.min_degree >= 1, "min_degree must be >= 1")
        object.__setattr__(self, "baselines", tuple(int(k) for k in self.baselines))
        need(len(self.baselines) >= 1 and all(k >= 1 for k in self.baselines)
             and len(set(self.baselines)) == len(self.baselines),
             "baselines must be distinct step gaps >= 1, e.g. (1,) or (5,)")
        need(0 <= self.min_parallax_rad < math.pi / 2, "min_parallax_rad must be in [0, pi/2)")
        need(self.max_range_factor > 0, "max_range_factor must be > 0")
        need(self.max_range_m is None or self.max_range_m > 0, "max_range_m must be > 0")
        need(self.max_relative_range_sigma > 0, "max_relative_range_sigma must be > 0")
        need(self.smacof_max_iter >= 0, "smacof_max_iter must be >= 0")
        need(self.smacof_restart_every >= 1, "smacof_restart_every must be >= 1")
        need(self.landmark_mds_above >= 3, "landmark_mds_above must be >= 3")
        need(self.n_pivots >= 3, "n_pivots must be >= 3")
        need(self.smacof_tol >= 0, "smacof_tol must be >= 0")
        need(0 < self.smacof_relaxation < 2, "smacof_relaxation must be in (0, 2)")
        need(self.window >= 2, "window (p) must be >= 2")
        need(self.robot_placement in ("auto", "joint", "trilateration"),
             "robot_placement must be 'auto', 'joint' or 'trilateration'")
        need(self.robot_ranges in ("pairwise", "window"),
             f"robot_ranges must be 'pairwise' or 'window', got {self.robot_ranges!r}")
        need(self.tri_stride is None or self.tri_window is not None,
             "tri_stride needs tri_window")
        need(self.tri_method in TRI_METHODS,
             f"tri_method must be one of {TRI_METHODS}, got {self.tri_method!r}")
        need(self.tri_method == "pair" or self.tri_window is not None,
             f"tri_method={self.tri_method!r} needs tri_window")
        need(self.tri_min_depth_m >= 0, "tri_min_depth_m must be >= 0")
        need(int(self.tri_grow) == self.tri_grow and self.tri_grow >= 1,
             "tri_grow must be an integer >= 1")
        need(self.tri_outlier_sigma is None or self.tri_outlier_sigma > 0,
             "tri_outlier_sigma must be > 0 or None")
        if self.tri_window is not None:
            need(int(self.tri_window) == self.tri_window and self.tri_window >= 2,
                 f"tri_window must be an integer >= 2 (poses per window), got "
                 f"{self.tri_window!r}")
            object.__setattr__(self, "tri_window", int(self.tri_window))
            need(self.baselines == (1,), "tri_window replaces baselines: leave baselines=(1,)")
            if self.tri_stride is not None:
                need(int(self.tri_stride) == self.tri_stride
                     and 1 <= self.tri_stride <= self.tri_window,
                     f"tri_stride must be an integer in [1, tri_window], got "
                     f"{self.tri_stride!r}")
                object.__setattr__(self, "tri_stride", int(self.tri_stride))
            need(not math.isfinite(self.max_relative_range_sigma),
                 "tri_window does not use the relative depth gate: leave "
                 "max_relative_range_sigma=inf")
            need(not self.localise or self.robot_ranges == "window",
                 "with tri_window, localisation needs robot_ranges='window'")

    @classmethod
    def improved(cls, **overrides: Any) -> "StmdsConfig":
        """The most accurate variant measured (``scripts/bench_stmds.py``), beyond the paper.

        Triangulation over a 4-step baseline (more parallax per unit of odometry noise), the
        ``"relative"`` fusion rule (near unbiased at that baseline), inverse-variance SMACOF
        weights and a depth gate at 1.3 x the sensor range. ``overrides`` replace fields.
        """
        base = cls(baselines=(4,), fusion="relative", weights="inverse-variance",
                   max_range_factor=1.3)
        return cls.with_options(base, **overrides)

    @classmethod
    def with_options(cls, base: "StmdsConfig | None" = None, **options: Any) -> "StmdsConfig":
        """``base`` (or the defaults) with ``options`` replaced; unknown names are refused."""
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(options) - names)
        if unknown:
            raise ConfigError(f"unknown BOM-STMDS option(s) {unknown}; known options: "
                              f"{sorted(names)}")
        return replace(base or cls(), **options)


class _GrowingFlags:
    """A boolean array indexed by dense landmark index that grows on assignment."""

    def __init__(self) -> None:
        self.array = np.zeros(64, bool)

    def __setitem__(self, idx: np.ndarray, value: bool) -> None:
        top = int(idx.max()) + 1 if idx.size else 0
        if top > len(self.array):
            grown = np.zeros(max(top, 2 * len(self.array)), bool)
            grown[:len(self.array)] = self.array
            self.array = grown
        self.array[idx] = value


class _PoseWindow:
    """The last ``p`` poses: odometry between them, their bearings and robot-landmark sums."""

    def __init__(self, size: int, fusion: str) -> None:
        self.size = size
        self.fusion = fusion
        self.t: list[int] = []
        self.odom: list[np.ndarray] = []        # odom[k] leads from pose k-1 to pose k
        self.sigma: list[np.ndarray] = []       # its std. devs.
        self.bearing_idx: list[np.ndarray] = []  # dense landmark indices seen at the pose
        self.bearings: list[np.ndarray] = []
        self.rl_idx: list[np.ndarray] = []       # robot-landmark estimates: landmark index
        self.rl_w: list[np.ndarray] = []         # sum of 1 / var
        self.rl_wd: list[np.ndarray] = []        # sum of d / var

    def reset(self) -> None:
        self.__init__(self.size, self.fusion)  # type: ignore[misc]

    def push(self, t: int, odom: np.ndarray | None, sigma: np.ndarray | None, idx: np.ndarray,
             bearings: np.ndarray) -> None:
        if odom is None and self.t:
            self.reset()
        self.t.append(t)
        self.odom.append(np.zeros(3) if odom is None else np.asarray(odom, float))
        self.sigma.append(np.zeros(3) if sigma is None else np.asarray(sigma, float))
        self.bearing_idx.append(idx)
        self.bearings.append(bearings)
        self.rl_idx.append(np.zeros(0, np.int64))
        self.rl_w.append(np.zeros(0))
        self.rl_wd.append(np.zeros(0))
        if len(self.t) > self.size:
            for lst in (self.t, self.odom, self.sigma, self.bearing_idx, self.bearings,
                        self.rl_idx, self.rl_w, self.rl_wd):
                del lst[0]

    def add_ranges(self, k: int, idx: np.ndarray, dist: np.ndarray, var: np.ndarray) -> None:
        """Fold robot-landmark distance estimates into pose ``k`` of the window, weighted by
        the same fusion rule as the landmark pairs (``var(r^2) = 4 r^2 var(r)``)."""
        if k < 0 or k >= len(self.t) or idx.size == 0:
            return
        r2 = dist * dist
        w, x = estimate_weights(self.fusion, r2, 4.0 * r2 * var)
        old_i, old_w, old_wd = self.rl_idx[k], self.rl_w[k], self.rl_wd[k]
        all_i = np.concatenate([old_i, idx])
        uniq, inv = np.unique(all_i, return_inverse=True)
        self.rl_idx[k] = uniq
        self.rl_w[k] = np.bincount(inv, np.concatenate([old_w, w]), len(uniq))
        self.rl_wd[k] = np.bincount(inv, np.concatenate([old_wd, w * x]), len(uniq))

    def ranges(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Fused robot-landmark distances of pose ``k``: (landmark, distance_m, variance_m2)."""
        d, v = fused_from_sums(self.fusion if self.fusion != "predicted" else "scale-free",
                               self.rl_w[k], self.rl_wd[k])
        return self.rl_idx[k], d, v

    def relative_poses(self) -> np.ndarray:
        """The window's poses dead-reckoned from its first one, shape ``(m, 3)``."""
        return dead_reckon(np.array(self.odom[1:]).reshape(-1, 3))

    def window_ranges(self, bearing_sigma_rad: float, min_parallax_rad: float
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Robot-landmark distances by triangulating every landmark over the whole window.

        The window's poses are dead-reckoned (short chains, little drift); each landmark seen
        from at least two of them is the least-squares intersection of its rays, weighted by
        ``1 / range^2`` (a bearing error moves the ray by ``range * sigma`` at the point), and
        refused without enough parallax or behind a ray. The distance from every observing
        pose follows, with the first-order variance ``u^T Cov(x) u`` plus the dead-reckoning
        variance of that pose's position within the window.

        Returns
        -------
        pose, landmark : int arrays of shape (R,)
            Window position and dense landmark index of each distance.
        distance_m, variance_m2 : arrays of shape (R,)
        """
        m = len(self.t)
        empty = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros(0))
        if m < 2:
            return empty
        poses = self.relative_poses()
        pose_of = np.repeat(np.arange(m), [len(b) for b in self.bearings])
        lm = np.concatenate(self.bearing_idx)
        if lm.size == 0:
            return empty
        ang = poses[pose_of, 2] + np.concatenate(self.bearings)
        origin = poses[pose_of, :2]
        uniq, owner = np.unique(lm, return_inverse=True)
        dx, dy = np.cos(ang), np.sin(ang)
        nxx, nxy, nyy = dy * dy, -dx * dy, dx * dx          # I - d d^T
        wgt = np.ones(lm.size)
        x = np.full((len(uniq), 2), np.nan)
        ok = np.zeros(len(uniq), bool)
        for _ in range(2):                                   # unweighted, then 1 / r^2
            axx = np.bincount(owner, wgt * nxx, len(uniq))
            axy = np.bincount(owner, wgt * nxy, len(uniq))
            ayy = np.bincount(owner, wgt * nyy, len(uniq))
            bx = np.bincount(owner, wgt * (nxx * origin[:, 0] + nxy * origin[:, 1]), len(uniq))
            by = np.bincount(owner, wgt * (nxy * origin[:, 0] + nyy * origin[:, 1]), len(uniq))
            det = axx * ayy - axy * axy
            tr = axx + ayy
            lam = tr / 2 - np.sqrt(np.maximum(tr * tr / 4 - det, 0.0))
            # smallest eigenvalue over the mean weight: 1 - cos(parallax) for two rays
            mean_w = np.bincount(owner, wgt, len(uniq)) / np.maximum(
                np.bincount(owner, minlength=len(uniq)), 1)
            ok = lam >= (1.0 - math.cos(min_parallax_rad)) * mean_w
            with np.errstate(divide="ignore", invalid="ignore"):
                x = np.column_stack([(ayy * bx - axy * by) / det, (axx * by - axy * bx) / det])
            off = x[owner] - origin
            with np.errstate(invalid="ignore"):
                depth = off[:, 0] * dx + off[:, 1] * dy
                front = np.bincount(owner, ~(depth > 0), len(uniq)) == 0
                rng2 = np.einsum("ra,ra->r", off, off)
            ok &= front & np.isfinite(x).all(axis=1)
            wgt = 1.0 / np.where(ok[owner], np.maximum(rng2, 1e-6), 1.0)
        use = ok[owner]
        if not use.any():
            return empty
        # Cov(x) = sigma^2 A_w^-1 with the 1 / r^2 weights of the last pass
        with np.errstate(divide="ignore", invalid="ignore"):
            cxx, cxy, cyy = ayy / det, -axy / det, axx / det
        off = off[use]
        r = np.sqrt(np.einsum("ra,ra->r", off, off))
        ux, uy = off[:, 0] / r, off[:, 1] / r
        o = owner[use]
        var = bearing_sigma_rad ** 2 * (ux * ux * cxx[o] + 2 * ux * uy * cxy[o] + uy * uy * cyy[o])
        sig = np.array(self.sigma)
        drift = np.cumsum((sig[:, 0] ** 2 + sig[:, 1] ** 2))        # position variance growth
        pose_var = np.abs(drift - drift[m // 2])
        return pose_of[use], uniq[o], r, var + pose_var[pose_of[use]]

    def robot_pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Dead-reckoned distances between all poses of the window and their variances.

        Returns ``(a, b, distance_m, variance_m2)`` with window positions ``a < b``.
        """
        m = len(self.t)
        sig = np.array(self.sigma[1:]).reshape(-1, 3)
        u = np.array(self.odom[1:]).reshape(-1, 3)
        psi = np.concatenate([[0.0], np.cumsum(u[:, 2])])
        c, s = np.cos(psi[:-1]), np.sin(psi[:-1])
        step = np.column_stack([c * u[:, 0] - s * u[:, 1], s * u[:, 0] + c * u[:, 1]])
        xy = np.concatenate([np.zeros((1, 2)), np.cumsum(step, axis=0)])
        a, b = np.triu_indices(m, 1)
        off = xy[b] - xy[a]
        dist = np.hypot(off[:, 0], off[:, 1])
        unit = off / np.maximum(dist, 1e-300)[:, None]
        # First-order variance: motion k (pose k-1 -> k) moves the offset when a < k <= b.
        k = np.arange(1, m)
        inside = (k[None, :] > a[:, None]) & (k[None, :] <= b[:, None])       # (pairs, m-1)
        # d off / d(dx, dy)_k = R(psi_{k-1}); projected on the unit offset.
        rx = unit[:, None, 0] * c[None, :] + unit[:, None, 1] * s[None, :]
        ry = -unit[:, None, 0] * s[None, :] + unit[:, None, 1] * c[None, :]
        # d off / d dpsi_k turns every later motion: the lever is xy_b - xy_k.
        lever = xy[b][:, None, :] - xy[k][None, :, :]
        perp = unit[:, None, 0] * (-lever[..., 1]) + unit[:, None, 1] * lever[..., 0]
        inside_turn = (k[None, :] > a[:, None]) & (k[None, :] < b[:, None])
        var = (inside * (rx ** 2 * sig[None, :, 0] ** 2 + ry ** 2 * sig[None, :, 1] ** 2)).sum(1) \
            + (inside_turn * perp ** 2 * sig[None, :, 2] ** 2).sum(1)
        return a, b, dist, var


class StmdsMapper:
    """BOM-STMDS (Methods 1 and 2, optionally localising) as a :class:`~bomgraph.mapper.Mapper`.

    Parameters
    ----------
    header : StreamHeader
        Sigmas, sensor range and priors of the stream.
    config : StmdsConfig, optional
        Defaults to ``StmdsConfig()`` (Method 2, the corrected fusion rule).
    **options
        Replace fields of ``config`` (e.g. ``fusion="paper"``).
    """

    def __init__(self, header: StreamHeader, config: StmdsConfig | None = None,
                 **options: Any) -> None:
        self.config = StmdsConfig.with_options(config, **options) if options else (
            config or StmdsConfig())
        cfg = self.config
        self.header = header
        self._bearing_sigma = float(header.bearing_sigma_rad)
        if cfg.max_range_m is not None:
            self._max_range = float(cfg.max_range_m)
        elif header.sensor_range_m is not None:
            self._max_range = cfg.max_range_factor * float(header.sensor_range_m)
        else:
            self._max_range = math.inf
        self._ids = IdIndex()
        self._store = DistanceStore(cfg.fusion, cfg.min_count)
        # the last max(baselines) + 1 steps: (sorted ids, bearings, dense idx, odom, sigma)
        self._history: list[tuple] = []
        self._max_baseline = max(cfg.baselines)
        # windowed triangulation: the steps of the current window, (ids, bearings, odom, sigma)
        self._tri_window: list[tuple] = []
        self._prev_bundle: tuple | None = None    # tri_method="ba": (t, poses, ids, xy)
        if cfg.tri_window is not None:
            self._tri_stride = cfg.tri_stride or cfg.tri_window - 1
            self._tri_inflation = float(max(1, math.ceil((cfg.tri_window - 1)
                                                         / self._tri_stride)))
        self._t = -1
        self._n_gated = 0
        self._n_outliers = 0                      # rays dropped by the window bundle
        self._triangulated = _GrowingFlags()      # by dense index: ever passed the gates
        self._relative_gate = math.isfinite(cfg.max_relative_range_sigma)
        self._n_smacof = 0                        # SMACOF estimates made so far
        self._n_triangulated = 0
        self._prev_xy = np.zeros((0, 2))   # previous map by dense landmark index (NaN: absent)
        self._window = _PoseWindow(cfg.window, cfg.fusion) if cfg.localise else None
        self._robot_placement = cfg.robot_placement
        if cfg.robot_placement == "auto":
            self._robot_placement = "joint" if cfg.method == "smacof" else "trilateration"
        if header.priors:
            pi = self._ids.lookup(np.array([p.i for p in header.priors], np.int64))
            pj = self._ids.lookup(np.array([p.j for p in header.priors], np.int64))
            self._store.add_priors(pi, pj, [p.distance_m for p in header.priors],
                                   [p.sigma_m for p in header.priors])

    # ------------------------------------------------------------------------------ steps
    def step(self, step: Step) -> None:
        """Triangulate the landmarks seen ``k`` steps ago and now (``k`` in ``baselines``; the
        paper: ``t-1`` and ``t``) and fuse their pair distances."""
        ids = step.landmark_ids
        brg = step.bearings_rad
        if ids.size > 1:
            order = np.argsort(ids)
            ids, brg = ids[order], brg[order]
        self._t = step.t
        idx_now = self._ids.lookup(ids)
        if self._window is not None:
            self._window.push(step.t, step.odom, None if step.odom is None
                              else step.odometry_sigma(self.header), idx_now, brg)
        if self.config.tri_window is not None:
            self._window_step(step, ids, brg)
            return
        hist = self._history
        if step.odom is None:
            hist.clear()
        hist.append((ids, brg, idx_now, step.odom,
                     None if step.odom is None else step.odometry_sigma(self.header)))
        if len(hist) > self._max_baseline + 1:
            del hist[0]
        if ids.size == 0:
            return
        for k in self.config.baselines:
            if len(hist) > k:
                self._triangulate(k, hist[-1 - k], ids, brg, idx_now)

    def _window_step(self, step: Step, ids: np.ndarray, brg: np.ndarray) -> None:
        """Collect the step into the current window; triangulate the window once it is full
        and start the next one ``tri_stride`` steps later."""
        buf = self._tri_window
        if step.odom is None:
            buf.clear()
            self._prev_bundle = None
        buf.append((ids, brg, step.odom,
                    None if step.odom is None else step.odometry_sigma(self.header), step.t))
        if len(buf) < self.config.tri_window:
            return
        self._triangulate_window(buf)
        del buf[:self._tri_stride]

    def _triangulate_window(self, buf: list[tuple]) -> None:
        """Windowed triangulation of the buffered steps; fuse the pairs of the window."""
        all_ids = np.concatenate([b[0] for b in buf])
        if all_ids.size < 2:
            return
        uniq, col = np.unique(all_ids, return_inverse=True)
        brg = np.full((len(buf), uniq.size), np.nan)
        row = np.repeat(np.arange(len(buf)), [b[0].size for b in buf])
        brg[row, col] = np.concatenate([b[1] for b in buf])
        odoms = np.array([b[2] for b in buf[1:]], float).reshape(-1, 3)
        sig = np.array([b[3] for b in buf[1:]], float).reshape(-1, 3)
        if self.config.tri_method == "ba":
            ts = np.array([b[4] for b in buf], np.int64)
            init_poses, init_points, n_shared = self._warm_start(ts, uniq, odoms)
            tri, n_gated = bundle_adjust_window(
                odoms, sig, brg, self._bearing_sigma, min_parallax_rad=self.config.min_parallax_rad,
                max_range_m=self._max_range, min_depth_m=self.config.tri_min_depth_m,
                outlier_sigma=self.config.tri_outlier_sigma, initial_poses=init_poses,
                initial_points=init_points, initial_prefix=n_shared,
                grow=self.config.tri_grow)
            self._n_outliers += tri.n_outliers
            self._prev_bundle = (ts, tri.poses, uniq[tri.column], tri.points_xy) if len(tri) \
                else None
        else:
            kernel = triangulate_window_lsq if self.config.tri_method == "lsq" else \
                triangulate_window
            tri, n_gated = kernel(odoms, brg, min_parallax_rad=self.config.min_parallax_rad,
                                  max_range_m=self._max_range)
        self._n_triangulated += len(tri)
        self._n_gated += n_gated
        if len(tri) == 0:
            return
        idx = self._ids.lookup(uniq[tri.column], add=False)
        self._triangulated[idx] = True
        if len(tri) < 2:
            return
        if isinstance(tri, WindowBundle):
            pairs = bundle_pair_squared_distances(tri)
        else:
            pairs = window_pair_squared_distances(tri, sig, self._bearing_sigma)
        var = pairs.variance_m4 if self._tri_inflation == 1.0 else \
            pairs.variance_m4 * self._tri_inflation
        self._store.add(idx[pairs.first], idx[pairs.second], pairs.squared_distance_m2, var)

    def _warm_start(self, ts: np.ndarray, uniq: np.ndarray, odoms: np.ndarray
                    ) -> tuple[np.ndarray | None, np.ndarray | None, int]:
        """Start of a window's bundle from the previous window's solution: the poses both
        windows hold, continued by the odometry, and the landmarks it mapped (in its frame)."""
        prev = self._prev_bundle
        if prev is None:
            return None, None, 1
        p_t, p_poses, p_ids, p_xy = prev
        shared = np.isin(ts, p_t)
        if not shared[0]:
            return None, None, 1
        poses = np.empty((len(ts), 3))
        n_shared = int(np.argmin(shared)) if not shared.all() else len(ts)
        poses[:n_shared] = p_poses[np.searchsorted(p_t, ts[:n_shared])]
        if n_shared < len(ts):
            poses[n_shared - 1:] = dead_reckon(odoms[n_shared - 1:], poses[n_shared - 1])
        points = np.full((len(uniq), 2), np.nan)
        pos = np.searchsorted(p_ids, uniq).clip(0, max(len(p_ids) - 1, 0))
        hit = p_ids[pos] == uniq if len(p_ids) else np.zeros(len(uniq), bool)
        points[hit] = p_xy[pos[hit]]
        return poses, points, n_shared

    def _triangulate(self, k: int, base: tuple, ids: np.ndarray, brg: np.ndarray,
                     idx_now: np.ndarray) -> None:
        """Sequential triangulation between the pose ``k`` steps back and now; fuse the pairs."""
        prev_ids = base[0]
        n_prev = prev_ids.size
        if n_prev == 0:
            return
        pos = np.searchsorted(prev_ids, ids)
        pos[pos == n_prev] = 0
        common = prev_ids[pos] == ids
        if k == 1:
            odom, odo_unc = self._history[-1][3], self._history[-1][4]
        else:
            recent = self._history[-k:]
            odom, odo_unc = compose_odometry([h[3] for h in recent], [h[4] for h in recent])
        tri = triangulate_rays(odom, base[1][pos[common]], brg[common])
        var_r1 = var_r2 = None
        if self._window is not None or self._relative_gate:
            var_r1, var_r2 = range_variances(tri, odo_unc, self._bearing_sigma)
        ok = np.flatnonzero(gate_points(
            tri, var_r1, min_parallax_rad=self.config.min_parallax_rad,
            max_range_m=self._max_range,
            max_relative_range_sigma=self.config.max_relative_range_sigma))
        n_ok = ok.size
        self._n_triangulated += n_ok
        self._n_gated += len(tri) - n_ok
        if n_ok == 0:
            return
        idx = idx_now[common]
        self._triangulated[idx[ok]] = True
        if self._window is not None and var_r1 is not None and var_r2 is not None:
            last = len(self._window.t) - 1
            self._window.add_ranges(last - k, idx[ok], tri.range_prev_m[ok], var_r1[ok])
            self._window.add_ranges(last, idx[ok], tri.range_now_m[ok], var_r2[ok])
        if n_ok < 2:
            return
        pairs = pair_squared_distances(tri, odo_unc, self._bearing_sigma, select=ok,
                                       with_translation=self._store.fusion == "predicted")
        self._store.add(idx[pairs.first], idx[pairs.second], pairs.squared_distance_m2,
                        pairs.variance_m4, pairs.translation_variance_m4)

    # ------------------------------------------------------------------------------ map
    def _base_info(self) -> dict[str, Any]:
        cfg = self.config
        return {"method": f"stmds-{cfg.method}" + ("-loc" if cfg.localise else ""),
                "t": self._t, "fusion": cfg.fusion, "n_pairs_stored": len(self._store),
                "n_triangulated": self._n_triangulated, "n_gated": self._n_gated,
                "n_outlier_rays": self._n_outliers}

    def estimate(self) -> MapEstimate:
        """The map now (and the window's poses when localising); never raises for lack of data."""
        cfg = self.config
        info = self._base_info()
        known = self._store.known()
        info["n_known_pairs"] = len(known)
        n_lm = len(self._ids)
        first, second = known.first, known.second
        dist, var = known.distance_m, known.variance_m2
        measured = known.count >= cfg.min_count          # not a prior alone
        n_nodes = n_lm
        robot_nodes = np.zeros(0, np.int64)
        joint = self._window is not None and self._robot_placement == "joint"
        if joint and len(self._window.t) >= 1:
            first, second, dist, var, robot_nodes = self._extend(first, second, dist, var, n_lm)
            measured = np.concatenate([measured, np.ones(len(first) - len(measured), bool)])
            n_nodes = n_lm + len(robot_nodes)
        if len(first) == 0:
            self._prev_xy = np.zeros((0, 2))
            info.update(reason="no known pair of landmarks yet", left_out=[])
            return MapEstimate.empty(**info)
        if not cfg.map_unobserved:
            seen = np.ones(n_nodes, bool)
            seen[:n_lm] = False
            flags = self._triangulated.array
            m_seen = min(len(flags), n_lm)
            seen[:m_seen] = flags[:m_seen]
            live = seen[first] & seen[second]
            first, second, dist, var = first[live], second[live], dist[live], var[live]
            measured = measured[live]
            # which landmarks are mapped is decided by triangulated distances alone; priors
            # then constrain the mapped ones (a landmark held only by priors is left out)
            touched = prune_low_degree(n_nodes, first[measured], second[measured],
                                       cfg.min_degree)
        else:
            touched = prune_low_degree(n_nodes, first, second, cfg.min_degree)
        live = touched[first] & touched[second]
        first, second, dist, var = first[live], second[live], dist[live], var[live]
        if len(first) == 0:
            self._prev_xy = np.zeros((0, 2))
            info.update(reason=f"no landmarks with {cfg.min_degree} known distances yet",
                        left_out=[])
            return MapEstimate.empty(**info)
        nodes = np.flatnonzero(touched)
        local = np.full(n_nodes, -1, np.int64)
        local[nodes] = np.arange(len(nodes))
        lf, ls = local[first], local[second]
        # the component with the most landmarks (robot positions do not count)
        comp = largest_component(len(nodes), lf, ls, (nodes < n_lm).astype(float))
        keep = np.zeros(len(nodes), bool)
        keep[comp.kept] = True
        sel = keep[lf] & keep[ls]
        kept_nodes = nodes[comp.kept]
        renum = np.full(len(nodes), -1, np.int64)
        renum[comp.kept] = np.arange(len(comp.kept))
        ef, es = renum[lf[sel]], renum[ls[sel]]
        ed, ev = dist[sel], var[sel]
        n = len(kept_nodes)
        is_lm = kept_nodes < n_lm
        left = np.concatenate([nodes[comp.left_out], np.flatnonzero(~touched)])
        info["left_out"] = sorted(int(i) for i in self._ids.ids[left[left < n_lm]])
        info["n_components"] = comp.n_components
        info["n_mapped_pairs"] = int(sel.sum())

        use_smacof = cfg.method == "smacof" and self._t >= cfg.smacof_from_t and n >= 2
        w = np.ones(len(ed)) if cfg.weights == "binary" else self._inverse_variance(ev)
        warm = None
        if use_smacof and cfg.smacof_init != "classical":
            warm = self._previous_positions(kept_nodes)
        restart = use_smacof and cfg.smacof_init == "best" and (
            self._n_smacof % cfg.smacof_restart_every == 0)
        xy_cs = None
        if not use_smacof or cfg.smacof_init == "classical" or restart or warm is None \
                or not np.isfinite(warm).all():
            if use_smacof and n > cfg.landmark_mds_above:
                # only a starting point for SMACOF: landmark MDS on pivot shortest paths
                pivots, rows = pivot_shortest_paths(n, ef, es, ed, cfg.n_pivots)
                xy_cs = landmark_scaling(rows, pivots)
                info["init_completion"] = f"landmark MDS, {len(pivots)} pivots"
            else:
                full = shortest_path_completion(n, ef, es, ed, keep_known=cfg.dmc_keep_known)
                xy_cs, _ = classical_scaling(full * full)
            if warm is not None and not np.isfinite(warm).all():
                warm = self._complete_warm_start(warm, xy_cs)
        xy = xy_cs
        info["reconstruction"] = "classical-scaling"
        if use_smacof:
            inits = []
            if warm is not None:
                inits.append(("previous", warm))
            if xy_cs is not None and (restart or not inits):
                inits.append(("classical", xy_cs))
            solver = LaplacianSolver(n, ef, es, w)
            best = None
            for name, init in inits:
                res = smacof(n, ef, es, ed, init=init, weights=w, max_iter=cfg.smacof_max_iter,
                             tol=cfg.smacof_tol, relaxation=cfg.smacof_relaxation,
                             solver=solver)
                if best is None or res.raw_stress < best[1].raw_stress:
                    best = (name, res)
            assert best is not None
            self._n_smacof += 1
            xy = best[1].points
            info.update(reconstruction="smacof", smacof_iterations=best[1].n_iter,
                        smacof_converged=best[1].converged, smacof_init=best[0],
                        smacof_starts=[name for name, _ in inits])
        assert xy is not None
        info["stress1"] = stress1(xy, ef, es, ed, w) if len(ed) else 0.0
        self._prev_xy = np.full((n_lm, 2), np.nan)
        self._prev_xy[kept_nodes[is_lm]] = xy[is_lm]

        lm_idx = kept_nodes[is_lm]
        lm_ids = self._ids.ids[lm_idx]
        lm_xy = xy[is_lm]
        pose_t = poses = None
        if self._window is not None and not joint and len(self._window.t):
            ks, robot_xy = self._trilaterate_window(lm_idx, lm_xy)
            kept_nodes = np.concatenate([kept_nodes, n_lm + ks])
            xy = np.concatenate([xy, robot_xy])
            robot_nodes = n_lm + ks
        if self._window is not None and robot_nodes.size:
            lm_xy, pose_t, poses, reflected = self._poses(kept_nodes, xy, n_lm, lm_idx, lm_xy)
            info["reflected"] = reflected
        order = np.argsort(lm_ids)
        return MapEstimate(lm_ids[order], lm_xy[order], pose_t=pose_t, poses=poses, info=info)

    @staticmethod
    def _inverse_variance(var: np.ndarray) -> np.ndarray:
        w = 1.0 / np.maximum(var, 1e-300)
        return w / w.mean()

    def _previous_positions(self, kept_nodes: np.ndarray) -> np.ndarray | None:
        """The previous map's positions of ``kept_nodes`` (NaN where it had none); None when
        it shares fewer than 3 nodes."""
        out = np.full((len(kept_nodes), 2), np.nan)
        inside = kept_nodes < len(self._prev_xy)
        out[inside] = self._prev_xy[kept_nodes[inside]]
        if np.isfinite(out[:, 0]).sum() < 3:
            return None
        return out

    @staticmethod
    def _complete_warm_start(warm: np.ndarray, xy_cs: np.ndarray) -> np.ndarray:
        """Nodes new to the previous map: the classical-scaling map aligned onto it."""
        have = np.isfinite(warm[:, 0])
        al = align(xy_cs[have], warm[have], allow_reflection=True)
        out = al.apply(xy_cs)
        out[have] = warm[have]
        return out

    # ------------------------------------------------------------------------------ III-E
    def _extend(self, first: np.ndarray, second: np.ndarray, dist: np.ndarray,
                var: np.ndarray, n_lm: int) -> tuple[np.ndarray, ...]:
        """Append the window's robot positions as nodes ``n_lm + k`` with their distances."""
        win = self._window
        assert win is not None
        m = len(win.t)
        robot_nodes = n_lm + np.arange(m)
        parts_f, parts_s, parts_d, parts_v = [first], [second], [dist], [var]
        if m >= 2:
            a, b, d, v = win.robot_pairs()
            parts_f.append(robot_nodes[a])
            parts_s.append(robot_nodes[b])
            parts_d.append(d)
            parts_v.append(np.maximum(v, 1e-12))
        if self.config.robot_ranges == "window":
            k, lm, d, v = win.window_ranges(self._bearing_sigma, self.config.min_parallax_rad)
            parts_f.append(lm)
            parts_s.append(robot_nodes[k])
            parts_d.append(d)
            parts_v.append(np.maximum(v, 1e-12))
        for k in range(m if self.config.robot_ranges == "pairwise" else 0):
            if win.rl_idx[k].size:
                lm, d, v = win.ranges(k)
                parts_f.append(lm)
                parts_s.append(np.full(lm.size, robot_nodes[k]))
                parts_d.append(d)
                parts_v.append(v)
        return (np.concatenate(parts_f), np.concatenate(parts_s), np.concatenate(parts_d),
                np.concatenate(parts_v), robot_nodes)

    def _trilaterate_window(self, lm_idx: np.ndarray, lm_xy: np.ndarray
                            ) -> tuple[np.ndarray, np.ndarray]:
        """Window positions placed against the mapped landmarks from their fused ranges."""
        win = self._window
        assert win is not None
        where = np.full(len(self._ids), -1, np.int64)
        where[lm_idx] = np.arange(len(lm_idx))
        ks, pts = [], []
        for k in range(len(win.t)):                       # at most `window` poses
            lm, d, v = win.ranges(k)
            row = where[lm]
            use = row >= 0
            x = trilaterate(lm_xy[row[use]], d[use], v[use])
            if x is not None:
                ks.append(k)
                pts.append(x)
        return np.array(ks, np.int64), np.array(pts).reshape(-1, 2)

    def _poses(self, kept_nodes: np.ndarray, xy: np.ndarray, n_lm: int, lm_idx: np.ndarray,
               lm_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None,
                                           bool]:
        """Headings by resection; reflect the frame when the mirror image fits better.

        Every bearing taken from a window pose to a mapped landmark gives a heading candidate
        ``atan2(landmark - robot) - bearing`` (vectorised over all of them); a pose's heading
        is the circular mean of its candidates. The spread of the candidates around their
        means decides between the map and its mirror image.
        """
        win = self._window
        assert win is not None
        m = len(win.t)
        node_row = np.full(n_lm + m, -1, np.int64)
        node_row[kept_nodes] = np.arange(len(kept_nodes))
        robot_row = node_row[n_lm + np.arange(m)]
        ks = np.flatnonzero(robot_row >= 0)
        if ks.size == 0:
            return lm_xy, None, None, False
        robot_xy = xy[robot_row[ks]]
        lm_row = np.full(n_lm, -1, np.int64)
        lm_row[lm_idx] = np.arange(len(lm_idx))
        # all bearings of the kept poses to mapped landmarks: (pose slot, landmark row, bearing)
        slot = np.concatenate([np.full(len(win.bearing_idx[k]), j) for j, k in enumerate(ks)])
        lm = lm_row[np.concatenate([win.bearing_idx[k] for k in ks])]
        brg = np.concatenate([win.bearings[k] for k in ks])
        use = lm >= 0
        slot, lm, brg = slot[use], lm[use], brg[use]
        n_obs = np.bincount(slot, minlength=len(ks))
        best = None
        for sign in (1.0, -1.0):
            flip = np.array([1.0, sign])
            off = lm_xy[lm] * flip - robot_xy[slot] * flip
            cand = np.arctan2(off[:, 1], off[:, 0]) - brg
            with np.errstate(invalid="ignore"):
                psi = np.arctan2(np.bincount(slot, np.sin(cand), len(ks)),
                                 np.bincount(slot, np.cos(cand), len(ks)))
            psi[n_obs == 0] = np.nan
            resid = float(np.sum(angle_residual(cand, psi[slot]) ** 2))
            if best is None or resid < best[0]:
                best = (resid, sign, psi)
        assert best is not None
        _, sign, psi = best
        flip = np.array([1.0, sign])
        psi = self._fill_headings(ks, psi)
        poses = np.column_stack([robot_xy * flip, wrap_angle(psi)])
        pose_t = np.array(win.t, np.int64)[ks]
        good = np.isfinite(poses).all(axis=1)
        return lm_xy * flip, pose_t[good], poses[good], bool(sign < 0)

    def _fill_headings(self, ks: np.ndarray, psi: np.ndarray) -> np.ndarray:
        """Poses that saw no mapped landmark take the heading of a neighbour plus odometry."""
        win = self._window
        assert win is not None
        psi = psi.copy()
        for _ in range(len(psi)):
            miss = ~np.isfinite(psi)
            if not miss.any() or miss.all():
                break
            for row in np.flatnonzero(miss):
                k = ks[row]
                if row > 0 and np.isfinite(psi[row - 1]) and ks[row - 1] == k - 1:
                    psi[row] = psi[row - 1] + win.odom[k][2]
                elif row + 1 < len(psi) and np.isfinite(psi[row + 1]) and ks[row + 1] == k + 1:
                    psi[row] = psi[row + 1] - win.odom[k + 1][2]
        return psi


PRESETS = ("paper", "improved", "window", "real")

#: Windowed triangulation (issue 8), chosen with ``scripts/bench_stmds_window.py``.
#: "window": the paper's simulation; "real": recordings with a narrow view and small steps
#: (MRCLAM6, the g2o set), where a pair must be seen within a longer stretch of the path.
WINDOW_PRESETS: dict[str, dict[str, Any]] = {
    "window": {"tri_window": 6, "tri_stride": 1, "fusion": "scale-free",
               "weights": "inverse-variance", "min_count": 3, "max_range_factor": 1.3},
    "real": {"tri_window": 60, "tri_stride": 10, "tri_method": "ba", "tri_grow": 3,
             "fusion": "scale-free", "weights": "inverse-variance", "min_count": 1},
}


def _make(header: StreamHeader, method: str, localise: bool, options: dict) -> StmdsMapper:
    """Factory behind the registry names. ``config=`` gives a base StmdsConfig, ``preset=``
    ``"paper"`` (the default), ``"improved"`` (:meth:`StmdsConfig.improved`), ``"window"`` or
    ``"real"`` (windowed triangulation, :data:`WINDOW_PRESETS`); the other options replace
    its fields."""
    config = options.pop("config", None)
    preset = options.pop("preset", "paper")
    if preset not in PRESETS:
        raise ConfigError(f"unknown BOM-STMDS preset {preset!r}; choose one of {PRESETS}")
    if config is not None and preset != "paper":
        raise ConfigError("give either config= or preset=, not both")
    if config is not None:
        base = config
    elif preset == "improved":
        base = StmdsConfig.improved()
    else:
        base = StmdsConfig(**WINDOW_PRESETS.get(preset, {}))
    windowed = options.get("tri_window", base.tri_window) is not None
    if localise and windowed and "robot_ranges" not in options:
        options["robot_ranges"] = "window"
    return StmdsMapper(header, StmdsConfig.with_options(base, method=method, localise=localise,
                                                         **options))


def make_stmds_cs(header: StreamHeader, **options: Any) -> StmdsMapper:
    """Method 1: DMC-SPL + classical scaling at every estimate."""
    return _make(header, "cs", False, options)


def make_stmds_smacof(header: StreamHeader, **options: Any) -> StmdsMapper:
    """Method 2: classical scaling before ``smacof_from_t``, weighted SMACOF from then on."""
    return _make(header, "smacof", False, options)


def make_stmds_cs_loc(header: StreamHeader, **options: Any) -> StmdsMapper:
    """Method 1 with the last ``window`` robot positions in the matrix (III-E)."""
    return _make(header, "cs", True, options)


def make_stmds_smacof_loc(header: StreamHeader, **options: Any) -> StmdsMapper:
    """Method 2 with the last ``window`` robot positions in the matrix (III-E)."""
    return _make(header, "smacof", True, options)


__all__ = ["StmdsConfig", "StmdsMapper", "make_stmds_cs", "make_stmds_smacof",
           "make_stmds_cs_loc", "make_stmds_smacof_loc"]
