"""BOM-STMDS as a Mapper: the online schedule of the paper (Algorithm 1, sections III-B to III-E).

Every step: triangulate the landmarks seen at ``t-1`` and ``t`` (III-B, :mod:`.triangulation`;
``baseline_steps`` can also pair ``t-k`` with ``t`` over the chained odometry, ``tri_window``
triangulates windows of poses, :mod:`.window` and :mod:`.bundle`), gate degenerate geometry,
and fuse every pair's instantaneous squared distance into the distance store (III-C,
:mod:`.distances`; priors from the stream header are the initial estimates). At every
``estimate()`` call: take the known pairs (a prior, or ``min_count`` estimates), add the held
robot positions when localising (III-E, :mod:`.localisation`), and reconstruct coordinates
(III-D, :func:`.reconstruct.reconstruct`); landmarks left out are named in
``info["left_out"]``. Method 2's SMACOF starts from the map of the last step on the method's
own schedule (every :data:`WARM_EVERY` steps, made there whether or not estimate() was
called), so the map at a step does not depend on the caller's estimate() cadence.

``estimate().info`` reports: method, t, fusion, the numbers of stored / known / mapped pairs,
of triangulated and gated landmarks, the landmarks left out, the number of components, the
reconstruction used, SMACOF's iterations and start, Stress-1, and (localising) whether the
frame was reflected.
"""

from __future__ import annotations

import copy
import math
from dataclasses import replace
from typing import Any

import numpy as np

from ..config import resolve
from ..errors import ConfigError, DegenerateGeometryError
from ..geometry import dead_reckon
from ..mapper import MapEstimate
from ..method_limits import check_bearing_sigma, check_distance, check_priors, check_sigmas
from ..stream import Step, StreamHeader
from .batch import BATCH_STEPS, StepBatch
from .bundle import (SIGMA_RANGE, PrefixState, WindowBundle, bundle_adjust_window,
                     bundle_pair_squared_distances, relative_range_sigma)
from .config import StmdsConfig
from .distances import DistanceStore, IdIndex
from .localisation import RobotPoses, extend_with_robots, resect_headings, trilaterate_robots
from .reconstruct import reconstruct
from .triangulation import (compose_odometry, gate_points, pair_squared_distances,
                            range_variances, triangulate_rays)
from .window import (WindowSchedule, triangulate_window, triangulate_window_lsq,
                     triangulate_windows_lsq, window_pair_squared_distances)


#: SMACOF's warm start is the map of the last step ``t`` with ``t % WARM_EVERY == 0`` (made
#: there whether or not the caller asked for an estimate: the paper's checkpoint cadence), so
#: the map at a step does not depend on how often estimate() was called before it.
WARM_EVERY = 10

#: Keyframe windows (``tri_method="lsq"``) held before they are triangulated together.
BATCH_WINDOWS = 64


def _check_sigmas(values: Any, t: int | None, key: str) -> None:
    """:func:`~bomgraph.method_limits.check_sigmas` for STMDS."""
    check_sigmas(values, t, key, "STMDS")


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




class StmdsMapper:
    """BOM-STMDS (Methods 1 and 2, optionally localising) as a :class:`~bomgraph.mapper.Mapper`.

    Parameters
    ----------
    header : StreamHeader
        Sigmas, sensor range and priors of the stream.
    config : StmdsConfig, optional
        Defaults to ``StmdsConfig()`` (Method 2, the corrected fusion rule). The registry's
        factories build it from ``preset=`` and options (:func:`bomgraph.config.resolve`).
    """

    def __init__(self, header: StreamHeader, config: StmdsConfig | None = None) -> None:
        self.config = config or StmdsConfig()
        cfg = self.config
        self.header = header
        check_bearing_sigma(header, "STMDS")  # its weights and variances (h161: warned only)
        _check_sigmas(header.odometry_sigma, None, "odometry_sigma")
        check_priors(header, "STMDS")
        self._bearing_sigma = float(header.bearing_sigma_rad)
        if cfg.max_range_m is not None:
            self._max_range = float(cfg.max_range_m)
        elif header.sensor_range_m is not None:
            self._max_range = cfg.max_range_factor * float(header.sensor_range_m)
        else:
            self._max_range = math.inf
        self._ids = IdIndex()
        self._store = DistanceStore(cfg.fusion, cfg.min_count)
        # the last max(baseline_steps) + 1 steps: (sorted ids, bearings, dense idx, odom, sigma)
        self._history: list[tuple] = []
        self._max_baseline = max(cfg.baseline_steps)
        # windowed triangulation: the current window's steps (ids, bearings, odom, sigma, t)
        self._tri_buffer: list[tuple] = []
        self._prev_bundle: tuple | None = None    # tri_method="ba": (t, poses, ids, xy)
        self._closed_t = -1                       # last step of the last closed window
        self._window_sigma = self._bearing_sigma  # tri_estimate_sigma: the last estimate
        # geometric windows, "ba": the open window's bundle after its last prefix (first step,
        # landmark ids of its columns, PrefixState), for the next estimate to go on from
        self._open_prefix: tuple | None = None
        if cfg.windowed:
            self._schedule = WindowSchedule(
                poses=cfg.tri_window, stride=cfg.tri_stride, parallax_rad=cfg.tri_parallax_rad,
                length_m=cfg.tri_window_m, overlap=cfg.tri_overlap,
                quantile=cfg.tri_parallax_quantile, max_poses=cfg.tri_max_poses,
                prefixes=cfg.tri_prefixes)
            self._tri_inflation = self._schedule.inflation
        self._t = -1
        self._n_gated = 0
        self._n_outliers = 0                      # rays dropped by the window bundle
        self._triangulated = _GrowingFlags()      # by dense index: ever passed the gates
        self._relative_gate = math.isfinite(cfg.max_relative_range_sigma)
        self._n_smacof = 0                        # SMACOF maps kept so far
        self._n_triangulated = 0
        # SMACOF's warm starts: the last scheduled map (_warm_scheduled; and its runner-up)
        # by dense landmark index (NaN: absent); the step and reconstruction it was kept at
        self._prev_maps: tuple[np.ndarray, ...] = ()
        self._kept_t = -1
        self._kept: tuple | None = None
        self._robots = RobotPoses(cfg.n_robot_poses, cfg.fusion) if cfg.localise else None
        # the paper's rule (consecutive steps, no localisation, no relative gate) runs in
        # batches of steps (.batch); the other variants step by step
        self._batch: StepBatch | None = None
        # keyframe windows solved by least squares are held and triangulated together
        # (up to BATCH_WINDOWS; estimate() processes them at once too)
        self._window_batch: list | None = None
        if cfg.windowed and cfg.tri_method == "lsq" and not cfg.geometric_windows:
            self._window_batch = []
        if (not cfg.windowed and cfg.baseline_steps == (1,) and self._robots is None
                and not self._relative_gate):
            self._batch = StepBatch(self._store, self._ids, bearing_sigma_rad=self._bearing_sigma,
                                    min_parallax_rad=cfg.min_parallax_rad,
                                    max_range_m=self._max_range,
                                    default_sigma=np.asarray(header.odometry_sigma, float),
                                    triangulated=self._triangulated)
        if header.priors:
            pi = self._ids.lookup(np.array([p.i for p in header.priors], np.int64))
            pj = self._ids.lookup(np.array([p.j for p in header.priors], np.int64))
            self._store.add_priors(pi, pj, [p.distance_m for p in header.priors],
                                   [p.sigma_m for p in header.priors])

    # ------------------------------------------------------------------------------ steps
    def step(self, step: Step) -> None:
        """Triangulate the landmarks seen ``k`` steps ago and now (``k`` in
        ``baseline_steps``; the paper: ``t-1`` and ``t``) and fuse their pair distances."""
        self._catch_up()
        ids = step.landmark_ids
        brg = step.bearings_rad
        if step.odom_sigma is not None:
            _check_sigmas(step.odom_sigma, step.t, "odom_sigma")
        if step.odom is not None:
            check_distance(math.hypot(step.odom[0], step.odom[1]), step.t, "STMDS",
                           "a move of")
        if self._batch is not None:
            self._t = step.t
            self._batch.push(ids, brg, step.odom, step.odom_sigma)
            if len(self._batch) >= BATCH_STEPS:
                self.flush()
            return
        if ids.size > 1:
            order = np.argsort(ids)
            ids, brg = ids[order], brg[order]
        self._t = step.t
        idx_now = self._ids.lookup(ids)
        if self._robots is not None:
            self._robots.push(step.t, step.odom, None if step.odom is None
                              else step.odometry_sigma(self.header), idx_now, brg)
        if self.config.windowed:
            self._tri_window_step(step, ids, brg)
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
        for k in self.config.baseline_steps:
            if len(hist) > k:
                self._triangulate(k, hist[-1 - k], ids, brg, idx_now)

    def _tri_window_step(self, step: Step, ids: np.ndarray, brg: np.ndarray) -> None:
        """Collect the step into the current window; triangulate the window once it is full
        and start the next one where :class:`.window.WindowSchedule` says."""
        buf = self._tri_buffer
        if step.odom is None:
            buf.clear()
            self._schedule.clear()
            self._prev_bundle = None
            self._open_prefix = None
        buf.append((ids, brg, step.odom,
                    None if step.odom is None else step.odometry_sigma(self.header), step.t))
        self._schedule.push(step.odom, ids, brg)
        if not self._schedule.full():
            return
        if self._window_batch is not None:
            self._window_batch.append(self._window_arrays(buf))
            if len(self._window_batch) >= BATCH_WINDOWS:
                self.flush()
        else:
            self._triangulate_window(buf)
        self._closed_t = step.t
        self._open_prefix = None
        del buf[:self._schedule.advance()]

    def _with_open_window(self) -> tuple[DistanceStore, np.ndarray]:
        """The distance store and the triangulated flags for an estimate now.

        Geometric windows close where the motion says, so the steps since the last closed
        window can be many; they are triangulated as one window for this estimate alone (a
        copy of the store and the flags; nothing is kept), so the map at ``t`` uses every
        step up to ``t`` and does not depend on when earlier estimates were asked for.
        """
        buf = self._tri_buffer
        if (not self.config.geometric_windows or len(buf) < 2
                or buf[-1][4] <= self._closed_t):
            return self._store, self._triangulated.array
        kept = (self._store, self._triangulated, self._prev_bundle, self._n_triangulated,
                self._n_gated, self._n_outliers, self._window_sigma)
        try:
            self._store = copy.deepcopy(self._store)
            self._triangulated = copy.deepcopy(self._triangulated)
            self._triangulate_window(buf)
            return self._store, self._triangulated.array
        finally:
            (self._store, self._triangulated, self._prev_bundle, self._n_triangulated,
             self._n_gated, self._n_outliers, self._window_sigma) = kept

    def _window_arrays(self, buf: list[tuple]) -> tuple | None:
        """The buffered window as arrays: ``(landmark ids (n,), bearings (W, n) NaN where
        not seen, increments (W-1, 3), their sigmas (W-1, 3))``; None with fewer than two
        readings."""
        all_ids = np.concatenate([b[0] for b in buf])
        if all_ids.size < 2:
            return None
        uniq, col = np.unique(all_ids, return_inverse=True)
        brg = np.full((len(buf), uniq.size), np.nan)
        row = np.repeat(np.arange(len(buf)), [b[0].size for b in buf])
        brg[row, col] = np.concatenate([b[1] for b in buf])
        odoms = np.array([b[2] for b in buf[1:]], float).reshape(-1, 3)
        sig = np.array([b[3] for b in buf[1:]], float).reshape(-1, 3)
        return uniq, brg, odoms, sig

    def _flush_windows(self) -> None:
        """Triangulate the held keyframe windows (``tri_method="lsq"``) in one call
        (:func:`.window.triangulate_windows_lsq`, the numbers of one window at a time) and
        fuse them in order."""
        held = [w for w in self._window_batch if w is not None]
        self._window_batch = []
        if not held:
            return
        results = triangulate_windows_lsq([w[2] for w in held], [w[1] for w in held],
                                          min_parallax_rad=self.config.min_parallax_rad,
                                          max_range_m=self._max_range)
        pairs: list[tuple] = []
        for (uniq, _, _, sig), (tri, n_gated) in zip(held, results):
            self._fuse_window(tri, n_gated, uniq, sig, None, pairs)
        if pairs:                  # one fusion call, the estimates in window order
            self._store.add(*(np.concatenate(col) for col in zip(*pairs)))

    def _triangulate_window(self, buf: list[tuple]) -> None:
        """Windowed triangulation of the buffered steps; fuse the pairs of the window."""
        arrays = self._window_arrays(buf)
        if arrays is None:
            return
        uniq, brg, odoms, sig = arrays
        well = None
        if self.config.tri_method == "ba":
            ts = np.array([b[4] for b in buf], np.int64)
            init_poses, init_points, n_shared = self._warm_start(ts, uniq, odoms)
            resume = self._resume(ts, uniq) if self.config.geometric_windows else None
            tri, n_gated = bundle_adjust_window(
                odoms, sig, brg, self._window_sigma, min_parallax_rad=self.config.min_parallax_rad,
                max_range_m=self._max_range, min_depth_m=self.config.tri_min_depth_m,
                outlier_sigma=self.config.tri_outlier_sigma, initial_poses=init_poses,
                initial_points=init_points, initial_prefix=n_shared,
                grow=self.config.tri_grow,
                prefix_ends=self._schedule.prefix_ends()
                if self.config.geometric_windows else None,
                estimate_sigma=self.config.tri_estimate_sigma, resume=resume,
                robust_start=self.config.tri_robust_start)
            if self.config.geometric_windows and tri.prefix_state is not None:
                self._open_prefix = (int(ts[0]), uniq, tri.prefix_state)
            self._n_outliers += tri.n_outliers
            if self.config.tri_estimate_sigma and len(tri):
                # the next window starts from it (within SIGMA_RANGE of the header's)
                self._window_sigma = float(np.clip(tri.bearing_sigma_rad,
                                                   SIGMA_RANGE[0] * self._bearing_sigma,
                                                   SIGMA_RANGE[1] * self._bearing_sigma))
            self._prev_bundle = (ts, tri.poses, uniq[tri.column], tri.points_xy) if len(tri) \
                else None
            if self._relative_gate and len(tri):
                # a landmark is admitted to the map once a window triangulates it well (its
                # covariance); its pairs from every window are fused
                well = relative_range_sigma(tri, brg) <= self.config.max_relative_range_sigma
        else:
            kernel = triangulate_window_lsq if self.config.tri_method == "lsq" else \
                triangulate_window
            tri, n_gated = kernel(odoms, brg, min_parallax_rad=self.config.min_parallax_rad,
                                  max_range_m=self._max_range)
        self._fuse_window(tri, n_gated, uniq, sig, well)

    def _fuse_window(self, tri: Any, n_gated: int, uniq: np.ndarray, sig: np.ndarray,
                     well: np.ndarray | None, pending: list | None = None) -> None:
        """Count a window's triangulation, flag its landmarks (those ``well`` triangulated,
        if given) and fuse its pairs (or append them to ``pending`` as ``(first, second,
        squared distance, variance)`` for one :meth:`.distances.DistanceStore.add` of
        several windows, which gives the same sums)."""
        self._n_triangulated += len(tri)
        self._n_gated += n_gated
        if len(tri) == 0:
            return
        idx = self._ids.lookup(uniq[tri.column], add=False)
        self._triangulated[idx if well is None else idx[well]] = True
        if len(tri) < 2:
            return
        if isinstance(tri, WindowBundle):
            pairs = bundle_pair_squared_distances(tri)
        else:
            pairs = window_pair_squared_distances(tri, sig, self._bearing_sigma)
        var = pairs.variance_m4 if self._tri_inflation == 1.0 else \
            pairs.variance_m4 * self._tri_inflation
        if pending is not None:
            pending.append((idx[pairs.first], idx[pairs.second], pairs.squared_distance_m2, var))
            return
        self._store.add(idx[pairs.first], idx[pairs.second], pairs.squared_distance_m2, var)

    def _resume(self, ts: np.ndarray, uniq: np.ndarray) -> PrefixState | None:
        """The open window's :class:`.bundle.PrefixState` from the last estimate, its columns
        moved to this window's landmarks (the same window, grown since), or None."""
        if self._open_prefix is None or self._open_prefix[0] != ts[0]:
            return None
        _, old_ids, state = self._open_prefix
        col = np.searchsorted(uniq, old_ids)           # every old landmark is still in view
        points = np.full((len(uniq), 2), np.nan)
        points[col] = state.points_xy
        return PrefixState(state.solved, state.poses, points, state.dropped_pose,
                           col[state.dropped_column])

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
        if self._robots is not None or self._relative_gate:
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
        if self._robots is not None and var_r1 is not None and var_r2 is not None:
            last = len(self._robots.t) - 1
            self._robots.add_ranges(last - k, idx[ok], tri.range_prev_m[ok], var_r1[ok])
            self._robots.add_ranges(last, idx[ok], tri.range_now_m[ok], var_r2[ok])
        if n_ok < 2:
            return
        pairs = pair_squared_distances(tri, odo_unc, self._bearing_sigma, select=ok)
        self._store.add(idx[pairs.first], idx[pairs.second], pairs.squared_distance_m2,
                        pairs.variance_m4)

    def flush(self) -> None:
        """Triangulate and fuse the steps held for the batched paths (:mod:`.batch`: the
        paper's rule holds up to ``batch.BATCH_STEPS`` steps; keyframe windows with
        ``tri_method="lsq"`` up to :data:`BATCH_WINDOWS` windows). :meth:`estimate` calls it;
        a timing of :meth:`step` alone should call it at the end too."""
        if self._window_batch:
            self._flush_windows()
        b = self._batch
        if b is not None and len(b):
            n_tri, n_gated = b.n_triangulated, b.n_gated
            b.flush()
            self._n_triangulated += b.n_triangulated - n_tri
            self._n_gated += b.n_gated - n_gated

    # ------------------------------------------------------------------------------ map
    def _base_info(self) -> dict[str, Any]:
        cfg = self.config
        return {"method": f"stmds-{cfg.method}" + ("-loc" if cfg.localise else ""),
                "t": self._t, "fusion": cfg.fusion, "n_pairs_stored": len(self._store),
                "n_triangulated": self._n_triangulated, "n_gated": self._n_gated,
                "n_outlier_rays": self._n_outliers,
                "n_degenerate_estimates": self._store.n_degenerate}

    def _warm_scheduled(self, t: int) -> bool:
        """Step ``t`` is on the method's own warm-start schedule: SMACOF warm-started from
        the previous map keeps the map at every :data:`WARM_EVERY`-th step (from the last
        one before ``smacof_from_t``), whatever the caller's estimate() cadence."""
        cfg = self.config
        return (cfg.method == "smacof" and cfg.smacof_init != "classical" and t > 0
                and t % WARM_EVERY == 0 and t + WARM_EVERY >= cfg.smacof_from_t)

    def _catch_up(self) -> None:
        """Make the scheduled map of the last step if no estimate() made it (before the next
        step changes the distances); a step whose pairs are all degenerate keeps no map."""
        if self._warm_scheduled(self._t) and self._kept_t != self._t:
            try:
                self._reconstruction()
            except DegenerateGeometryError:
                self._prev_maps = ()
                self._kept_t, self._kept = self._t, None

    def _reconstruction(self) -> tuple[dict[str, Any], Any, int, bool]:
        """``(info, Reconstruction, n_landmarks, joint)`` of the map now, warm-started from
        the last scheduled map; a scheduled step's map is kept (:meth:`_warm_scheduled`) and
        given again to a second estimate() at that step."""
        cfg = self.config
        if self._kept is not None and self._kept_t == self._t:
            info, rec, n_lm, joint = self._kept
            return dict(info), rec, n_lm, joint
        self.flush()
        info = self._base_info()
        store, triangulated = self._with_open_window()
        if len(store) == 0 and store.n_degenerate:
            raise DegenerateGeometryError(
                f"the stream gives no usable landmark distance up to step {self._t}: all "
                f"{store.n_degenerate} pair estimates put two landmarks on one point "
                f"(parallel rays through every landmark: is the bearing sensor stuck at one "
                f"value?) or had no finite variance")
        known = store.known()
        info["n_known_pairs"] = len(known)
        n_lm = len(self._ids)
        first, second = known.first, known.second
        dist, var = known.distance_m, known.variance_m2
        measured = known.count >= cfg.min_count          # not a prior alone
        n_nodes = n_lm
        # Method 2 reconstructs the robot positions with the landmarks (eq. 7); Method 1 maps
        # the landmarks alone, then trilaterates the positions (DMC-SPL over the sparse robot
        # rows distorts the map)
        joint = self._robots is not None and cfg.method == "smacof"
        if joint and len(self._robots.t) >= 1:
            first, second, dist, var, _ = extend_with_robots(
                self._robots, first, second, dist, var, n_lm, cfg.robot_ranges,
                self._window_sigma, cfg.min_parallax_rad)
            measured = np.concatenate([measured, np.ones(len(first) - len(measured), bool)])
            n_nodes = n_lm + len(self._robots.t)
        rec = reconstruct(cfg, n_nodes, n_lm, first, second, dist, var, measured,
                          triangulated, t=self._t, n_smacof=self._n_smacof,
                          previous_maps=self._prev_maps)
        if self._warm_scheduled(self._t):
            self._kept_t, self._kept = self._t, (dict(info), rec, n_lm, joint)
            self._n_smacof += int(rec.used_smacof)
            self._prev_maps = rec.landmark_maps(n_lm)
        return info, rec, n_lm, joint

    def estimate(self) -> MapEstimate:
        """The map now (and the held poses when localising); never raises for lack of data.

        Raises :class:`~bomgraph.errors.DegenerateGeometryError` when the stream gave pair
        estimates but every one was degenerate (zero length: parallel rays through every
        landmark, e.g. a stuck sensor; or no finite variance), naming that cause.
        """
        info, rec, n_lm, joint = self._reconstruction()
        if len(rec.nodes) == 0:
            info.update(reason=rec.info["reason"], left_out=[])
            return MapEstimate.empty(**info)
        kept_nodes, xy = rec.nodes, rec.points_xy
        left = rec.left_out
        info["left_out"] = sorted(int(i) for i in self._ids.ids[left[left < n_lm]])
        info.update(rec.info)
        is_lm = kept_nodes < n_lm
        robot_nodes = n_lm + np.arange(len(self._robots.t) if joint else 0)
        lm_idx = kept_nodes[is_lm]
        lm_ids = self._ids.ids[lm_idx]
        lm_xy = xy[is_lm]
        pose_t = poses = None
        if self._robots is not None and not joint and len(self._robots.t):
            ks, robot_xy = trilaterate_robots(self._robots, n_lm, lm_idx, lm_xy)
            kept_nodes = np.concatenate([kept_nodes, n_lm + ks])
            xy = np.concatenate([xy, robot_xy])
            robot_nodes = n_lm + ks
        if self._robots is not None and robot_nodes.size:
            lm_xy, pose_t, poses, reflected = resect_headings(self._robots, kept_nodes, xy, n_lm,
                                                              lm_idx, lm_xy)
            info["reflected"] = reflected
        order = np.argsort(lm_ids)
        return MapEstimate(lm_ids[order], lm_xy[order], pose_t=pose_t, poses=poses, info=info)


def _make(header: StreamHeader, method: str, localise: bool, options: dict) -> StmdsMapper:
    """Factory behind the registry names: ``config=`` (a StmdsConfig) alone, or ``preset=``
    (a name of :data:`StmdsConfig.PRESETS`, default ``"paper"``) and field options
    (:func:`bomgraph.config.resolve`); the registry name sets ``method`` and ``localise``."""
    config = options.pop("config", None)
    preset = options.pop("preset", None)
    for name in ("method", "localise"):
        if name in options:
            raise ConfigError(f"{name} is set by the method name (stmds-cs, stmds-smacof, "
                              f"...-loc), not as an option")
    if config is not None:
        cfg = replace(resolve(StmdsConfig, config, preset, options), method=method,
                      localise=localise)
    else:
        cfg = resolve(StmdsConfig, None, preset, {**options, "method": method,
                                                  "localise": localise})
    return StmdsMapper(header, cfg)


def make_stmds_cs(header: StreamHeader, **options: Any) -> StmdsMapper:
    """Method 1: DMC-SPL + classical scaling at every estimate."""
    return _make(header, "cs", False, options)


def make_stmds_smacof(header: StreamHeader, **options: Any) -> StmdsMapper:
    """Method 2: classical scaling before ``smacof_from_t``, weighted SMACOF from then on."""
    return _make(header, "smacof", False, options)


def make_stmds_cs_loc(header: StreamHeader, **options: Any) -> StmdsMapper:
    """Method 1 with the last ``n_robot_poses`` robot positions (III-E)."""
    return _make(header, "cs", True, options)


def make_stmds_smacof_loc(header: StreamHeader, **options: Any) -> StmdsMapper:
    """Method 2 with the last ``n_robot_poses`` robot positions in the matrix (III-E, eq. 7)."""
    return _make(header, "smacof", True, options)


for _factory in (make_stmds_cs, make_stmds_smacof, make_stmds_cs_loc, make_stmds_smacof_loc):
    _factory.config_class = StmdsConfig  # type: ignore[attr-defined]  # for `methods NAME`


__all__ = ["StmdsConfig", "StmdsMapper", "make_stmds_cs", "make_stmds_smacof",
           "make_stmds_cs_loc", "make_stmds_smacof_loc"]
