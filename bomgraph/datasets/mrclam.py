"""UTIAS MRCLAM recordings -> a bearing-only :class:`~bomgraph.stream.Stream` of keyframes.

The paper (section IV) needs parallax between consecutive poses; an MRCLAM camera reports
bursts of detections a few centimetres apart, so :func:`import_mrclam` turns one robot's
recording (``shared/data/mrclam*/SOURCE.md``) into keyframes (numbered as in its body):

1. **Rows.** Barcodes map to subjects; subjects 1-5 are robots, unknown barcodes false
   detections (both dropped); subjects in ``Landmark_Groundtruth.dat`` are landmarks (id =
   subject). The landmark table is checked against the detections' range-bearing pair
   distances and a known erratum corrected (:mod:`.landmark_truth`, ``meta["landmark_truth"]``;
   MRCLAM Dataset 1 swaps landmarks 11 and 17). Every dropped row is counted in ``meta["rows"]``. Ranges are dropped
   (``keep_ranges=True`` keeps them in ``meta["ranges_m"]``; ``sensor_range_m`` is the largest).
2. **Time window.** Detections outside the odometry or the robot's truth, or in a truth gap
   longer than ``max_truth_gap_s``, are dropped and counted, so every step has a true pose.
3. **Bursts; 4. keyframes.** Detections at most ``burst_gap_s`` apart are one burst. The
   velocity commands, delayed by ``command_delay_s``, are held and integrated along arcs into
   ``P(t)``. Burst 0 is keyframe 0; a later burst is the next once ``P`` moved ``min_distance_m``
   or turned ``min_turn_rad``. Step ``t``'s odometry is ``between(P(t_{t-1}), P(t_t))``.
5. **Attachment.** A detection goes to the keyframe nearest in time within ``attach_window_s``,
   its bearing re-expressed by the odometry turn ``b + (psi(t_m) - psi(t_k))``; a landmark
   seen twice for one keyframe keeps the detection closest in time.
6. **Calibration** (``calibrate=True``, needs the robot's truth; :mod:`.calibration`):
   per-step ``odom_sigma`` from the fitted model, header sigmas the median; the bearing sigma
   is the robust inlier RMS (bias included; outliers stay in the stream).
   ``meta["raw_bearing_check"]``: the same for every raw detection. Otherwise the sigmas are
   the ``DEFAULT_*`` below. Why the default thresholds: ``docs/measurements.md``.
"""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..angles import angle_residual, wrap_angle
from ..config import requirement
from ..errors import ConfigError, DatasetError, shown_path
from ..geometry import between, pair_bearings
from ..plausibility import refuse_implausible
from ..stream import Step, Stream, StreamHeader, Truth
from .calibration import (bearing_residuals, calibrate_odometry, odometry_length_ratio,
                          odometry_sigma_model,
                          robust_bearing_stats)
from .landmark_truth import checked_mrclam_landmarks
from .mrclam_files import ROBOT_SUBJECTS, MrclamRobotData, read_mrclam_robot

DEFAULT_BEARING_SIGMA_RAD = 0.0160
"""Bearing sigma used when not calibrating (fitted on mrclam6, docs/measurements.md)."""

DEFAULT_ODOMETRY_MODEL = ((0.0001, 0.0664, 0.0688),   # dx:   a [m], b [m/m], c [m/rad]
                          (0.0048, 0.0634, 0.0016),   # dy
                          (0.0282, 0.0936, 0.1361))   # dpsi: a [rad], b [rad/m], c [rad/rad]
"""``(a, b, c)`` per component of the odometry sigma model used when not calibrating."""


@dataclass(frozen=True)
class KeyframeConfig:
    """How detections are grouped into keyframes (module docstring, steps 2-5).

    Attributes
    ----------
    min_distance_m : float
        A new keyframe once the odometry has travelled this far since the last one ...
    min_turn_rad : float
        ... or turned this much (whichever comes first).
    burst_gap_s : float
        Detections closer in time than this belong to one camera burst.
    attach_window_s : float
        Detections at most this far in time from a keyframe are attached to it.
    rotate_bearings : bool
        Re-express attached bearings by the odometry heading change (recommended).
    max_truth_gap_s : float
        Bursts inside a gap in the robot's ground truth longer than this are dropped.
    command_delay_s : float
        The logged velocity commands take effect this long after their time stamp (the
        odometry time stamps are shifted by it before integration).
    """

    min_distance_m: float = 0.3
    min_turn_rad: float = 0.3
    burst_gap_s: float = 0.02
    attach_window_s: float = 0.6
    rotate_bearings: bool = True
    max_truth_gap_s: float = 0.5
    command_delay_s: float = 0.2

    def __post_init__(self) -> None:
        need = requirement("KeyframeConfig")

        for name in ("min_distance_m", "min_turn_rad", "burst_gap_s", "attach_window_s",
                     "max_truth_gap_s", "command_delay_s"):
            v = getattr(self, name)
            need(isinstance(v, (int, float)) and math.isfinite(v) and v >= 0,
                 f"{name} must be a finite number >= 0, got {v!r}")
        need(self.min_distance_m > 0 or self.min_turn_rad > 0,
             "min_distance_m and min_turn_rad cannot both be 0 (every burst would be a "
             "keyframe with no parallax); set at least one > 0")
        need(self.min_turn_rad < math.pi, "min_turn_rad must be < pi")
        need(self.max_truth_gap_s > 0, "max_truth_gap_s must be > 0")


# --------------------------------------------------------------------------------------------
# Kinematics and interpolation
# --------------------------------------------------------------------------------------------

def _arc(v: np.ndarray, w: np.ndarray, dt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Displacement ``(dx, dy)`` in the start frame of a constant-(v, w) arc of duration dt."""
    th = w * dt
    small = np.abs(th) < 1e-6
    w_safe = np.where(small, 1.0, w)
    # Series for tiny turns: sin(th)/w ~ dt (1 - th^2/6), (1 - cos th)/w ~ dt th / 2.
    dx = np.where(small, v * dt * (1.0 - th * th / 6.0), v * np.sin(th) / w_safe)
    dy = np.where(small, v * dt * th / 2.0, v * (1.0 - np.cos(th)) / w_safe)
    return dx, dy


def integrate_odometry(time_s: np.ndarray, v_mps: np.ndarray,
                       w_radps: np.ndarray) -> np.ndarray:
    """Dead-reckon velocity commands held constant between their time stamps.

    Parameters
    ----------
    time_s : ndarray of shape (k,)
        Non-decreasing time stamps.
    v_mps, w_radps : ndarray of shape (k,)
        Forward and angular velocity commanded from each time stamp to the next.

    Returns
    -------
    ndarray of shape (k, 3)
        Poses ``[x_m, y_m, psi_rad]`` at the time stamps, starting from the origin. The
        heading is NOT wrapped (it is the cumulative turn), so differences of it are turns.
    """
    t = np.asarray(time_s, dtype=float)
    v = np.asarray(v_mps, dtype=float)[:-1]
    w = np.asarray(w_radps, dtype=float)[:-1]
    dt = np.diff(t)
    lx, ly = _arc(v, w, dt)
    psi = np.concatenate([[0.0], np.cumsum(w * dt)])
    c, s = np.cos(psi[:-1]), np.sin(psi[:-1])
    x = np.concatenate([[0.0], np.cumsum(c * lx - s * ly)])
    y = np.concatenate([[0.0], np.cumsum(s * lx + c * ly)])
    return np.column_stack([x, y, psi])


def odometry_poses_at(time_s: np.ndarray, v_mps: np.ndarray, w_radps: np.ndarray,
                      poses: np.ndarray, query_s: np.ndarray) -> np.ndarray:
    """The dead-reckoned pose at arbitrary times inside ``[time_s[0], time_s[-1]]``.

    Parameters
    ----------
    time_s, v_mps, w_radps : ndarray of shape (k,)
        The odometry log.
    poses : ndarray of shape (k, 3)
        :func:`integrate_odometry` of that log.
    query_s : ndarray of shape (m,)
        Query times (clipped to the log's span).

    Returns
    -------
    ndarray of shape (m, 3)
        Poses with unwrapped (cumulative) heading, exact along each held arc.
    """
    t = np.asarray(time_s, dtype=float)
    q = np.clip(np.asarray(query_s, dtype=float), t[0], t[-1])
    k = np.clip(np.searchsorted(t, q, side="right") - 1, 0, len(t) - 1)
    dt = q - t[k]
    v = np.asarray(v_mps, dtype=float)[k]
    w = np.asarray(w_radps, dtype=float)[k]
    lx, ly = _arc(v, w, dt)
    p = poses[k]
    c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
    return np.column_stack([p[:, 0] + c * lx - s * ly, p[:, 1] + s * lx + c * ly,
                            p[:, 2] + w * dt])


def interpolate_poses(time_s: np.ndarray, poses: np.ndarray,
                      query_s: np.ndarray) -> np.ndarray:
    """Interpolate poses in time: linear in x, y; along the shorter arc in heading.

    Parameters
    ----------
    time_s : ndarray of shape (g,)
        Non-decreasing time stamps of the known poses.
    poses : ndarray of shape (g, 3)
        ``[x_m, y_m, psi_rad]`` (heading may be wrapped).
    query_s : ndarray of shape (m,)
        Times inside ``[time_s[0], time_s[-1]]``.

    Returns
    -------
    ndarray of shape (m, 3)
        Interpolated poses, heading wrapped to (-pi, pi].
    """
    t = np.asarray(time_s, dtype=float)
    p = np.asarray(poses, dtype=float)
    q = np.asarray(query_s, dtype=float)
    k = np.clip(np.searchsorted(t, q, side="right") - 1, 0, len(t) - 2)
    span = t[k + 1] - t[k]
    s = np.where(span > 0, (q - t[k]) / np.where(span > 0, span, 1.0), 0.0)
    s = np.clip(s, 0.0, 1.0)
    a, b = p[k], p[k + 1]
    xy = a[:, :2] + s[:, None] * (b[:, :2] - a[:, :2])
    psi = wrap_angle(a[:, 2] + s * angle_residual(b[:, 2], a[:, 2]))
    return np.column_stack([xy, psi])


def select_keyframes(poses: np.ndarray, min_distance_m: float,
                     min_turn_rad: float) -> np.ndarray:
    """Indices of the candidate poses that become keyframes.

    Parameters
    ----------
    poses : ndarray of shape (n, 3)
        Dead-reckoned poses of the candidates (bursts) in time order, cumulative heading.
    min_distance_m, min_turn_rad : float
        A candidate becomes a keyframe when its motion from the previous keyframe reaches
        either threshold (a threshold of 0 is ignored). Candidate 0 is always a keyframe.

    Returns
    -------
    ndarray of shape (K,), int64
        Increasing indices, starting with 0 (empty if there are no candidates).
    """
    n = len(poses)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    dist_on = min_distance_m > 0
    turn_on = min_turn_rad > 0
    out = [0]
    last = poses[0]
    # Sequential by nature: each choice depends on the previous keyframe.
    for i in range(1, n):
        u = between(last, poses[i])
        if (dist_on and math.hypot(u[0], u[1]) >= min_distance_m) or \
                (turn_on and abs(poses[i, 2] - last[2]) >= min_turn_rad):
            out.append(i)
            last = poses[i]
    return np.array(out, dtype=np.int64)


# --------------------------------------------------------------------------------------------
# The importer, step by step (module docstring)
# --------------------------------------------------------------------------------------------

_Rows = dict[str, Any]


def _classify_rows(raw: MrclamRobotData, odo_time_s: np.ndarray, keyframe: KeyframeConfig
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, _Rows]:
    """Steps 1-2: which measurement rows are usable landmark detections.

    Returns
    -------
    subject : ndarray of shape (n_rows,), int64
        Subject of each row (-1 for an unknown barcode).
    use : ndarray of shape (n_rows,), bool
        Landmark detections inside the odometry (and ground-truth) span, outside truth gaps.
    idx : ndarray of shape (m,), int64
        ``flatnonzero(use)``.
    rows : dict
        The counts of ``meta["rows"]`` so far.
    """
    me, gt = raw.measurements, raw.groundtruth
    n_rows = int(me["time_s"].size)
    barcodes = me["barcode"]
    known = np.array([b in raw.barcode_subject for b in barcodes.tolist()], dtype=bool)
    subject = np.array([raw.barcode_subject.get(b, -1) for b in barcodes.tolist()],
                       dtype=np.int64)
    is_robot = known & np.isin(subject, ROBOT_SUBJECTS)
    is_landmark = known & np.isin(subject, raw.landmark_ids)
    is_other = known & ~is_robot & ~is_landmark
    rows: _Rows = {
        "total": n_rows,
        "robot_sightings": int(is_robot.sum()),
        "unknown_barcode": int((~known).sum()),
        "unknown_barcode_values": sorted(set(barcodes[~known].tolist())),
        "subject_without_landmark_truth": int(is_other.sum()),
    }
    t_m = me["time_s"]
    in_time = (t_m >= odo_time_s[0]) & (t_m <= odo_time_s[-1])
    in_gap = np.zeros(n_rows, dtype=bool)
    if gt is not None:
        tg = gt["time_s"]
        in_time &= (t_m >= tg[0]) & (t_m <= tg[-1])
        k = np.clip(np.searchsorted(tg, t_m, side="right") - 1, 0, len(tg) - 2)
        in_gap = in_time & ((tg[k + 1] - tg[k]) > keyframe.max_truth_gap_s)
    use = is_landmark & in_time & ~in_gap
    rows["outside_time_span"] = int((is_landmark & ~in_time).sum())
    rows["in_truth_gap"] = int((is_landmark & in_gap).sum())
    return subject, use, np.flatnonzero(use), rows


def _select_keyframes(tu: np.ndarray, odo_at: Callable[[np.ndarray], np.ndarray],
                      keyframe: KeyframeConfig
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Steps 3-4: bursts of the detection times ``tu`` (m,) and the keyframes among them.

    Returns ``burst_of`` (m,) burst index per detection, ``burst_t`` (n_bursts,),
    ``kf_burst`` (K,) the bursts that are keyframes, ``kf_t`` (K,) their times.
    """
    new_burst = np.concatenate([[True], np.diff(tu) > keyframe.burst_gap_s])
    burst_of = np.cumsum(new_burst) - 1
    burst_t = tu[new_burst]
    kf_burst = select_keyframes(odo_at(burst_t), keyframe.min_distance_m,
                                keyframe.min_turn_rad)
    return burst_of, burst_t, kf_burst, burst_t[kf_burst]


def _attach_detections(tu: np.ndarray, burst_of: np.ndarray, burst_t: np.ndarray,
                       kf_burst: np.ndarray, kf_t: np.ndarray,
                       psi_shift: Callable[[np.ndarray], np.ndarray] | None,
                       ids: np.ndarray, bearing: np.ndarray, range_m: np.ndarray,
                       keyframe: KeyframeConfig, rows: _Rows
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Step 5: attach detections (m,) to keyframes, one per landmark and keyframe.

    ``psi_shift(near)`` gives, for the keyframe index of each detection, the heading change
    ``psi(t_m) - psi(t_k)`` [rad] added to its bearing (None: bearings are not re-expressed).
    Returns ``(step, landmark_id, bearing_rad, range_m)`` of the kept detections, sorted by
    step, the detection closest in time winning; adds the counts to ``rows``.
    """
    j = np.clip(np.searchsorted(kf_t, tu), 1, max(len(kf_t) - 1, 1))
    if len(kf_t) == 1:
        near = np.zeros(tu.size, dtype=np.int64)
    else:
        near = np.where(np.abs(tu - kf_t[j - 1]) <= np.abs(tu - kf_t[j]), j - 1, j)
    # A keyframe's own burst is always attached to it (its spread is below burst_gap_s).
    own = np.isin(burst_of, kf_burst)
    near = np.where(own, np.searchsorted(kf_t, burst_t[burst_of]), near)
    dt = tu - kf_t[near]
    attached = own | (np.abs(dt) <= keyframe.attach_window_s)
    rows["between_keyframes"] = int((~attached).sum())
    if psi_shift is not None:
        bearing = bearing + psi_shift(near)
    a_step = near[attached]
    a_id = ids[attached]
    a_brg = wrap_angle(bearing[attached])
    a_rng = range_m[attached]
    a_dt = np.abs(dt[attached])
    order = np.lexsort((np.arange(a_step.size), a_dt, a_id, a_step))
    a_step, a_id, a_brg, a_rng = a_step[order], a_id[order], a_brg[order], a_rng[order]
    first = np.concatenate([[True], (np.diff(a_step) != 0) | (np.diff(a_id) != 0)])
    rows["duplicate_in_keyframe"] = int((~first).sum())
    rows["kept"] = int(first.sum())
    return a_step[first], a_id[first], a_brg[first], a_rng[first]


def _raw_bearing_check(raw: MrclamRobotData, subject: np.ndarray,
                       det: np.ndarray) -> dict[str, Any] | None:
    """Step 6, the sensor before keyframing: every usable detection (mask ``det``) against the
    truth interpolated at its own time; None with fewer than 2 detections."""
    gt, me = raw.groundtruth, raw.measurements
    det_pose = interpolate_poses(gt["time_s"],
                                 np.column_stack([gt["x_m"], gt["y_m"], gt["psi_rad"]]),
                                 me["time_s"][det])
    det_xy = raw.landmarks_xy[np.searchsorted(raw.landmark_ids, subject[det],
                                              sorter=np.argsort(raw.landmark_ids))]
    if det.sum() < 2:
        return None
    det_r = angle_residual(me["bearing_rad"][det],
                           pair_bearings(det_pose, det_xy, wrapped=False))
    return {**robust_bearing_stats(det_r), "fov_rad": [float(me["bearing_rad"][det].min()),
                                                       float(me["bearing_rad"][det].max())]}


def import_mrclam(data_dir: str | os.PathLike[str], robot: int, *,
                  keyframe: KeyframeConfig = KeyframeConfig(), keep_ranges: bool = False,
                  calibrate: bool = True, landmark_check: bool = True,
                  odometry_scale: float = 1.0) -> Stream:
    """Import one MRCLAM robot as a keyframed bearing-only stream (see the module docstring).

    Parameters
    ----------
    data_dir : path-like
        ``shared/data/mrclam6`` (complete) or ``shared/data/mrclam1`` (gzip, no robot truth).
    robot : int
        1..5.
    keyframe : KeyframeConfig
        Keyframing and attachment thresholds.
    keep_ranges : bool
        Also store ``[t, landmark_id, range_m]`` of every kept bearing in ``meta["ranges_m"]``.
    calibrate : bool
        Fit the odometry and bearing sigmas against the robot's ground truth (required to
        exist); False uses the documented defaults measured on mrclam6.
    landmark_check : bool
        Correct a landmark table that matches a known erratum (MRCLAM Dataset 1 lists
        landmarks 11 and 17 at each other's positions) and refuse one that the detections'
        pair distances contradict (:mod:`.landmark_truth`); False takes the table as read.
    odometry_scale : float
        Multiply the logged forward velocities by this before anything else (keyframing
        included): a robot's odometry calibration, e.g. ``meta["odometry_length_ratio"]`` of
        the same robot imported from a recording with ground truth (MRCLAM6 puts robots 1-5 at
        0.932-0.974; :func:`.calibration.odometry_length_ratio`). 1 (the default): as logged.
        Recorded in ``meta["odometry_scale"]``.

    Returns
    -------
    Stream
        Steps = keyframes (``time_s`` = Unix time); truth = landmarks and, if the robot's
        ground truth exists, the interpolated pose of every keyframe.

    Raises
    ------
    DatasetError
        Missing or malformed files, no usable detections, ``calibrate=True`` without the
        robot's ground truth, or (``landmark_check``) a landmark table that contradicts the
        measured ranges and bearings.
    """
    if not isinstance(keyframe, KeyframeConfig):
        raise ConfigError(f"keyframe must be a KeyframeConfig, got {type(keyframe).__name__}")
    if not (isinstance(odometry_scale, (int, float)) and math.isfinite(odometry_scale)
            and 0.5 <= odometry_scale <= 2.0):
        raise ConfigError(f"odometry_scale must be a number in [0.5, 2] (a length calibration "
                          f"of a few per cent is typical), got {odometry_scale!r}")
    # 1-2. rows and time window ------------------------------------------------------------
    raw = read_mrclam_robot(data_dir, robot)
    landmark_truth: dict[str, Any] = {"checked": False}
    if landmark_check:
        raw, landmark_truth = checked_mrclam_landmarks(raw, data_dir, robot)
    gt = raw.groundtruth
    if calibrate and gt is None:
        raise DatasetError(f"{shown_path(Path(data_dir))}: no Robot{robot}_Groundtruth.dat, so "
                           f"the sigmas "
                           f"cannot be calibrated; pass calibrate=False (CLI: --no-calibrate) "
                           f"to use the defaults measured on mrclam6")
    me = raw.measurements
    od = dict(raw.odometry)
    od["time_s"] = od["time_s"] + keyframe.command_delay_s
    if odometry_scale != 1.0:
        od["v_mps"] = od["v_mps"] * float(odometry_scale)
    subject, use, idx, rows = _classify_rows(raw, od["time_s"], keyframe)
    if idx.size == 0:
        raise DatasetError(f"{shown_path(Path(data_dir))}: robot {robot} has no landmark "
                           f"detection inside "
                           f"its odometry{' and ground-truth' if gt is not None else ''} time "
                           f"span; nothing to import")

    # 3-4. odometry, bursts, keyframes ------------------------------------------------------
    odo_poses = integrate_odometry(od["time_s"], od["v_mps"], od["w_radps"])

    def odo_at(q: np.ndarray) -> np.ndarray:
        return odometry_poses_at(od["time_s"], od["v_mps"], od["w_radps"], odo_poses, q)

    tu = me["time_s"][idx]
    burst_of, burst_t, kf_burst, kf_t = _select_keyframes(tu, odo_at, keyframe)
    kf_pose = odo_at(kf_t)

    # 5. attach detections ------------------------------------------------------------------
    psi_shift = ((lambda near: odo_at(tu)[:, 2] - kf_pose[near, 2])
                 if keyframe.rotate_bearings else None)
    a_step, a_id, a_brg, a_rng = _attach_detections(
        tu, burst_of, burst_t, kf_burst, kf_t, psi_shift, subject[idx],
        me["bearing_rad"][idx].copy(), me["range_m"][idx], keyframe, rows)
    accounted = sum(rows[k] for k in ("robot_sightings", "unknown_barcode",
                                      "subject_without_landmark_truth", "outside_time_span",
                                      "in_truth_gap", "between_keyframes",
                                      "duplicate_in_keyframe", "kept"))
    if accounted != rows["total"]:  # an internal invariant, not user input
        raise RuntimeError(f"row accounting broken: {accounted} != {rows['total']}")

    # steps and truth ----------------------------------------------------------------------
    n_kf = len(kf_t)
    odoms = between(kf_pose[:-1], kf_pose[1:]) if n_kf > 1 else np.zeros((0, 3))
    _check_steps(odoms, kf_t, raw.files.get("odometry", "the odometry file"))
    # the sigma model's regressors: length and the whole (unwrapped) turn, which exceeds pi
    # when the robot spins during a long stretch without detections
    regress = odoms.copy()
    regress[:, 2] = np.diff(kf_pose[:, 2])
    bounds = np.searchsorted(a_step, np.arange(n_kf + 1))
    truth_poses = None
    if gt is not None:
        truth_poses = interpolate_poses(
            gt["time_s"], np.column_stack([gt["x_m"], gt["y_m"], gt["psi_rad"]]), kf_t)

    # 6. calibration ------------------------------------------------------------------------
    if calibrate and truth_poses is not None:  # calibrate without truth was refused above
        try:
            model, odo_info = calibrate_odometry(odoms, regress, truth_poses,
                                                 keyframe.min_distance_m, keyframe.min_turn_rad)
        except DatasetError as exc:  # h91: the message named neither the folder nor the robot
            raise DatasetError(f"{shown_path(Path(data_dir))}: robot {robot}: {exc}") from None
    else:
        model = np.asarray(DEFAULT_ODOMETRY_MODEL, dtype=float)
        odo_info = {"source": "DEFAULT_ODOMETRY_MODEL (mrclam6 robots 1-5, default keyframes)"}
    step_sigma = odometry_sigma_model(model, regress)
    steps = tuple(Step(t=t, odom=None if t == 0 else odoms[t - 1],
                       landmark_ids=a_id[bounds[t]:bounds[t + 1]],
                       bearings_rad=a_brg[bounds[t]:bounds[t + 1]],
                       odom_sigma=None if t == 0 else step_sigma[t - 1], time_s=float(kf_t[t]))
                  for t in range(n_kf))
    truth = Truth(raw.landmark_ids, raw.landmarks_xy, truth_poses)
    header_odo = (tuple(float(v) for v in np.median(step_sigma, axis=0)) if n_kf > 1
                  else tuple(float(v) for v in model[:, 0]))
    sensor_range = float(a_rng.max()) if a_rng.size and a_rng.max() > 0 else None
    meta: dict[str, Any] = {
        "source": "UTIAS MRCLAM", "dataset": Path(data_dir).resolve().name, "robot": int(robot),
        "citation": "K. Y. K. Leung, Y. Halpern, T. D. Barfoot, H. H. T. Liu, The UTIAS "
                    "Multi-Robot Cooperative Localization and Mapping Dataset, IJRR 30(8), "
                    "969-974, 2011",
        "licence": "third-party research data (ASRL, University of Toronto); cite, do not "
                   "relicense",
        "files": dict(raw.files),
        "importer": "bomgraph.datasets.mrclam.import_mrclam",
        "keyframe": asdict(keyframe),
        "rows": rows,
        "n_bursts": int(burst_t.size),
        "bearing_fov_rad": [float(a_brg.min()), float(a_brg.max())] if a_brg.size else None,
        "sensor_range_source": "largest measured range among kept detections",
        "odometry_model": {"form": "sigma_j = sqrt(a_j^2 + (b_j l)^2 + (c_j |dpsi|)^2)",
                           "components": ["dx_m", "dy_m", "dpsi_rad"],
                           "abc": [[float(v) for v in row] for row in model], **odo_info},
        "calibrated": bool(calibrate),
        "odometry_scale": float(odometry_scale),
        "landmark_truth": landmark_truth,
    }
    if truth_poses is not None and n_kf > 1:
        meta["odometry_length_ratio"] = odometry_length_ratio(odoms, truth_poses)
    if gt is not None:
        tg = gt["time_s"]
        k = np.clip(np.searchsorted(tg, kf_t, side="right") - 1, 0, len(tg) - 2)
        meta["truth_max_bracket_s"] = float(np.max(tg[k + 1] - tg[k]))
        check = _raw_bearing_check(raw, subject, use)
        if check is not None:
            meta["raw_bearing_check"] = check
    if calibrate and truth_poses is not None:
        stats = robust_bearing_stats(bearing_residuals(
            Stream(StreamHeader(1.0, header_odo), steps, truth))[0])
        bearing_sigma = stats["sigma_rad"]
        meta["bearing_calibration"] = stats
        if bearing_sigma > MAX_CALIBRATED_BEARING_SIGMA_RAD:
            raise DatasetError(
                f"{shown_path(Path(data_dir))}: robot {robot}: the bearings fit the ground truth "
                f"with a "
                f"sigma of {bearing_sigma:.3g} rad (the mrclam6 robots give 0.01-0.03 rad): "
                f"the truth does not belong to these measurements (x and y swapped? another "
                f"robot's {raw.files.get('groundtruth', 'ground truth')}?); check the files, "
                f"or import with --no-calibrate")
    else:
        bearing_sigma = DEFAULT_BEARING_SIGMA_RAD
        meta["bearing_calibration"] = {"source": "DEFAULT_BEARING_SIGMA_RAD (mrclam6 robots "
                                                 "1-5, default keyframes)"}
    if keep_ranges:
        meta["ranges_m"] = [[int(s), int(i), float(r)] for s, i, r in zip(a_step, a_id, a_rng)]
    header = StreamHeader(bearing_sigma_rad=float(bearing_sigma), odometry_sigma=header_odo,
                          sensor_range_m=sensor_range, meta=meta)
    refuse_implausible(header, steps, DatasetError, str(Path(data_dir)),
                       landmarks_xy=truth.landmarks_xy, poses=truth.poses)
    return Stream(header, steps, truth)


#: plausibility (issue 13, item 20): a calibrated bearing sigma above this means the truth
#: does not fit the measurements (mrclam6: 0.011-0.021 rad; x/y swapped: 0.98 rad) ...
MAX_CALIBRATED_BEARING_SIGMA_RAD = 0.2
#: ... and a keyframe step above this cannot happen in the ~10 m MRCLAM arena.
MAX_KEYFRAME_STEP_M = 100.0


def _check_steps(odoms: np.ndarray, kf_t: np.ndarray, odometry_file: str) -> None:
    """Refuse a keyframe step longer than :data:`MAX_KEYFRAME_STEP_M`, naming its times."""
    if not len(odoms):
        return
    length = np.hypot(odoms[:, 0], odoms[:, 1])
    k = int(np.argmax(length))
    if length[k] > MAX_KEYFRAME_STEP_M:
        raise DatasetError(f"keyframe step {k + 1} (times {kf_t[k]:.3f} to {kf_t[k + 1]:.3f} s) "
                           f"moves {length[k]:.3g} m by the odometry, implausible in the ~10 m "
                           f"MRCLAM arena: {odometry_file} has a corrupt velocity or time "
                           f"stamp between those times")


__all__ = ["KeyframeConfig", "MrclamRobotData", "read_mrclam_robot", "integrate_odometry",
           "odometry_poses_at", "interpolate_poses", "select_keyframes", "import_mrclam",
           "ROBOT_SUBJECTS", "DEFAULT_BEARING_SIGMA_RAD", "DEFAULT_ODOMETRY_MODEL"]
