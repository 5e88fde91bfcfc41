"""Admission of landmarks by the parallax the whole run gave them (issue 15, ``admit_parallax_rad``).

A window bundle sees a landmark over a short stretch of path; a distant landmark can be seen
with little parallax in every window and still be well placed by the run as a whole (it was
seen again from elsewhere), or be poorly placed by every window and by the run alike (the
robot never moved across its line of sight). Neither one window's angle nor its covariance
tells the two apart, and a covariance shrinks with the number of rays (the keyframing). Here
every window's ray origins are carried into the frame of the map (each window fitted rigidly
onto the map by the landmarks both hold) and a landmark is admitted when the origins of all
its rays, over the whole run, span at least ``admit_parallax_rad`` seen from its mapped
position (:func:`bomgraph.geometry.origin_spread`: the geometric parallax test of
:func:`bomgraph.geometry.intersect_rays`, the rule the factor-graph baselines admit
landmarks by). An angle spanned by positions: the same for any keyframing of the same path and
any bearing-sigma calibration.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import origin_spread


@dataclass(frozen=True)
class WindowRays:
    """Where one window saw its triangulated landmarks from, in the window's frame.

    Attributes
    ----------
    ids : ndarray of shape (k,), int64
        The landmarks the window triangulated (sorted, unique).
    points_xy : ndarray of shape (k, 2)
        The window's estimate of each (metres): what fits the window onto the map.
    origins_xy : ndarray of shape (R, 2)
        Position of the pose of each ray of the window (metres), of every landmark it saw,
        triangulated there or not.
    ray_ids : ndarray of shape (R,), int64
        Landmark of each ray.
    """

    ids: np.ndarray
    points_xy: np.ndarray
    origins_xy: np.ndarray
    ray_ids: np.ndarray


def window_rays(ids: np.ndarray, points_xy: np.ndarray, poses: np.ndarray,
                column_ids: np.ndarray, bearings_rad: np.ndarray) -> WindowRays:
    """The :class:`WindowRays` of a window: the landmark ``ids`` (k,) it triangulated with
    their points (k, 2), its poses (W, 3), and its bearing matrix (W, n) (NaN: not seen) of
    the landmarks ``column_ids`` (n,)."""
    pose, col = np.nonzero(np.isfinite(np.asarray(bearings_rad, float)))
    return WindowRays(np.asarray(ids, np.int64), np.asarray(points_xy, float),
                      np.asarray(poses, float)[pose, :2],
                      np.asarray(column_ids, np.int64)[col])


def rigid_fit(source_xy: np.ndarray, target_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rotation (reflection allowed: a map from distances comes mirrored or
    not) and translation taking ``source_xy`` (n, 2) onto ``target_xy`` (n, 2): ``(R (2, 2),
    t (2,))`` with ``target ~ source @ R.T + t``."""
    ms, mt = source_xy.mean(axis=0), target_xy.mean(axis=0)
    u, _, vt = np.linalg.svd((target_xy - mt).T @ (source_xy - ms))
    rot = u @ vt
    return rot, mt - ms @ rot.T


def accumulated_parallax(records: list[WindowRays], map_ids: np.ndarray,
                         map_xy: np.ndarray, min_common: int = 3) -> np.ndarray:
    """Per landmark of the map, the angle its rays' origins over every window span, seen
    from its mapped position (radians, shape ``(len(map_ids),)``; 0 for a landmark no window
    placed in the map frame).

    Parameters
    ----------
    records : list of WindowRays
        Every window's rays (overlapping windows repeat rays: a span does not count them).
    map_ids : int array of shape (n,)
        Ids of the mapped landmarks, sorted.
    map_xy : array of shape (n, 2)
        Their positions in the map.
    min_common : int
        A window is carried into the map frame only when it shares this many landmarks
        with the map (a rigid fit needs 2; 3 also checks it).
    """
    map_ids = np.asarray(map_ids, np.int64)
    n = len(map_ids)
    origins, owners = [], []
    for rec in records:
        pos = np.searchsorted(map_ids, rec.ids).clip(0, max(n - 1, 0))
        hit = map_ids[pos] == rec.ids if n else np.zeros(len(rec.ids), bool)
        if np.count_nonzero(hit) < min_common:
            continue
        rot, t = rigid_fit(rec.points_xy[hit], map_xy[pos[hit]])
        ray_pos = np.searchsorted(map_ids, rec.ray_ids).clip(0, n - 1)
        keep = map_ids[ray_pos] == rec.ray_ids
        origins.append(rec.origins_xy[keep] @ rot.T + t)
        owners.append(ray_pos[keep])
    if not origins:
        return np.zeros(n)
    return origin_spread(np.asarray(map_xy, float), np.concatenate(origins),
                         np.concatenate(owners), n)


__all__ = ["WindowRays", "accumulated_parallax", "rigid_fit", "window_rays"]
