"""Checking a landmark truth table against the recording's own range-bearing detections.

A map is scored against ``Landmark_Groundtruth.dat``; if that table lists two landmarks at
each other's positions (or the barcode table maps their barcodes the wrong way round), every
method's map is "wrong" by the distance between them, whatever it does. That happened with
MRCLAM Dataset 1 (docs/measurements.md): every method scored about 1 m MPE because subjects 11
and 17 are exchanged. The check below needs no robot ground truth and no mapping:

- **Pair distances.** Two landmarks ``a``, ``b`` detected in one camera frame (the same time
  stamp) at range ``r`` and bearing ``beta`` are ``|r_a e^(i beta_a) - r_b e^(i beta_b)|``
  apart, whatever the robot's pose (and whatever the bearing sign convention). The residual is
  that minus the distance the truth table gives. Per landmark, the median absolute residual
  over all its pairs is its *pair error*; a landmark whose pair error exceeds
  :data:`MAX_PAIR_ERROR_M` (with at least :data:`MIN_PAIRS` pairs) contradicts the
  detections. On MRCLAM the consistent landmarks give 0.01-0.23 m (camera ranges are coarse),
  the exchanged ones 2.7-6.0 m.
- **Swap suggestion.** When landmarks fail, every exchange of two table rows is tried; one
  that leaves no failing landmark is named in the error.
- **Errata.** :data:`KNOWN_ERRATA` lists exchanges established that way for published
  tables, matched by the listed coordinates (so line endings or compression do not matter);
  :func:`apply_errata` corrects a matching table and says so (``meta["landmark_truth"]``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..errors import DatasetError, shown_path
from .mrclam_files import MrclamRobotData

MAX_PAIR_ERROR_M = 0.5
"""A landmark whose median pair-distance residual exceeds this contradicts the detections."""

MIN_PAIRS = 10
"""Landmarks in fewer simultaneous pairs than this are not judged."""

_MATCH_TOL_M = 1e-6


@dataclass(frozen=True)
class LandmarkErratum:
    """Two rows of a published landmark table that list each other's positions.

    ``listed`` holds the two rows as the faulty table gives them, ``{subject: (x_m, y_m)}``;
    a table with exactly these values has the two positions exchanged back.
    """

    dataset: str
    listed: Mapping[int, tuple[float, float]]
    evidence: str

    @property
    def swap(self) -> tuple[int, int]:
        a, b = sorted(self.listed)
        return int(a), int(b)


KNOWN_ERRATA: tuple[LandmarkErratum, ...] = (
    LandmarkErratum(
        dataset="UTIAS MRCLAM Dataset 1 (Landmark_Groundtruth.dat md5 02eac755...)",
        listed={11: (3.15071999, 2.38294871), 17: (0.03596156, -2.84396626)},
        evidence="the range-bearing pair distances of all 5 robots: pair error of subjects 11 "
                 "and 17 2.7-6.0 m as listed, 0.08-0.18 m exchanged (the other 13: "
                 "0.03-0.23 m); the exchanged table is also what "
                 "DanielIngham/Cooperative-Positioning-Data-Handler ships. Whether "
                 "Landmark_Groundtruth.dat or Barcodes.dat (barcodes 18, 61) is at fault "
                 "cannot be told from the data; for scoring both are the same correction"),
)


def apply_errata(landmark_ids: np.ndarray, landmarks_xy: np.ndarray,
                 errata: tuple[LandmarkErratum, ...] = KNOWN_ERRATA
                 ) -> tuple[np.ndarray, list[dict[str, Any]]]:
    """Correct a landmark table that matches a known erratum.

    Parameters
    ----------
    landmark_ids : ndarray of shape (n,), int
    landmarks_xy : ndarray of shape (n, 2), metres
    errata : the errata to match

    Returns
    -------
    xy : ndarray of shape (n, 2)
        A corrected copy (unchanged values when nothing matched).
    applied : list of dict
        One ``{"dataset", "swapped", "evidence"}`` per erratum applied.
    """
    ids = np.asarray(landmark_ids).tolist()
    xy = np.array(landmarks_xy, dtype=float, copy=True).reshape(-1, 2)
    applied: list[dict[str, Any]] = []
    for err in errata:
        if not all(s in ids for s in err.listed):
            continue
        rows = {s: ids.index(s) for s in err.listed}
        if all(np.max(np.abs(xy[rows[s]] - np.asarray(p))) <= _MATCH_TOL_M
               for s, p in err.listed.items()):
            a, b = err.swap
            xy[[rows[a], rows[b]]] = xy[[rows[b], rows[a]]]
            applied.append({"dataset": err.dataset, "swapped": [a, b],
                            "evidence": err.evidence})
    return xy, applied


def pair_distance_residuals(time_s: np.ndarray, subject: np.ndarray, range_m: np.ndarray,
                            bearing_rad: np.ndarray, landmark_ids: np.ndarray,
                            landmarks_xy: np.ndarray
                            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Measured minus tabulated distance of every pair of landmarks detected together.

    Parameters
    ----------
    time_s, subject, range_m, bearing_rad : ndarray of shape (m,)
        Detections (rows whose subject is not in ``landmark_ids`` are ignored); detections
        with the same time stamp are one camera frame.
    landmark_ids : ndarray of shape (n,)
    landmarks_xy : ndarray of shape (n, 2)

    Returns
    -------
    a, b : ndarray of shape (p,), int64
        Row indices into ``landmark_ids`` of each pair (``a != b``).
    residual_m : ndarray of shape (p,)
    """
    known = np.isin(np.asarray(subject), landmark_ids)
    t = np.asarray(time_s, dtype=float)[known]
    order = np.argsort(t, kind="stable")
    t = t[order]
    row = np.searchsorted(np.sort(landmark_ids), np.asarray(subject)[known][order])
    row = np.argsort(landmark_ids)[np.clip(row, 0, len(landmark_ids) - 1)]
    z = (np.asarray(range_m, dtype=float) * np.exp(1j * np.asarray(bearing_rad, dtype=float))
         )[known][order]
    starts = np.flatnonzero(np.r_[True, np.diff(t) != 0])
    ends = np.r_[starts[1:], t.size]
    ia, ib = [], []
    for s, e in zip(starts, ends):
        if e - s >= 2:
            i, j = np.triu_indices(e - s, 1)
            ia.append(s + i)
            ib.append(s + j)
    if not ia:
        z0 = np.zeros(0, dtype=np.int64)
        return z0, z0, np.zeros(0)
    ia, ib = np.concatenate(ia), np.concatenate(ib)
    keep = row[ia] != row[ib]
    ia, ib = ia[keep], ib[keep]
    xy = np.asarray(landmarks_xy, dtype=float)
    tab = np.hypot(*(xy[row[ia]] - xy[row[ib]]).T)
    return row[ia].astype(np.int64), row[ib].astype(np.int64), np.abs(z[ia] - z[ib]) - tab


def _pair_errors(a: np.ndarray, b: np.ndarray, residual_m: np.ndarray, n: int
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Per landmark row: median absolute residual over its pairs (NaN without), pair count."""
    rows = np.concatenate([a, b])
    res = np.abs(np.concatenate([residual_m, residual_m]))
    err = np.full(n, np.nan)
    count = np.bincount(rows, minlength=n)
    for k in np.flatnonzero(count):
        err[k] = float(np.median(res[rows == k]))
    return err, count


def check_landmark_table(time_s: np.ndarray, subject: np.ndarray, range_m: np.ndarray,
                         bearing_rad: np.ndarray, landmark_ids: np.ndarray,
                         landmarks_xy: np.ndarray) -> dict[str, Any]:
    """Judge a landmark table by the pair distances of the detections (module docstring).

    Parameters are those of :func:`pair_distance_residuals`.

    Returns
    -------
    dict
        ``n_pairs``; ``pair_error_m`` ``{id: [median |residual| m, n_pairs]}`` for every
        landmark seen in a pair; ``failing`` (ids beyond :data:`MAX_PAIR_ERROR_M` with at
        least :data:`MIN_PAIRS` pairs); ``swap`` (two ids whose exchange leaves no landmark
        failing, or None); ``max_pair_error_m`` among the judged landmarks (None if none).
    """
    ids = np.asarray(landmark_ids)
    xy = np.asarray(landmarks_xy, dtype=float)
    a, b, r = pair_distance_residuals(time_s, subject, range_m, bearing_rad, ids, xy)
    n = len(ids)

    def failing(residual: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        err, count = _pair_errors(a, b, residual, n)
        judged = count >= MIN_PAIRS
        return judged & (err > MAX_PAIR_ERROR_M), err, judged

    bad, err, judged = failing(r)
    swap = None
    if bad.any():
        measured = r + np.hypot(*(xy[a] - xy[b]).T)
        for i, j in zip(*np.triu_indices(n, 1)):
            p = np.arange(n)
            p[i], p[j] = j, i
            if not failing(measured - np.hypot(*(xy[p[a]] - xy[p[b]]).T))[0].any():
                swap = [int(ids[i]), int(ids[j])]
                break
    return {"n_pairs": int(r.size),
            "pair_error_m": {int(ids[k]): [float(err[k]), int(c)] for k, c in
                             enumerate(np.bincount(np.r_[a, b], minlength=n)) if c},
            "failing": [int(v) for v in ids[bad]], "swap": swap,
            "max_pair_error_m": float(np.max(err[judged])) if judged.any() else None,
            "limits": {"max_pair_error_m": MAX_PAIR_ERROR_M, "min_pairs": MIN_PAIRS}}


def checked_mrclam_landmarks(raw: MrclamRobotData, data_dir: str | os.PathLike[str],
                             robot: int) -> tuple[MrclamRobotData, dict[str, Any]]:
    """:func:`apply_errata` then :func:`check_landmark_table` for one MRCLAM robot's files.

    Returns the raw data with the corrected table and ``{"errata_applied", "check"}`` (the
    importer's ``meta["landmark_truth"]``).

    Raises
    ------
    DatasetError
        When landmarks fail the check (naming them, their pair errors and the exchange of two
        rows that explains the detections, if one does).
    """
    xy, applied = apply_errata(raw.landmark_ids, raw.landmarks_xy)
    raw = replace(raw, landmarks_xy=xy)
    me = raw.measurements
    subject = np.array([raw.barcode_subject.get(b, -1) for b in me["barcode"].tolist()],
                       dtype=np.int64)
    check = check_landmark_table(me["time_s"], subject, me["range_m"], me["bearing_rad"],
                                 raw.landmark_ids, raw.landmarks_xy)
    if check["failing"]:
        bad = ", ".join(f"{i} ({check['pair_error_m'][i][0]:.2f} m over "
                        f"{check['pair_error_m'][i][1]} pairs)" for i in check["failing"])
        hint = (f"exchanging landmarks {check['swap'][0]} and {check['swap'][1]} explains "
                f"the detections, so the two rows (or their barcodes) are swapped"
                if check["swap"] else "no exchange of two rows explains it")
        raise DatasetError(
            f"{shown_path(Path(data_dir))}: robot {robot}: {raw.files.get('landmarks')} "
            f"contradicts the "
            f"measured ranges and bearings: landmarks seen together lie farther from their "
            f"tabulated distance than {check['limits']['max_pair_error_m']} m (median): {bad}; "
            f"{hint}. Every map would be scored against wrong positions: fix the table (or "
            f"Barcodes.dat), or import anyway with landmark_check=False "
            f"(CLI: --no-landmark-check)")
    return raw, {"errata_applied": applied, "check": check}


__all__ = ["LandmarkErratum", "KNOWN_ERRATA", "apply_errata", "pair_distance_residuals",
           "check_landmark_table", "checked_mrclam_landmarks", "MAX_PAIR_ERROR_M", "MIN_PAIRS"]
