"""Bearing-only SLAM with GTSAM: the helpers of the baselines, public and in one place.

A bearing-only problem (2-D poses ``x_t``, 2-D landmarks ``l_i``, one bearing per
observation, odometry between poses) is easy to write as a GTSAM factor graph and hard to
solve: a landmark seen from one place, or along nearly parallel rays, leaves the linear
system singular, and GTSAM then stops with *"Indeterminant linear system detected while
working near variable ..."*, naming one variable, not the cause. That message and its
sequels are among the most asked GTSAM questions:

* borglab/gtsam#550 "Debugging an indeterminant linear exception" (no way to drill down to
  what is unconstrained; asked for tools) -> :func:`diagnose`;
* borglab/gtsam#964 "Indeterminant linear system detected while working near variable"
  (an incremental graph whose new variables are not yet constrained) -> :func:`diagnose`
  before ``isam.update``;
* borglab/gtsam#1130 "RangeISAMExample Error" (landmarks of a range-only iSAM example: first
  missing initial values, then an indeterminant system once they were initialised at
  random) -> :func:`diagnose` reports missing values too, and landmarks start from
  triangulation or from a map (:func:`seed_landmarks`);
* borglab/gtsam#2008 "Example for adding landmarks incrementally" (when and where a new
  landmark enters iSAM2) -> :class:`BearingGraph` delays a landmark until its rays
  intersect; ``hybrid-isam2`` (:mod:`baselines.hybrid_isam2`) lets it in earlier at its
  BOM-STMDS position.

What is here, each the same object the baselines run (re-exported, never copied):

* **graph**: :func:`build_graph` (a whole stream into a :class:`BatchState`: the factor
  graph, the initial values and the growing :class:`BearingGraph`), with the pieces
  :func:`odometry_factors` (the exact split of one odometry step into two between factors,
  see :mod:`baselines.bearing_graph`), :func:`bearing_noise`, :func:`prior_factor` (a known
  landmark distance as a ``RangeFactor2``), the keys :func:`pose_key`, :func:`mid_key`,
  :func:`landmark_key` and the value helpers :func:`insert_pose`,
  :func:`poses_from_values`, :func:`landmarks_from_values`;
* **initialisation**: :func:`triangulate_landmarks` (least-squares ray intersection,
  :func:`bomgraph.geometry.intersect_rays`), :func:`align_map` (any
  :class:`bomgraph.mapper.MapEstimate`, e.g. a BOM-STMDS map, into the graph frame: rigid
  fit with reflection, trimmed: :func:`trimmed_align`) and :func:`seed_landmarks` (the
  aligned map as the start of the graph's landmarks, and landmarks the rays do not yet
  determine entered at their map position); :func:`resect_pose` and
  :func:`resect_trajectory` (poses from their bearings to a map, :mod:`baselines.resection`),
  and :func:`seed_start` (every pose started from a map in any frame: aligned, resected,
  moved onto the start pose; :mod:`baselines.seeding`, the hybrid's own seeding);
* **diagnosis**: :func:`diagnose` names, before any solve, the landmarks with fewer than two
  bearings or too little parallax, the poses with no path to a prior, the variables without
  values, and checks the rank of the linearised system (:class:`Diagnosis`);
* **solving**: :func:`solve_lm` (Levenberg-Marquardt with an honest :class:`SolveReport`:
  a run that gave up is never "converged"), :func:`checked_solve` (diagnose, then solve,
  raising :class:`UnconstrainedGraphError` with the names instead of GTSAM's message),
  :func:`gauss_newton_check`, :func:`estimate_from_values` (a solution as a MapEstimate),
  :func:`isam2_params` (the ``gtsam.ISAM2Params`` ``gtsam-isam2`` runs with for a config).

Units: metres and radians; poses ``(x_m, y_m, psi_rad)``; points are ``(n, 2)`` arrays with
their ids beside them. The paper's section IV, Exp. 2 compares BOM-STMDS with such graphs.
Example: ``docs/examples/custom_hybrid.py`` (a custom hybrid in under 40 lines).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Iterable, Sequence

import gtsam
import numpy as np

from bomgraph.angles import angle_residual
from bomgraph.checks import row_array
from bomgraph.errors import BomgraphError, ConfigError, TooFewLandmarksError
from bomgraph.evaluate import Alignment, align
from bomgraph.geometry import intersect_rays
from bomgraph.mapper import MapEstimate
from bomgraph.stream import Step, StreamHeader

from .bearing_graph import (BearingGraph, FactorGraphConfig, NewFactors, bearing_noise,
                            insert_pose, landmark_key, landmarks_from_values, mid_key,
                            odometry_factors, pose_key, poses_from_values, prior_factor)
from .factor_graph import (GTSAM_ERRORS, BatchState, SolveReport, estimate_from_values,
                           gauss_newton_check, lm_params, marginal_covariances, solve_lm)
from .isam2 import Isam2Config, isam2_params
from .resection import resect_pose, resect_trajectory
from .seeding import (SeedAlignment, SeedStart, align_seed, check_map, seed_start,
                      triangulate_arrays, trimmed_align)


class UnconstrainedGraphError(BomgraphError, ValueError):
    """The graph leaves variables undetermined; ``diagnosis`` (a :class:`Diagnosis`) names
    them. Raised by :func:`checked_solve` instead of GTSAM's "Indeterminant linear system"."""

    def __init__(self, diagnosis: "Diagnosis") -> None:
        super().__init__(diagnosis.summary())
        self.diagnosis = diagnosis


# --------------------------------------------------------------------------------------------
# Graph
# --------------------------------------------------------------------------------------------

def build_graph(header: StreamHeader, steps: Iterable[Step], *,
                config: FactorGraphConfig | None = None,
                start_pose: Sequence[float] = (0.0, 0.0, 0.0), admit: bool = True
                ) -> BatchState:
    """The factor graph and initial values of a whole stream, on the dead-reckoned poses.

    Unlike ``gtsam-batch``, which lets landmarks in as it goes (on its solved poses), this
    lets them in once, at the end: those whose rays on the dead-reckoned poses of the whole
    stream intersect (on a drifting recording few or none); the others stay pending.

    Parameters
    ----------
    header : StreamHeader
        Bearing sigma (rad), odometry sigmas, sensor range (m) and known landmark distances
        (``header.priors``, as ``RangeFactor2``).
    steps : iterable of Step
        In order ``t = 0, 1, ...``; each gives the odometry ``[dx_m, dy_m, dpsi_rad]`` (from
        ``t = 1``) and its bearings.
    config : FactorGraphConfig, optional
        Sigma floors, the parallax a landmark needs to enter (``min_parallax_rad``), LM
        settings; the ``paper`` preset by default.
    start_pose : (x_m, y_m, psi_rad)
        The pose ``x_0`` is tied to by a prior: it fixes the map frame.
    admit : bool
        Let in the landmarks whose rays intersect on the dead-reckoned poses now. With False
        every landmark stays pending (:meth:`BearingGraph.pending`), e.g. for
        :func:`seed_landmarks` to place them first.

    Returns
    -------
    BatchState
        ``state.graph`` (a ``gtsam.NonlinearFactorGraph``: a prior on ``x_0``, two split
        odometry factors per step, one ``BearingFactor2D`` per bearing of an entered
        landmark, the range priors), ``state.values`` (``gtsam.Values``: dead-reckoned poses,
        landmarks at their ray intersection), ``state.problem`` (the :class:`BearingGraph`:
        entered and pending landmarks, counts) and ``state.solve`` / ``state.to_estimate``.
    """
    cfg = config if config is not None else FactorGraphConfig.preset("paper")
    state = BatchState(header, cfg, start_pose)
    for step in steps:
        state.add_step(step)
    if admit:
        state.absorb()
    return state


# --------------------------------------------------------------------------------------------
# Initialisation
# --------------------------------------------------------------------------------------------

def triangulate_landmarks(poses: np.ndarray, owner: np.ndarray, ids: np.ndarray,
                          bearings_rad: np.ndarray, only: np.ndarray,
                          min_parallax_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """Landmarks intersected from their bearings (the hybrid's first alignment reference).

    Parameters
    ----------
    poses : array of shape (T, 3)
        ``(x_m, y_m, psi_rad)`` of every step.
    owner, ids, bearings_rad : arrays of shape (J,)
        Per bearing: the step that took it, the landmark id, the bearing (rad, robot frame).
    only : array of int
        The landmark ids to try.
    min_parallax_rad : float
        Rays must span at least this angle (:func:`bomgraph.geometry.intersect_rays`).

    Returns
    -------
    ids : ndarray (n,), int64; xy : ndarray (n, 2), metres
        The landmarks with at least two bearings whose rays intersect, sorted by id.
    """
    poses = row_array(poses, 3, "triangulate_landmarks: poses", ConfigError, copy=False)
    owner = np.asarray(owner, np.int64)
    if owner.size and not 0 <= owner.min() <= owner.max() < len(poses):
        raise ConfigError(f"triangulate_landmarks: bearings of steps {int(owner.min())} .. "
                          f"{int(owner.max())} but poses has {len(poses)} rows (steps 0 .. "
                          f"{len(poses) - 1}): give only the bearings of those poses "
                          f"(owner < len(poses)) or a pose per step")
    return triangulate_arrays(poses, owner, np.asarray(ids, np.int64),
                              np.asarray(bearings_rad, float), np.asarray(only, np.int64),
                              float(min_parallax_rad))


@dataclass(frozen=True)
class AlignedMap:
    """A map moved into the graph frame by :func:`align_map`.

    ``landmark_ids`` (n,) and ``landmarks_xy`` (n, 2) are the whole map, transformed;
    ``alignment`` the transform (``reflected`` when the map came mirrored, as MDS maps may);
    ``n_common`` how many landmarks the fit used; ``rms_m`` its RMS residual on them.
    """

    landmark_ids: np.ndarray
    landmarks_xy: np.ndarray
    alignment: Alignment
    n_common: int
    rms_m: float

    def as_dict(self) -> dict[int, np.ndarray]:
        """id -> (2,) position."""
        return dict(zip(self.landmark_ids.tolist(), self.landmarks_xy))


def align_map(estimate: MapEstimate, reference_ids: np.ndarray, reference_xy: np.ndarray,
              *, trim: float = 3.0, with_scale: bool = False) -> AlignedMap:
    """Move ``estimate``'s map (any frame, mirrored or not) onto reference landmarks.

    A rigid fit with reflection allowed (:func:`trimmed_align`: refitted once without the
    landmarks whose residual exceeds ``trim`` times the median), or a similarity fit with
    ``with_scale`` (a map known only up to scale; untrimmed).

    Parameters
    ----------
    estimate : MapEstimate
        E.g. the final map of ``stmds-smacof``.
    reference_ids : array (k,), reference_xy : array (k, 2)
        Landmarks in the graph frame (e.g. the graph's current values, or
        :func:`triangulate_landmarks` on dead-reckoned poses).

    Raises
    ------
    TooFewLandmarksError
        Fewer than 3 landmarks common to the map and the reference.
    ConfigError
        ``estimate`` is no map (:func:`~baselines.seeding.check_map`: e.g. a ``RunResult``).
    """
    check_map("align_map", estimate)
    ref_ids = np.asarray(reference_ids, np.int64)
    ref_xy = np.asarray(reference_xy, float).reshape(-1, 2)
    _, i_map, i_ref = np.intersect1d(estimate.landmark_ids, ref_ids, return_indices=True)
    if i_map.size < 3:
        raise TooFewLandmarksError(
            f"align_map: {i_map.size} landmarks common to the map "
            f"({len(estimate.landmark_ids)}) and the reference ({ref_ids.size}); 3 are "
            f"needed: admit more landmarks to the graph first or give a reference with more "
            f"of the map's landmarks")
    src, dst = estimate.landmarks_xy[i_map], ref_xy[i_ref]
    al = (align(src, dst, allow_reflection=True, with_scale=True) if with_scale
          else trimmed_align(src, dst, trim))
    rms = float(np.sqrt(np.mean(np.sum((al.apply(src) - dst) ** 2, axis=1))))
    return AlignedMap(np.asarray(estimate.landmark_ids), al.apply(estimate.landmarks_xy), al,
                      int(i_map.size), rms)


def seed_landmarks(state: BatchState, estimate: MapEstimate, *, trim: float = 3.0,
                   overwrite: bool = True) -> AlignedMap:
    """Start the graph's landmarks from a map (e.g. BOM-STMDS), aligned into the graph frame.

    The map is aligned (:func:`align_map`) onto the landmarks already in ``state``'s values;
    every pending landmark with at least two bearings that the map has enters the graph at
    its aligned position (with all its bearing factors), the other pending ones by ray
    intersection as usual (:meth:`BatchState.absorb`), and with ``overwrite`` the initial
    value of every graph landmark the map has is replaced by its map position.

    Returns the :class:`AlignedMap`; raises :class:`TooFewLandmarksError` if fewer than 3
    graph landmarks are in the map, saying whether the map holds too few of the stream's
    landmarks (ids not the stream's), or whether pending landmarks would enter now
    (``state.absorb()``; a graph built with ``admit=False``) or not: the dead-reckoned rays of
    a whole run may admit none (a drifting recording; 11 of the 25 300-step runs of
    ``paper_design(0)`` admit fewer than 3). Then start the poses from the map first:
    ``state.values.update(seed_start(state, estimate).values())`` (:func:`seed_start`, as
    the hybrid does), ``state.absorb()``, and seed again (docs/USAGE.md, "GTSAM helpers").
    """
    check_map("seed_landmarks", estimate)
    problem = state.problem
    ids = np.array(sorted(problem.landmark_ids), np.int64)
    ref_xy = landmarks_from_values(state.values, ids)
    n_common = np.intersect1d(ids, estimate.landmark_ids).size
    n_map = len(estimate.landmark_ids)                  # a Truth has no len()
    pending = problem.pending()
    seen = np.intersect1d(np.union1d(ids, np.array(list(pending), np.int64)),
                          estimate.landmark_ids).size   # of the stream's, graph or pending
    if n_common < 3 and ids.size >= 3 and seen < 3:   # the graph has enough: the map has not
        raise TooFewLandmarksError(
            f"seed_landmarks: the graph holds {ids.size} landmarks, {n_common} of them in the "
            f"map ({n_map}), and 3 are needed to align the map onto them; " +
            ("the map's landmark ids are not the stream's (it holds none the stream sees): "
             "give a map of this stream" if not seen else
             f"the map holds {seen} of the landmarks the stream sees: give a map of more"))
    if n_common < 3:
        cand = sorted(lid for lid, n_rays in pending.items() if n_rays >= 2)
        n_ok = int(problem.initial_points(*problem.rays_of(cand, state.poses))[1].sum())
        why = (f"{n_ok} of them intersect on the graph's poses: let them in first "
               f"(state.absorb(), or build_graph(admit=True)), or" if n_ok else
               "their rays on the graph's poses do not intersect (as on a drifting "
               "recording's dead-reckoned poses):")
        raise TooFewLandmarksError(
            f"seed_landmarks: the graph holds {ids.size} landmarks, {n_common} of them in the "
            f"map ({n_map}), and 3 are needed to align the map onto them; "
            f"{len(pending)} landmarks are pending, and {why} start the poses from the map "
            f"first (as the hybrid does): state.values.update(seed_start(state, "
            f"map).values()); state.absorb() (the rays on those poses intersect); then "
            f"seed_landmarks again (docs/USAGE.md, GTSAM helpers)")
    aligned = align_map(estimate, ids, ref_xy, trim=trim)
    where = aligned.as_dict()
    for lid, n_rays in sorted(problem.pending().items()):
        if n_rays >= 2 and lid in where:
            problem.enter(lid, where[lid])
    state.absorb()
    if overwrite:
        for lid in problem.landmark_ids:
            if lid in where:
                xy = where[lid]
                state.values.update(landmark_key(lid), gtsam.Point2(float(xy[0]), float(xy[1])))
    return aligned


# --------------------------------------------------------------------------------------------
# Diagnosis
# --------------------------------------------------------------------------------------------

def key_name(key: int) -> str:
    """A GTSAM key as text: its symbol (``x12``, ``l3``) when it is one, else the number."""
    sym = gtsam.Symbol(int(key))
    return sym.string() if chr(sym.chr()).isalpha() else str(int(key))


@dataclass(frozen=True)
class Diagnosis:
    """What :func:`diagnose` found; every entry names GTSAM keys as text (:func:`key_name`).

    Attributes
    ----------
    weak_landmarks : dict
        Landmark -> why it is not determined by its bearings alone: ``"1 bearing"``, ``"no
        bearing"``, ``"rays span 0.012 rad < 0.3"`` (too little parallax). A landmark also
        tied by range factors is listed too (``"... (+2 range factors)"``): the rank check
        decides.
    unanchored : list of str
        Variables (poses, landmarks) in a connected part of the graph that holds no prior
        factor: the whole part can slide and turn freely (the gauge is free).
    missing_values : list of str
        Keys used by factors but absent from the values (GTSAM: ``ValuesKeyDoesNotExist``).
    unused_values : list of str
        Keys with a value but no factor (GTSAM would find them indeterminate).
    rank, n_columns : int or None
        Numerical rank and width of the whitened Jacobian (dense, only up to
        ``dense_limit`` columns; else None).
    null_variables : list of str
        Variables that move in the Jacobian's null space (the undetermined ones).
    elimination_error : str
        GTSAM's own complaint when the linear system was eliminated ("" if it solved),
        with the variable it names.
    """

    weak_landmarks: dict[str, str] = field(default_factory=dict)
    unanchored: list[str] = field(default_factory=list)
    missing_values: list[str] = field(default_factory=list)
    unused_values: list[str] = field(default_factory=list)
    rank: int | None = None
    n_columns: int | None = None
    null_variables: list[str] = field(default_factory=list)
    elimination_error: str = ""

    @property
    def ok(self) -> bool:
        """True when the system is determined: values for every key, every part anchored,
        full rank (when checked) and the elimination solved."""
        full = self.rank is None or self.rank == self.n_columns
        return (not self.missing_values and not self.unused_values and not self.unanchored
                and full and not self.null_variables and not self.elimination_error)

    def summary(self) -> str:
        """One paragraph naming every problem, and what to do about each."""
        if self.ok:
            return ("graph determined" + (f" (rank {self.rank} of {self.n_columns})"
                                          if self.rank is not None else "")
                    + (f"; weak landmarks held by other factors: "
                       f"{_names(self.weak_landmarks)}" if self.weak_landmarks else ""))
        parts = []
        if self.missing_values:
            parts.append(f"no initial value for {_names(self.missing_values)} (insert one)")
        if self.unused_values:
            parts.append(f"values without factors: {_names(self.unused_values)} (remove them)")
        if self.weak_landmarks:
            parts.append("landmarks not determined by their bearings: " + ", ".join(
                f"{k} ({v})" for k, v in list(self.weak_landmarks.items())[:20])
                + (" ..." if len(self.weak_landmarks) > 20 else "")
                + " (wait for more bearings from other places, or seed them from a map "
                  "with a prior)")
        if self.unanchored:
            parts.append(f"no path to a prior: {_names(self.unanchored)} (add a prior or "
                         f"connect them by odometry)")
        if self.rank is not None and self.rank < (self.n_columns or 0):
            parts.append(f"Jacobian rank {self.rank} of {self.n_columns}")
        if self.null_variables:
            parts.append(f"free directions in {_names(self.null_variables)}")
        if self.elimination_error:
            parts.append(f"GTSAM: {self.elimination_error}")
        return "graph not determined: " + "; ".join(parts)


def _names(items: Iterable[str]) -> str:
    items = list(items)
    return ", ".join(items[:20]) + (f" ... ({len(items)} in all)" if len(items) > 20 else "")


def _is_point2(values: gtsam.Values, key: int) -> bool:
    try:
        values.atPoint2(key)
    except GTSAM_ERRORS:
        return False
    return True


def diagnose(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, *,
             min_parallax_rad: float = 0.3, dense_limit: int = 1500,
             rank_tol: float = 1e-9) -> Diagnosis:
    """Name what leaves ``graph`` undetermined at ``values``, before solving it.

    Checks, in order: keys without values and values without factors; per landmark (a
    ``Point2`` value), its bearing factors and the angle their world rays span
    (``pose heading + bearing``, with :func:`bomgraph.geometry.intersect_rays`'s parallax
    rule, threshold ``min_parallax_rad``); the connected parts of the graph (factors joining
    keys) that hold no unary (prior) factor; the rank of the whitened Jacobian (dense SVD
    when it has at most ``dense_limit`` columns: the null space names the free variables);
    and GTSAM's own elimination of the linear system (its exception's variable).

    Parameters
    ----------
    graph : gtsam.NonlinearFactorGraph
    values : gtsam.Values
        The linearisation point (e.g. the initial values).
    min_parallax_rad : float
        A landmark whose rays span less is reported weak (the graph builder's entry rule).
    dense_limit : int
        Widest Jacobian (columns = sum of variable dimensions) checked densely. The dense
        check is an SVD of the whole whitened Jacobian (a row per bearing), O(rows x
        columns^2): on a paper run (50 landmarks) 0.5 s CPU at 100 steps (697 columns) and
        2.8 s at 200 (1,297), several times the LM solve itself; beyond the limit the rank is
        not checked (``rank`` None) and the diagnosis costs about 0.1 s. Called at every
        estimate of a growing graph (as :func:`checked_solve` is), lower it or diagnose once.
    rank_tol : float
        Singular values below ``rank_tol`` times the largest count as zero.

    Returns
    -------
    Diagnosis
        ``.ok``, ``.summary()`` and the lists of names.
    """
    value_keys = set(int(k) for k in values.keys())
    factor_keys: set[int] = set()
    parent: dict[int, int] = {}

    def find(k: int) -> int:
        while parent.setdefault(k, k) != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    anchored_roots: list[int] = []
    bearings: dict[int, list[tuple[int, float]]] = {}
    ranges: dict[int, int] = {}
    for i in range(graph.size()):
        f = graph.at(i)
        if f is None:
            continue
        keys = [int(k) for k in f.keys()]
        factor_keys.update(keys)
        for k in keys[1:]:
            parent[find(k)] = find(keys[0])
        find(keys[0])
        if len(keys) == 1:
            anchored_roots.append(keys[0])
        if isinstance(f, gtsam.BearingFactor2D):
            bearings.setdefault(keys[1], []).append((keys[0], float(f.measured().theta())))
        elif isinstance(f, gtsam.RangeFactor2):
            for k in keys:
                ranges[k] = ranges.get(k, 0) + 1
    missing = sorted(factor_keys - value_keys)
    unused = sorted(value_keys - factor_keys)
    anchored = {find(k) for k in anchored_roots}
    unanchored = sorted(k for k in factor_keys if find(k) not in anchored)

    weak: dict[str, str] = {}
    for k in sorted(value_keys & factor_keys):
        if not _is_point2(values, k):
            continue
        rays = [(p, b) for p, b in bearings.get(k, []) if p in value_keys]
        why = ""
        if len(rays) < 2:
            why = f"{len(rays) or 'no'} bearing" + ("" if len(rays) == 1 else "s")
        else:
            poses = np.array([[values.atPose2(p).x(), values.atPose2(p).y(),
                               values.atPose2(p).theta()] for p, _ in rays])
            dirs = poses[:, 2] + np.array([b for _, b in rays])
            _, ok = intersect_rays(poses[:, :2], dirs, min_parallax_rad=min_parallax_rad,
                                   min_front_fraction=0.0)
            if not ok:
                span = _ray_span(dirs)
                why = f"rays span {span:.3g} rad < {min_parallax_rad:g}"
        if why:
            if ranges.get(k):
                why += f" (+{ranges[k]} range factors)"
            weak[key_name(k)] = why

    rank = n_cols = None
    null: list[str] = []
    elim = ""
    if not missing:
        linear = graph.linearize(values)
        try:
            linear.optimize()
        except GTSAM_ERRORS as exc:
            text = " ".join(str(exc).split())
            m = re.search(r"near variable (\d+)", text)
            elim = (f"indeterminant linear system near {key_name(int(m.group(1)))}" if m
                    else text.split(" Thrown when")[0][:300])
        keys = sorted(factor_keys)
        dims = [2 if _is_point2(values, k) else 3 for k in keys]
        if sum(dims) <= dense_limit:
            ordering = gtsam.Ordering()
            for k in keys:
                ordering.push_back(k)
            a, _ = linear.jacobian(ordering)
            n_cols = a.shape[1]
            # V only: with at least as many rows as columns the thin SVD holds all of it,
            # and a full one would also make U, rows x rows (a row per bearing)
            _, sv, vt = np.linalg.svd(a, full_matrices=a.shape[0] < a.shape[1])
            tol = rank_tol * (sv[0] if sv.size else 0.0)
            rank = int(np.sum(sv > tol))
            if rank < n_cols:
                basis = vt[rank:]
                starts = np.cumsum([0] + dims[:-1])
                for k, s, d in zip(keys, starts, dims):
                    if np.max(np.abs(basis[:, s:s + d])) > 1e-6:
                        null.append(key_name(k))
    return Diagnosis(weak, [key_name(k) for k in unanchored], [key_name(k) for k in missing],
                     [key_name(k) for k in unused], rank, n_cols, null, elim)


def _ray_span(directions_rad: np.ndarray) -> float:
    """The largest angle between two of the lines (rays modulo pi), radians in [0, pi/2]."""
    d = np.asarray(directions_rad, float)
    diff = np.abs(angle_residual(d[:, None], d[None, :]))
    diff = np.minimum(diff, math.pi - diff)
    return float(diff.max()) if diff.size else 0.0


# --------------------------------------------------------------------------------------------
# Solving
# --------------------------------------------------------------------------------------------

def checked_solve(graph: gtsam.NonlinearFactorGraph, initial: gtsam.Values,
                  config: FactorGraphConfig | None = None,
                  robust_graph: gtsam.NonlinearFactorGraph | None = None, *,
                  min_parallax_rad: float | None = None
                  ) -> tuple[gtsam.Values, SolveReport]:
    """:func:`diagnose`, then :func:`solve_lm` (Levenberg-Marquardt with an honest report).

    The diagnosis's dense rank check can cost more than the solve (:func:`diagnose`,
    ``dense_limit``); in a loop, diagnose once and call :func:`solve_lm`.

    Raises
    ------
    UnconstrainedGraphError
        When the diagnosis finds the graph undetermined; its message names the landmarks
        and poses to fix (instead of GTSAM's "Indeterminant linear system").
    """
    cfg = config if config is not None else FactorGraphConfig.preset("paper")
    diag = diagnose(graph, initial, min_parallax_rad=(cfg.min_parallax_rad
                                                      if min_parallax_rad is None
                                                      else min_parallax_rad))
    if not diag.ok:
        raise UnconstrainedGraphError(diag)
    return solve_lm(graph, initial, cfg, robust_graph)


__all__ = [
    # graph
    "build_graph", "BatchState", "BearingGraph", "NewFactors", "FactorGraphConfig",
    "odometry_factors", "bearing_noise", "prior_factor", "pose_key", "mid_key",
    "landmark_key", "insert_pose", "poses_from_values", "landmarks_from_values",
    # initialisation
    "triangulate_landmarks", "align_map", "AlignedMap", "seed_landmarks", "trimmed_align",
    "resect_pose", "resect_trajectory", "seed_start", "SeedStart", "align_seed",
    "SeedAlignment",
    # diagnosis
    "diagnose", "Diagnosis", "key_name", "UnconstrainedGraphError",
    # solving
    "solve_lm", "checked_solve", "SolveReport", "lm_params", "gauss_newton_check",
    "marginal_covariances", "estimate_from_values", "isam2_params", "Isam2Config",
]
