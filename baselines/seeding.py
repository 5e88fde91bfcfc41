"""Start a bearing graph's poses from another method's map: the hybrid's seeding, public.

A map made without the poses (BOM-STMDS, or any :class:`~bomgraph.mapper.MapEstimate`) lives
in its own frame, possibly mirrored. :func:`seed_start` turns it into a start for every pose
of a :class:`~baselines.factor_graph.BatchState` in the graph frame (the frame of the prior on
``x_0``):

1. :func:`align_seed`: the map is aligned rigidly, reflection allowed and trimmed
   (:func:`trimmed_align`), onto reference landmarks in the odometry frame: the landmarks of
   the graph's current values if asked (a previous solution) and at least 3 are in the map,
   else landmarks triangulated on the dead-reckoned poses of the first ``align_steps`` steps
   (all steps if that gives fewer than 3);
2. every pose is resected against the aligned map
   (:func:`~baselines.resection.resect_trajectory`; the odometry is the prior);
3. the poses and the map are moved rigidly so that pose 0 is the graph's start pose.

``hybrid`` (:class:`baselines.hybrid.HybridMapper`) runs exactly this; it is re-exported by
:mod:`baselines.gtsam_tools`. Units: metres and radians; poses ``(x_m, y_m, psi_rad)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gtsam
import numpy as np

from bomgraph.angles import angle_residual, wrap_angle
from bomgraph.errors import ConfigError, TooFewLandmarksError
from bomgraph.evaluate import Alignment, align
from bomgraph.geometry import dead_reckon, intersect_rays, rotation
from bomgraph.mapper import MapEstimate, RunResult

from .bearing_graph import insert_pose, landmarks_from_values
from .factor_graph import BatchState, all_poses
from .resection import resect_trajectory


def check_map(where: str, estimate: object) -> None:
    """Refuse a map argument without ``landmark_ids`` and ``landmarks_xy`` (a
    :class:`~bomgraph.mapper.MapEstimate`, or a ``Truth``) where it enters ``where()``: a
    ``RunResult`` is told to give ``.final`` (the README's ``run(...).final``).

    Raises
    ------
    ConfigError
        Naming ``where`` and the type given.
    """
    if hasattr(estimate, "landmark_ids") and hasattr(estimate, "landmarks_xy"):
        return
    hint = (" (result.final or result.at(t))" if isinstance(estimate, RunResult) else "")
    raise ConfigError(f"{where}(): the map must be a MapEstimate, got "
                      f"{type(estimate).__name__}{hint}")


def trimmed_align(source_xy: np.ndarray, target_xy: np.ndarray, trim: float = 3.0,
                  floor_m: float = 0.01) -> Alignment:
    """Rigid alignment with reflection of ``source`` onto ``target`` ((n, 2) each, n >= 3),
    refitted once without the points whose residual exceeds ``trim`` times the median (and
    ``floor_m``)."""
    al = align(source_xy, target_xy, allow_reflection=True)
    res = np.linalg.norm(al.apply(source_xy) - target_xy, axis=1)
    keep = res <= max(trim * float(np.median(res)), floor_m)
    if 3 <= keep.sum() < len(keep):
        al = align(source_xy[keep], target_xy[keep], allow_reflection=True)
    return al


def triangulate_arrays(poses: np.ndarray, owner: np.ndarray, ids: np.ndarray,
                       bearings_rad: np.ndarray, only: np.ndarray, min_parallax_rad: float
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Landmarks of ``only`` intersected from the bearings (owner step ``owner``, landmark
    ``ids``, all (J,)) on ``poses`` (T, 3): ids (n,) and points (n, 2)."""
    out_ids, out_xy = [], []
    for lid in np.intersect1d(np.unique(ids), only):
        sel = ids == lid
        if sel.sum() < 2:
            continue
        p = poses[owner[sel]]
        xy, ok = intersect_rays(p[:, :2], p[:, 2] + bearings_rad[sel],
                                min_parallax_rad=min_parallax_rad)
        if ok:
            out_ids.append(int(lid))
            out_xy.append(xy)
    return np.array(out_ids, dtype=np.int64), np.array(out_xy).reshape(-1, 2)


@dataclass(frozen=True)
class SeedAlignment:
    """A seed map aligned into the odometry frame by :func:`align_seed`.

    ``landmark_ids`` (n,) and ``landmarks_xy`` (n, 2, metres) are the whole map, moved;
    ``alignment`` the fit (seed frame -> odometry frame; ``alignment.reflected`` when the map
    came mirrored); ``in_solution_frame`` whether it was fitted on the graph's current
    landmarks (else on landmarks triangulated on dead-reckoned poses); ``n_reference`` how
    many reference landmarks there were.
    """

    landmark_ids: np.ndarray
    landmarks_xy: np.ndarray
    alignment: Alignment
    in_solution_frame: bool
    n_reference: int


@dataclass(frozen=True)
class SeedStart:
    """A start for every pose of a graph, from :func:`seed_start`, in the graph frame.

    ``poses`` (T, 3): ``(x_m, y_m, psi_rad)`` of steps ``0 .. T-1``, pose 0 at the start pose;
    ``landmark_ids`` (n,) and ``landmarks_xy`` (n, 2): the seed map in the same frame;
    ``reflected``: the seed map came mirrored; ``aligned``: the :class:`SeedAlignment` (how
    it aligned, in the odometry frame, before the rigid move onto the start pose).
    """

    poses: np.ndarray
    landmark_ids: np.ndarray
    landmarks_xy: np.ndarray
    reflected: bool
    aligned: SeedAlignment

    @property
    def landmarks(self) -> dict[int, np.ndarray]:
        """id -> (2,) position."""
        return dict(zip(self.landmark_ids.tolist(), self.landmarks_xy))

    def values(self) -> gtsam.Values:
        """A new ``gtsam.Values`` with every pose (and the intermediate poses of the split
        odometry, :func:`~baselines.bearing_graph.insert_pose`), no landmark."""
        values = gtsam.Values()
        for t in range(len(self.poses)):
            insert_pose(values, t, self.poses[t], self.poses[t - 1] if t else None)
        return values


def align_seed(state: BatchState, estimate: MapEstimate, *, use_solution: bool = False,
               align_steps: int = 50, trim: float = 3.0) -> SeedAlignment:
    """Step 1 of :func:`seed_start`: ``estimate``'s map aligned into the odometry frame.

    With ``use_solution`` the reference is the landmarks of ``state.values`` (a solution) if
    at least 3 are in the map; else landmarks triangulated on the dead-reckoned poses of the
    first ``align_steps`` steps, or of all steps if that gives fewer than 3 (with
    ``state.config.min_parallax_rad``).

    Raises
    ------
    TooFewLandmarksError
        Fewer than 3 reference landmarks in the map.
    ConfigError
        ``estimate`` is no map (:func:`check_map`: e.g. a ``RunResult``).
    """
    check_map("align_seed", estimate)
    problem = state.problem
    seed_ids = np.asarray(estimate.landmark_ids)
    ref = None
    if use_solution and problem.landmark_ids:
        ids = np.array(sorted(problem.landmark_ids), dtype=np.int64)
        common = np.intersect1d(ids, seed_ids)
        if common.size >= 3:
            ref = common, landmarks_from_values(state.values, common), True
    if ref is None:
        odoms = np.array([o for o in problem.odoms[1:]]).reshape(-1, 3)
        poses = dead_reckon(odoms, problem.start_pose)
        for upto in (min(align_steps, len(poses)), len(poses)):
            owner, ids, brg = state.bearings()
            n_j = int(np.searchsorted(owner, upto))
            owner, ids, brg = owner[:n_j], ids[:n_j], brg[:n_j]
            ids_out, xy_out = triangulate_arrays(poses[:upto], owner, ids, brg, seed_ids,
                                                 state.config.min_parallax_rad)
            if ids_out.size >= 3:
                ref = ids_out, xy_out, False
                break
    if ref is None:
        # h123: a map whose ids are not the stream's was told to "give more steps"; h163: a
        # map holding every landmark of a whole recording was told to hold more of them
        n_seen = np.intersect1d(seed_ids, state.bearings()[1]).size
        fix = ("give more steps or a map holding more of the landmarks the stream sees (by the "
               "stream's landmark ids)" if n_seen < 3 else
               "give more steps, or, where the dead reckoning drifts (a recording), start the "
               "poses from a map that carries them in the graph's frame (pose 0 at the start "
               "pose, as ekf's and gtsam-batch's maps do): insert_pose(state.values, t, "
               "pose, previous pose) for every step, state.absorb(), then seed_landmarks")
        raise TooFewLandmarksError(
            f"align_seed: fewer than 3 of the map's {seed_ids.size} landmarks ({n_seen} of "
            f"them seen in the stream) intersect with min_parallax_rad = "
            f"{state.config.min_parallax_rad:g} on the dead-reckoned poses of the "
            f"{problem.n_steps} step{'s' * (problem.n_steps != 1)}, so the map cannot be "
            f"aligned: {fix}")
    ref_ids, ref_xy, in_solution_frame = ref
    _, i_seed, i_ref = np.intersect1d(seed_ids, ref_ids, return_indices=True)
    al = trimmed_align(estimate.landmarks_xy[i_seed], ref_xy[i_ref], trim)
    return SeedAlignment(np.asarray(seed_ids), al.apply(estimate.landmarks_xy), al,
                         in_solution_frame, int(ref_ids.size))


def seed_start(state: BatchState, estimate: MapEstimate | SeedAlignment, *,
               use_solution: bool | None = None, align_steps: int | None = None,
               trim: float | None = None, n_headings: int = 36, huber_k: float = 2.0,
               map_sigma_m: float = 0.03,
               prior_sigma: tuple[float, float, float] = (0.02, 0.02, math.radians(2.0))
               ) -> SeedStart:
    """A start for every pose of ``state`` from a map in any frame (the hybrid's seeding).

    Aligns ``estimate`` (:func:`align_seed`; or takes an aligned one), resects every pose of
    ``state`` against it (:func:`~baselines.resection.resect_trajectory`, from the graph's
    current poses if the map was aligned on them, else from a grid of ``n_headings``
    headings), and moves poses and map rigidly so that pose 0 is ``state``'s start pose.

    Parameters
    ----------
    state : BatchState
        The graph (e.g. :func:`~baselines.gtsam_tools.build_graph`); its bearings, odometry
        and odometry sigmas are used, nothing in it is changed.
    estimate : MapEstimate or SeedAlignment
        E.g. the final map of ``stmds-smacof``: ids (n,), xy (n, 2) in metres, any frame.
    use_solution, align_steps, trim
        Of :func:`align_seed` (its defaults when not given), for a ``MapEstimate`` only: a
        ``SeedAlignment`` is aligned already, and giving them with one raises ``ConfigError``
        (pass them to the :func:`align_seed` call that made it).
    n_headings, huber_k, map_sigma_m, prior_sigma
        Of :func:`~baselines.resection.resect_trajectory` (heading grid, Huber threshold,
        map position error in metres, odometry-prior std. devs. (m, m, rad)).

    Returns
    -------
    SeedStart
        ``poses`` (T, 3) and the map (``landmark_ids``, ``landmarks_xy``) in the graph frame;
        ``values()`` gives the poses as ``gtsam.Values``. Then :func:`insert_pose` (or
        ``state.values.update``) each pose, ``state.absorb()`` (the rays intersect on these
        poses) and :func:`~baselines.gtsam_tools.seed_landmarks`.

    Raises
    ------
    TooFewLandmarksError
        The map cannot be aligned (:func:`align_seed`), or no pose sees 3 of its landmarks.
    ConfigError
        ``use_solution``, ``align_steps`` or ``trim`` given with a ``SeedAlignment``, or
        ``estimate`` is no map (:func:`check_map`).
    """
    given = {name: value for name, value in (("use_solution", use_solution),
                                             ("align_steps", align_steps), ("trim", trim))
             if value is not None}
    if isinstance(estimate, SeedAlignment):
        if given:
            raise ConfigError(
                f"seed_start: {', '.join(given)} given with a SeedAlignment, which is aligned "
                f"already (they apply only when seed_start aligns a MapEstimate itself): pass "
                f"them to the align_seed call that made it, or pass the MapEstimate instead")
        aligned = estimate
    else:
        check_map("seed_start", estimate)
        aligned = align_seed(state, estimate, **given)
    problem = state.problem
    map_ids, map_xy = aligned.landmark_ids, aligned.landmarks_xy
    # in the previous solution's frame its poses (and the odometry predictions of the new
    # ones) start the resection; otherwise a grid over the heading does
    start = all_poses(state.values, problem.n_steps) if aligned.in_solution_frame else None
    owner, ids, brg = state.bearings()
    odoms = np.array([np.zeros(3) if o is None else o for o in problem.odoms])
    poses = resect_trajectory(owner, ids, brg, float(state.header.bearing_sigma_rad),
                              map_ids, map_xy, odoms, state.odometry_sigmas(), start=start,
                              n_headings=n_headings, huber_k=huber_k,
                              map_sigma_m=map_sigma_m, prior_sigma=prior_sigma)
    if poses is None:
        raise TooFewLandmarksError(
            f"seed_start: no pose sees 3 of the map's {len(map_ids)} landmarks, so none can "
            f"be resected: give a map holding more of the landmarks the stream sees")
    # the first pose defines the frame: move the whole start rigidly onto it
    ang = float(angle_residual(problem.start_pose[2], poses[0, 2]))
    r = rotation(ang)
    c = problem.start_pose[:2] - r @ poses[0, :2]
    poses = np.column_stack([poses[:, :2] @ r.T + c, wrap_angle(poses[:, 2] + ang)])
    return SeedStart(poses, map_ids, map_xy @ r.T + c, bool(aligned.alignment.reflected),
                     aligned)


__all__ = ["SeedAlignment", "SeedStart", "align_seed", "check_map", "seed_start",
           "triangulate_arrays", "trimmed_align"]
