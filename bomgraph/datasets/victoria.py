"""GTSAM's pre-processed Victoria Park file -> a bearing-only :class:`~bomgraph.stream.Stream`.

Issue 7, part 3 (``shared/data/victoria_park/SOURCE.md``). The file has two records::

    ODOMETRY i j dx dy dtheta c_xx c_xy c_xth c_yy c_yth c_thth
    LANDMARK i l x y c_xx c_xy c_yy

``ODOMETRY`` is the motion from pose i to pose j in the frame of pose i, with the upper
triangle of its COVARIANCE (GTSAM's ``load2D`` reads it so). ``LANDMARK`` is landmark l seen
from pose i as a point ``(x, y)`` in the robot frame (x forward, y left) with its covariance.

Conversion:

- Steps follow the ``ODOMETRY`` chain (poses and landmarks share one id space in the file;
  pose ids skip the landmark ids, so the chain, not the id, gives the step index). Landmark
  ids in the stream are the file's landmark ids.
- Bearing ``atan2(y, x)``; the range ``hypot(x, y)`` is dropped (bearing-only).
- Odometry sigmas: the covariance is that of a GTSAM ``BetweenFactor<Pose2>``, whose error
  is in the frame of the measured pose j; it is turned by ``dtheta`` into the frame of pose i,
  where a stream's ``[dx, dy, dpsi]`` sigmas are (the same mapping as the g2o importer's,
  :func:`.g2o.odometry_sigma_from_information`), and the square roots of that diagonal are
  kept (the file's off-diagonal entries are all zero, but the turn correlates dx and dy when
  their sigmas differ; the largest dropped correlation goes to meta). Uniform sigmas go to
  the header; otherwise each step carries its own ``odom_sigma``. A header turn sigma above
  pi/sqrt(3) ("turn unknown") would read as degrees: the steps then carry their own and the
  header's is capped at pi/sqrt(3), as in the g2o importer.
- Bearing sigma: the point covariance ``C`` propagated to the bearing,
  ``var = g C g^T`` with ``g = [-y, x] / r^2``; the header holds the median over all
  measurements (a stream has one bearing sigma; the spread goes to meta). GTSAM's own example
  uses ``sqrt(c_xx / 10)`` (0.2 rad for this file); it is recorded in meta. Pass
  ``bearing_sigma_rad`` to choose another value.
- There is no ground truth and there are no time stamps. Near-zero odometry steps (the
  vehicle standing still) are kept as they are.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DatasetError
from ..plausibility import refuse_implausible
from ..stream import Step, Stream, StreamHeader
from .g2o import checked_sigma, header_odometry_sigma, odometry_sigma_from_information
from ._text import (MAX_RECORD_FILE_BYTES, chain_order, checked_bearing_sigma, dataset_error,
                    file_label, parse_float, parse_int, read_lines)

_RECORDS = {
    "ODOMETRY": ["i", "j", "dx", "dy", "dtheta", "c_xx", "c_xy", "c_xth", "c_yy", "c_yth",
                 "c_thth"],
    "LANDMARK": ["i", "l", "x", "y", "c_xx", "c_xy", "c_yy"],
}


def victoria_inputs(path: str | os.PathLike[str]) -> dict[str, Path]:
    """Role -> the file :func:`import_victoria` reads: what a recording's cache key hashes."""
    return {"data": Path(path)}


def import_victoria(path: str | os.PathLike[str], *,
                    bearing_sigma_rad: float | None = None) -> Stream:
    """Import GTSAM's ``victoria_park.txt`` (see the module docstring).

    Parameters
    ----------
    path : path-like
        The text file.
    bearing_sigma_rad : float, optional
        Overrides the header's bearing sigma (default: median propagated point covariance).

    Returns
    -------
    Stream
        One step per pose of the odometry chain, no truth.

    Raises
    ------
    DatasetError
        A malformed line (file, line, field), a covariance that is not positive definite, a
        landmark seen from a pose off the chain, or the same landmark twice from one pose.
    """
    p = Path(path)
    odo: list[tuple[int, int, int, np.ndarray, np.ndarray]] = []
    obs: list[tuple[int, int, int, float, float, float]] = []
    for line in read_lines(p, max_bytes=MAX_RECORD_FILE_BYTES):
        tag = line.tokens[0]
        if tag not in _RECORDS:
            raise dataset_error(p, line.number, "tag",
                                f"unknown record {tag[:40]!r}; expected ODOMETRY or LANDMARK")
        names = _RECORDS[tag]
        if len(line.tokens) - 1 != len(names):
            raise dataset_error(p, line.number, None,
                                f"{tag} needs {len(names)} fields ({' '.join(names)}), got "
                                f"{len(line.tokens) - 1}; fix or delete this line")
        v: dict[str, Any] = {}
        for name, tok in zip(names, line.tokens[1:]):
            if name in ("i", "j", "l"):
                v[name] = parse_int(tok, p, line.number, name)
                if v[name] < 0:
                    raise dataset_error(p, line.number, name, f"id must be >= 0, got "
                                                              f"{v[name]}")
            else:
                v[name] = parse_float(tok, p, line.number, name)
        if tag == "ODOMETRY":
            cov = np.array([[v["c_xx"], v["c_xy"], v["c_xth"]],
                            [v["c_xy"], v["c_yy"], v["c_yth"]],
                            [v["c_xth"], v["c_yth"], v["c_thth"]]])
            if not np.all(np.linalg.eigvalsh(cov) > 0):
                raise dataset_error(p, line.number, "covariance",
                                    "the odometry covariance is not positive definite")
            odo.append((v["i"], v["j"], line.number,
                        np.array([v["dx"], v["dy"], v["dtheta"]]), cov))
        else:
            cov2 = np.array([[v["c_xx"], v["c_xy"]], [v["c_xy"], v["c_yy"]]])
            if not np.all(np.linalg.eigvalsh(cov2) > 0):
                raise dataset_error(p, line.number, "covariance",
                                    "the landmark point covariance is not positive definite")
            x, y = v["x"], v["y"]
            r2 = x * x + y * y
            if r2 == 0:
                raise dataset_error(p, line.number, "x", "the point (0, 0) has no bearing")
            g = np.array([-y, x]) / r2
            obs.append((v["i"], v["l"], line.number, math.atan2(y, x),
                        float(math.sqrt(g @ cov2 @ g)), v["c_xx"]))

    order = chain_order([(i, j, n) for i, j, n, _, _ in odo], p)
    if not order:
        observers = sorted({o[0] for o in obs})
        if len(observers) != 1:
            raise dataset_error(p, None, None, "no ODOMETRY records joining the poses; nothing "
                                               "to import as one chain")
        order = observers
    step_of = {pid: t for t, pid in enumerate(order)}

    by_target = {j: (meas, cov) for _, j, _, meas, cov in odo}
    line_of = {j: n for _, j, n, _, _ in odo}
    odoms = np.zeros((len(order) - 1, 3))
    sig = np.zeros((len(order) - 1, 3))
    max_corr = 0.0
    for t, pid in enumerate(order[1:]):
        meas, cov = by_target[pid]
        odoms[t] = meas
        with np.errstate(all="ignore"):
            sigma, corr = odometry_sigma_from_information(float(meas[2]), np.linalg.inv(cov))
        sig[t] = checked_sigma(sigma, p, line_of[pid], "covariance")
        max_corr = max(max_corr, corr)
    header_odo, uniform = header_odometry_sigma(sig)

    per_step: list[dict[int, float]] = [{} for _ in order]
    first_line: dict[tuple[int, int], int] = {}
    sig_b = []
    gtsam_sig = []
    for i, lid, n, brg, sb, cxx in obs:
        if i not in step_of:
            raise dataset_error(p, n, "i", f"landmark seen from pose {i}, which is not on the "
                                           f"odometry chain")
        if lid in step_of:
            raise dataset_error(p, n, "l", f"landmark id {lid} is also a pose id")
        if (i, lid) in first_line:
            raise dataset_error(p, n, None, f"landmark {lid} seen a second time from pose {i} "
                                            f"(first on line {first_line[(i, lid)]}); one "
                                            f"landmark appears at most once per step")
        first_line[(i, lid)] = n
        per_step[step_of[i]][lid] = brg
        sig_b.append(sb)
        gtsam_sig.append(math.sqrt(cxx / 10.0))
    sig_b_arr = np.array(sig_b)

    if bearing_sigma_rad is not None:
        sigma_b = checked_bearing_sigma(bearing_sigma_rad)
        source = "given by the caller"
    elif sig_b_arr.size:
        sigma_b = float(np.median(sig_b_arr))
        source = "median of the point covariances propagated to the bearing"
    else:
        raise dataset_error(p, None, None, "no LANDMARK records, so no bearing sigma; pass "
                                           "bearing_sigma_rad")

    steps = []
    for t, lms in enumerate(per_step):
        ids = np.array(sorted(lms), dtype=np.int64)
        steps.append(Step(t=t, odom=None if t == 0 else odoms[t - 1], landmark_ids=ids,
                          bearings_rad=np.array([lms[k] for k in ids.tolist()]),
                          odom_sigma=None if (t == 0 or uniform) else sig[t - 1]))
    meta: dict[str, Any] = {
        "source": "Victoria Park (J. Guivant, E. Nebot, ACFR, University of Sydney), as "
                  "pre-processed in GTSAM's examples/Data/victoria_park.txt",
        "licence": "GTSAM is BSD; the data file has no licence of its own: credit the authors",
        "files": {"data": file_label(p)},
        "importer": "bomgraph.datasets.victoria.import_victoria",
        "n_odometry": len(odo), "n_landmark_records": len(obs),
        "ranges_dropped": len(obs),
        "odometry_sigma_source": "sqrt of the ODOMETRY covariance diagonal",
        "odometry_sigma_per_step": not uniform,
        "odometry_max_dropped_correlation": max_corr,
        "bearing_sigma_source": source,
        "bearing_sigma_propagated_rad": ({"min": float(sig_b_arr.min()),
                                          "median": float(np.median(sig_b_arr)),
                                          "max": float(sig_b_arr.max())}
                                         if sig_b_arr.size else None),
        "bearing_sigma_gtsam_example_rad": float(np.median(gtsam_sig)) if gtsam_sig else None,
        "ground_truth": "none",
    }
    header = StreamHeader(bearing_sigma_rad=sigma_b, odometry_sigma=header_odo, meta=meta)
    refuse_implausible(header, steps, DatasetError, str(p),
                       odom_lines=[line_of[pid] for pid in order[1:]])
    return Stream(header, tuple(steps), None)


__all__ = ["import_victoria", "victoria_inputs"]
