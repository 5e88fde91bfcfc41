"""Reading the files of one UTIAS MRCLAM robot into raw tables (``.dat`` or ``.dat.gz``).

:func:`read_mrclam_robot` reads ``Barcodes.dat``, ``Landmark_Groundtruth.dat`` and the robot's
``RobotN_Odometry.dat``, ``RobotN_Measurement.dat`` and (if present) ``RobotN_Groundtruth.dat``
(``shared/data/mrclam*/SOURCE.md``), checks them (time order, no repeated barcode or landmark,
no negative range) and returns them unchanged: times in Unix seconds, metres, radians.
:mod:`~bomgraph.datasets.mrclam` turns them into keyframes.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import numpy as np

from ..errors import DatasetError, shown_path
from ._text import dataset_error, file_label, file_read, find_file, has_file, read_table

ROBOT_SUBJECTS = (1, 2, 3, 4, 5)
"""Subject numbers of the five robots (dataset rule, SOURCE.md quirk 1)."""


@dataclass(frozen=True)
class MrclamRobotData:
    """The raw tables of one robot, as read (times in Unix seconds).

    Attributes
    ----------
    barcode_subject : dict of int to int
        Barcode number -> subject number.
    landmark_ids : ndarray of shape (n,), int64
    landmarks_xy : ndarray of shape (n, 2)
    odometry : dict with "time_s", "v_mps", "w_radps", each (k,)
    measurements : dict with "time_s", "barcode", "range_m", "bearing_rad", each (m,)
    groundtruth : dict with "time_s", "x_m", "y_m", "psi_rad", each (g,), or None
    files : dict of role -> file name
    """

    barcode_subject: Mapping[int, int]
    landmark_ids: np.ndarray
    landmarks_xy: np.ndarray
    odometry: Mapping[str, np.ndarray]
    measurements: Mapping[str, np.ndarray]
    groundtruth: Mapping[str, np.ndarray] | None
    files: Mapping[str, str]


def mrclam_file_names(robot: int) -> dict[str, str]:
    """Role -> name of each file :func:`read_mrclam_robot` reads for ``robot`` (each as it is
    or gzip-compressed, ``NAME.gz``); ``groundtruth`` only if it is there."""
    return {"barcodes": "Barcodes.dat", "landmarks": "Landmark_Groundtruth.dat",
            "odometry": f"Robot{robot}_Odometry.dat",
            "measurements": f"Robot{robot}_Measurement.dat",
            "groundtruth": f"Robot{robot}_Groundtruth.dat"}


def mrclam_inputs(data_dir: str | os.PathLike[str], robot: int) -> dict[str, Path | None]:
    """Role -> the file :func:`read_mrclam_robot` reads for ``robot`` (of
    :func:`mrclam_file_names`), None where there is none (the importer says why, or, for
    ``groundtruth``, does without): what a recording's cache key hashes."""
    return {role: file_read(data_dir, name) for role, name in mrclam_file_names(robot).items()}


def _check_sorted(path: Path, time_s: np.ndarray, lines: np.ndarray) -> None:
    bad = np.flatnonzero(np.diff(time_s) < 0)
    if bad.size:
        k = int(bad[0]) + 1
        raise dataset_error(path, int(lines[k]), "time",
                            f"time {time_s[k]:.3f} is earlier than the previous row's "
                            f"{time_s[k - 1]:.3f}; rows must be in time order (sort the file)")


#: plausibility (issue 13, item 20): the MRCLAM robots drive below 0.1 m/s and turn below
#: 0.6 rad/s, see ranges below 9 m, in an arena of about 10 m; a value 50-100 times beyond
#: is a corrupt file (one such velocity made a 2e10 m keyframe step).
MAX_SPEED_MPS = 5.0
MAX_TURN_RATE_RADPS = 30.0
MAX_RANGE_M = 1000.0
MAX_COORDINATE_M = 1000.0


def _check_within(path: Path, lines: np.ndarray, table: dict[str, np.ndarray],
                  limits: dict[str, float]) -> None:
    """Refuse the first row whose ``|field|`` exceeds its limit, naming file, line, field."""
    for field, limit in limits.items():
        bad = np.flatnonzero(np.abs(table[field]) > limit)
        if bad.size:
            k = int(bad[0])
            raise dataset_error(path, int(lines[k]), field,
                                f"{table[field][k]:g} is implausible for MRCLAM (|{field}| "
                                f"above {limit:g}); the file is corrupt: fix or delete this "
                                f"line")


def read_mrclam_robot(data_dir: str | os.PathLike[str], robot: int) -> MrclamRobotData:
    """Read the files of one MRCLAM robot (``.dat`` or ``.dat.gz``).

    Parameters
    ----------
    data_dir : path-like
        The dataset folder (e.g. ``shared/data/mrclam6``).
    robot : int
        1..5.

    Returns
    -------
    MrclamRobotData
        ``groundtruth`` is None when ``RobotN_Groundtruth.dat`` is absent (mrclam1).

    Raises
    ------
    DatasetError
        On a missing file or a malformed line (naming file, line and field).
    """
    if isinstance(robot, bool) or not isinstance(robot, (int, np.integer)) \
            or robot not in ROBOT_SUBJECTS:
        raise DatasetError(f"robot must be one of 1, 2, 3, 4, 5, got {robot!r}")
    d = Path(data_dir)
    if not d.is_dir():
        raise DatasetError(f"{shown_path(d)}: not a directory; pass the MRCLAM dataset folder")
    files: dict[str, str] = {}
    names = mrclam_file_names(robot)

    p = find_file(d, names["barcodes"])
    files["barcodes"] = file_label(p)
    bc, bc_lines = read_table(p, [("subject", "int"), ("barcode", "int")])
    seen: dict[int, int] = {}
    for k, (s, b) in enumerate(zip(bc["subject"].tolist(), bc["barcode"].tolist())):
        if b in seen:
            raise dataset_error(p, int(bc_lines[k]), "barcode",
                                f"barcode {b} is listed twice (subjects {seen[b]} and {s}); "
                                f"each barcode must name one subject")
        seen[b] = s

    p = find_file(d, names["landmarks"])
    files["landmarks"] = file_label(p)
    lm, lm_lines = read_table(p, [("subject", "int"), ("x", "float"), ("y", "float"),
                                  ("x_std", "float"), ("y_std", "float")])
    _check_within(p, lm_lines, lm, {"x": MAX_COORDINATE_M, "y": MAX_COORDINATE_M})
    ids = lm["subject"]
    _, first_index = np.unique(ids, return_index=True)
    dup = np.setdiff1d(np.arange(ids.size), first_index)
    if dup.size:
        k = int(dup[0])
        raise dataset_error(p, int(lm_lines[k]), "subject",
                            f"landmark {int(ids[k])} is listed twice; keep one row")
    robots_in_lm = np.isin(ids, ROBOT_SUBJECTS)
    if robots_in_lm.any():
        k = int(np.flatnonzero(robots_in_lm)[0])
        raise dataset_error(p, int(lm_lines[k]), "subject",
                            f"subject {int(ids[k])} is a robot (1-5), not a landmark")

    p = find_file(d, names["odometry"])
    files["odometry"] = file_label(p)
    od, od_lines = read_table(p, [("time", "float"), ("v", "float"), ("w", "float")])
    if od["time"].size < 2:
        raise DatasetError(f"{shown_path(p)}: needs at least 2 odometry rows to integrate, got "
                           f"{od['time'].size}")
    _check_sorted(p, od["time"], od_lines)
    _check_within(p, od_lines, od, {"v": MAX_SPEED_MPS, "w": MAX_TURN_RATE_RADPS})

    p = find_file(d, names["measurements"])
    files["measurements"] = file_label(p)
    me, me_lines = read_table(p, [("time", "float"), ("barcode", "int"), ("range", "float"),
                                  ("bearing", "float")])
    _check_sorted(p, me["time"], me_lines)
    neg = np.flatnonzero(me["range"] < 0)
    if neg.size:
        k = int(neg[0])
        raise dataset_error(p, int(me_lines[k]), "range",
                            f"negative range {me['range'][k]}; fix or delete this line")

    _check_within(p, me_lines, me, {"range": MAX_RANGE_M})

    gt = None
    if has_file(d, names["groundtruth"]):
        p = find_file(d, names["groundtruth"])
        files["groundtruth"] = file_label(p)
        g, g_lines = read_table(p, [("time", "float"), ("x", "float"), ("y", "float"),
                                    ("heading", "float")])
        if g["time"].size < 2:
            raise DatasetError(f"{shown_path(p)}: needs at least 2 ground-truth rows to "
                               f"interpolate")
        _check_sorted(p, g["time"], g_lines)
        _check_within(p, g_lines, g, {"x": MAX_COORDINATE_M, "y": MAX_COORDINATE_M})
        gt = {"time_s": g["time"], "x_m": g["x"], "y_m": g["y"], "psi_rad": g["heading"]}

    return MrclamRobotData(
        barcode_subject=seen, landmark_ids=ids,
        landmarks_xy=np.column_stack([lm["x"], lm["y"]]),
        odometry={"time_s": od["time"], "v_mps": od["v"], "w_radps": od["w"]},
        measurements={"time_s": me["time"], "barcode": me["barcode"], "range_m": me["range"],
                      "bearing_rad": me["bearing"]},
        groundtruth=gt, files=files)


__all__ = ["MrclamRobotData", "read_mrclam_robot", "mrclam_file_names", "mrclam_inputs",
           "ROBOT_SUBJECTS", "MAX_SPEED_MPS", "MAX_TURN_RATE_RADPS", "MAX_RANGE_M",
           "MAX_COORDINATE_M"]
