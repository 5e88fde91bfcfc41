"""Estimates and truth out of bomgraph: TUM, KITTI, CSV and g2o text (issue 17, point 1).

The formats, for a planar pose ``[x_m, y_m, psi_rad]`` lifted to 3-D with ``z = 0`` and a
rotation about ``z`` only:

``tum``
    One line per pose, ``t x y z qx qy qz qw`` with ``q = (0, 0, sin(psi/2), cos(psi/2))``
    (the TUM RGB-D benchmark's trajectory format, which ``evo_ape tum`` reads). ``t`` is the
    step's ``time_s`` when every step of the stream has one, else the step index ``t``.
``kitti``
    One line per pose, the first three rows of the 4x4 ``T_world_robot`` row-major:
    ``r00 r01 r02 x r10 r11 r12 y r20 r21 r22 z``. KITTI has no time column: lines are the poses
    in step order.
``csv``
    ONE file with a ``kind`` column: header ``kind,id,x_m,y_m,psi_rad,time_s``; ``pose`` rows
    (``id`` = step ``t``, ``time_s`` empty when the stream has none), then ``landmark`` rows
    (``psi_rad`` and ``time_s`` empty). An estimate without poses gives landmark rows only.
``g2o``
    The problem (the stream's odometry and bearings) with the estimate as the vertex values:
    ``VERTEX_SE2`` per step, ``VERTEX_XY`` per estimated landmark, ``FIX`` on the first pose,
    ``EDGE_SE2`` per odometry step with the information ``J^T diag(1/sigma^2) J``,
    ``J = diag(R(dth), 1)`` (the inverse of the importer's mapping,
    :func:`bomgraph.datasets.g2o.odometry_sigma_from_information`), and
    ``EDGE_BEARING_SE2_XY`` per bearing with information ``1 / sigma_b^2``. Landmark vertex ids
    are the landmark ids; pose vertex ids are ``max landmark id + 1 + t`` (a stream whose
    last pose id would pass 2^63 - 1, which the importer refuses, is refused). The importer
    (:func:`bomgraph.datasets.import_g2o`) reads the file back to the same steps. A landmark that
    is observed but not in the estimate gets no vertex (its edges stay, and g2o's loader
    drops them without a word; a comment line lists it, :func:`unmapped_landmarks`). The
    stream's sensor range, time stamps and known landmark distances (priors, for which g2o
    has no edge) go into a ``# bomgraph header`` comment that the importer reads.
    Needs an estimate pose at every step. An odometry sigma of 0 (the simulator's
    ``sigma_dy``: its robot moves straight, then turns) has no finite information; it is written
    as :data:`ZERO_SIGMA_FLOOR` (1e-4 m or rad, information 1e8) and a comment line says so, so
    the importer reads that floor back where the stream had 0.

Formats without landmarks (tum, kitti) refuse an estimate without poses; the numbers are written
with ``repr`` precision, so they read back exactly. Writing is atomic (a temporary file beside
the output, then a rename) and refuses to overwrite one of the inputs; ``-`` is left to the
caller (stdout).
"""

from __future__ import annotations

import json
import math
import os
from typing import Any, Sequence

import numpy as np

from .checks import option_named, real
from .datasets.g2o import G2O_HEADER_PREFIX
from .errors import ConfigError, ExportError
from .mapper import MapEstimate, RunResult
from .stream import Stream
from .stream_file import header_to_json


FORMATS = ("tum", "kitti", "csv", "g2o")
ZERO_SIGMA_FLOOR = 1e-4
_CSV = "fmt='csv'"


def truth_estimate(stream: Stream) -> MapEstimate:
    """The stream's ground truth as a :class:`MapEstimate` (poses at every step when the
    truth has them), so that it exports like any estimate."""
    _check_stream(stream, "truth_estimate", needed=True)
    if stream.truth is None:
        raise ExportError("the stream has no truth to export")
    tr = stream.truth
    pose_t = None if tr.poses is None else np.arange(len(tr.poses), dtype=np.int64)
    return MapEstimate(tr.landmark_ids, tr.landmarks_xy, pose_t=pose_t, poses=tr.poses,
                       info={"source": "truth"})


def _check_estimate(src: object, where: str) -> None:
    """Refuse an estimate that is no MapEstimate (naming the likely fix)."""
    if not isinstance(src, MapEstimate):
        hint = (" (result.final, or result.at(t))" if isinstance(src, RunResult) else
                " (its .final)" if hasattr(src, "final") else "")
        raise ExportError(f"{where}(): the estimate must be a MapEstimate, got "
                          f"{type(src).__name__}{hint}")


def _check_stream(stream: object, where: str, *, needed: bool = False) -> None:
    """Refuse a stream that is no Stream (None passes unless ``needed``)."""
    if isinstance(stream, Stream) or stream is None and not needed:
        return
    hint = (" (read the file with bomgraph.read_stream(path))"
            if isinstance(stream, (str, os.PathLike)) else
            " (pass the Stream itself, not its steps or its header)"
            if isinstance(stream, (tuple, list)) or hasattr(stream, "bearing_sigma_rad") else "")
    raise ExportError(f"{where}(): stream must be a bomgraph Stream{'' if needed else ' or None'}"
                      f", got {type(stream).__name__}{hint}")


def _r(v: float) -> str:
    return repr(float(v))


def _check_pose_steps(pose_t: np.ndarray, n_steps: int) -> None:
    """Refuse a pose whose step ``t`` is outside ``0 .. n_steps - 1`` of the stream."""
    outside = pose_t[(pose_t < 0) | (pose_t >= n_steps)]
    if outside.size:
        raise ExportError(f"the estimate has a pose at step {int(outside[0])} but the stream "
                          f"has steps 0..{n_steps - 1}; is it the estimate's stream?")


def _times(pose_t: np.ndarray, stream: Stream | None) -> list[float | None]:
    if stream is not None:  # with or without time stamps, a pose must be one of its steps
        _check_pose_steps(pose_t, len(stream.steps))
    if stream is None or any(s.time_s is None for s in stream.steps):
        return [None] * len(pose_t)
    return [float(stream.steps[int(t)].time_s) for t in pose_t]  # type: ignore[arg-type]


def _need_poses(src: MapEstimate, fmt: str) -> tuple[np.ndarray, np.ndarray]:
    if src.poses is None or src.pose_t is None or len(src.poses) == 0:
        whose = ("the stream's truth has none (landmark truth only)"
                 if src.info.get("source") == "truth" else
                 "this estimate has none (the method maps landmarks only)")
        raise ExportError(f"{fmt} holds robot poses and {whose}; use "
                          f"{option_named('--format csv', _CSV)} for its landmarks")
    order = np.argsort(src.pose_t, kind="stable")
    return src.pose_t[order], src.poses[order]


def to_tum(src: MapEstimate, stream: Stream | None = None) -> str:
    """TUM lines ``t x y z qx qy qz qw`` (module docstring), one per pose in step order."""
    _check_estimate(src, "to_tum")
    _check_stream(stream, "to_tum")
    pose_t, poses = _need_poses(src, "tum")
    times = _times(pose_t, stream)
    lines = ["# bomgraph export: t x y z qx qy qz qw (z = 0, rotation about z; t = "
             + ("time_s" if times and times[0] is not None else "step index") + ")"]
    for t, ts, (x, y, psi) in zip(pose_t, times, poses):
        stamp = _r(ts) if ts is not None else _r(t)
        lines.append(" ".join([stamp, _r(x), _r(y), "0.0", "0.0", "0.0",
                               _r(math.sin(psi / 2)), _r(math.cos(psi / 2))]))
    return "\n".join(lines) + "\n"


def to_kitti(src: MapEstimate) -> str:
    """KITTI lines: the 3x4 ``[R | t]`` of each pose row-major, in step order."""
    _check_estimate(src, "to_kitti")
    _, poses = _need_poses(src, "kitti")
    lines = []
    for x, y, psi in poses:
        c, s = math.cos(psi), math.sin(psi)
        row = [c, -s, 0.0, x, s, c, 0.0, y, 0.0, 0.0, 1.0, 0.0]
        lines.append(" ".join(_r(v) for v in row))
    return "\n".join(lines) + ("\n" if lines else "")


CSV_HEADER = "kind,id,x_m,y_m,psi_rad,time_s"


def to_csv(src: MapEstimate, stream: Stream | None = None) -> str:
    """One CSV with a ``kind`` column (``pose`` rows, then ``landmark`` rows)."""
    _check_estimate(src, "to_csv")
    _check_stream(stream, "to_csv")
    lines = [CSV_HEADER]
    if src.poses is not None and src.pose_t is not None:
        pose_t, poses = _need_poses(src, "csv")
        for t, ts, (x, y, psi) in zip(pose_t, _times(pose_t, stream), poses):
            lines.append(f"pose,{int(t)},{_r(x)},{_r(y)},{_r(psi)},"
                         f"{'' if ts is None else _r(ts)}")
    for i, (x, y) in zip(src.landmark_ids, src.landmarks_xy):
        lines.append(f"landmark,{int(i)},{_r(x)},{_r(y)},,")
    return "\n".join(lines) + "\n"


def odometry_information(dth_rad: float, sigma: np.ndarray) -> np.ndarray:
    """g2o ``EDGE_SE2`` information for independent ``[dx, dy, dpsi]`` sigmas (all > 0).

    The inverse of :func:`bomgraph.datasets.g2o.odometry_sigma_from_information`:
    ``Omega = J^T diag(1/sigma^2) J`` with ``J = diag(R(dth), 1)``, so that
    ``J Omega^-1 J^T = diag(sigma^2)`` (J is orthogonal).
    """
    dth = real(dth_rad, "odometry_information(): dth_rad", ExportError)
    try:
        sig = np.asarray(sigma, dtype=float)
    except (TypeError, ValueError):
        sig = np.zeros(0)
    if not (math.isfinite(dth) and sig.shape == (3,) and np.all(np.isfinite(sig))
            and np.all(sig > 0)):
        raise ExportError(f"odometry_information(): needs a finite dth_rad and 3 finite sigmas "
                          f"> 0 (sigma_dx_m, sigma_dy_m, sigma_dpsi_rad; to_g2o floors a 0 at "
                          f"ZERO_SIGMA_FLOOR), got {dth_rad!r:.20} and {sigma!r:.60}")
    c, s = math.cos(dth), math.sin(dth)
    jac = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return jac.T @ np.diag(1.0 / sig ** 2) @ jac


def g2o_header_comment(stream: Stream) -> str:
    """``# bomgraph header: {"sensor_range_m": ..., "time_s": [...], "priors": [...]}`` for
    ``stream`` (``time_s`` only when every step has one, ``priors`` when the stream has known
    landmark distances): what g2o has no record for, in a comment line (g2o skips ``#`` lines)
    that ``bomgraph import g2o`` reads back (:data:`~bomgraph.datasets.g2o.G2O_HEADER_PREFIX`)."""
    extra: dict[str, Any] = {"sensor_range_m": stream.header.sensor_range_m}
    times = [s.time_s for s in stream.steps]
    if times and all(v is not None for v in times):
        extra["time_s"] = [float(v) for v in times]  # type: ignore[arg-type]
    if stream.header.priors:  # as the stream file writes them
        extra["priors"] = header_to_json(stream.header)["priors"]
    return G2O_HEADER_PREFIX + json.dumps(extra, allow_nan=False, separators=(",", ":"))


#: the largest vertex id ``import g2o`` reads (an int64)
_MAX_G2O_ID = 2**63 - 1


def to_g2o(src: MapEstimate, stream: Stream) -> str:
    """The stream's problem with ``src`` as the vertex values (module docstring)."""
    _check_estimate(src, "to_g2o")
    _check_stream(stream, "to_g2o", needed=True)
    pose_t, poses = _need_poses(src, "g2o")
    n = len(stream.steps)
    _check_pose_steps(pose_t, n)
    by_t = {int(t): p for t, p in zip(pose_t, poses)}
    missing = [t for t in range(n) if t not in by_t]
    if missing:
        raise ExportError(f"g2o needs a pose vertex at every step; the estimate has none at "
                          f"{len(missing)} of {n} steps (first t = {missing[0]})")
    observed = stream.landmark_ids()
    all_ids = np.concatenate([observed, src.landmark_ids]).astype(np.int64)
    base = int(all_ids.max()) + 1 if all_ids.size else 0
    if base + n - 1 > _MAX_G2O_ID:  # h96: written, then refused by `import g2o`
        # the stream's id, unless the estimate's alone (h101: named the estimate file)
        error = StreamExportError if base - 1 in observed else ExportError
        raise error(f"g2o: pose vertex ids are the largest landmark id + 1 + t, and "
                    f"landmark id {base - 1} leaves no room for {n} poses below 2^63 "
                    f"(the ids g2o and bomgraph read); renumber the landmarks")
    lm = {int(i): xy for i, xy in zip(src.landmark_ids, src.landmarks_xy)}
    lines = ["# bomgraph export: bearing-only 2-D SLAM problem with the estimate as vertex "
             f"values; pose vertex id = {base} + t", g2o_header_comment(stream)]
    if stream.header.priors:
        lines.append(f"# {len(stream.header.priors)} known landmark distances (the stream's "
                     f"priors) are in the bomgraph header only: g2o has no edge for them")
    unmapped, _ = unmapped_landmarks(src, stream)
    if unmapped:
        lines.append(f"# observed landmarks without an estimate (no VERTEX_XY): "
                     f"{' '.join(str(i) for i in unmapped)}")
    for t in range(n):
        x, y, psi = by_t[t]
        lines.append(f"VERTEX_SE2 {base + t} {_r(x)} {_r(y)} {_r(psi)}")
    for i in sorted(lm):
        lines.append(f"VERTEX_XY {i} {_r(lm[i][0])} {_r(lm[i][1])}")
    lines.append(f"FIX {base}")
    w_b = 1.0 / stream.header.bearing_sigma_rad ** 2
    floored = False
    for step in stream.steps:
        if step.odom is not None:
            sig = step.odometry_sigma(stream.header)
            if np.any(sig <= 0):
                sig = np.where(sig > 0, sig, ZERO_SIGMA_FLOOR)
                if not floored:
                    lines.insert(1, f"# odometry sigmas of 0 written as {ZERO_SIGMA_FLOOR!r} "
                                    f"(g2o needs a positive definite information matrix)")
                    floored = True
            info = odometry_information(float(step.odom[2]), sig)
            upper = [info[0, 0], info[0, 1], info[0, 2], info[1, 1], info[1, 2], info[2, 2]]
            lines.append(f"EDGE_SE2 {base + step.t - 1} {base + step.t} "
                         + " ".join(_r(v) for v in step.odom) + " "
                         + " ".join(_r(v) for v in upper))
        for lid, brg in zip(step.landmark_ids, step.bearings_rad):
            lines.append(f"EDGE_BEARING_SE2_XY {base + step.t} {int(lid)} {_r(brg)} {_r(w_b)}")
    return "\n".join(lines) + "\n"


def unmapped_landmarks(src: MapEstimate, stream: Stream) -> tuple[list[int], int]:
    """The landmarks ``stream`` observes that ``src`` has no position for (no ``VERTEX_XY``
    in its g2o export), and how many of the stream's bearings are to them: g2o's loader
    drops an edge to a missing vertex without a word, so those bearings are not in the
    problem g2o optimises."""
    mapped = set(src.landmark_ids.tolist())
    unmapped = [int(i) for i in stream.landmark_ids() if int(i) not in mapped]
    lost = set(unmapped)
    n_bearings = sum(sum(int(i) in lost for i in step.landmark_ids.tolist())
                     for step in stream.steps) if lost else 0
    return unmapped, n_bearings


class StreamExportError(ExportError):
    """An export refused for what the stream holds (not the estimate)."""


def export_text(src: MapEstimate, fmt: str, stream: Stream | None = None, *,
                name: str | None = None, stream_name: str | None = None) -> str:
    """The text of ``src`` in format ``fmt`` (one of :data:`FORMATS`); ``name``, the file
    ``src`` was read from (``-``: stdin), starts the message of what it lacks for ``fmt``;
    ``stream_name``, the stream's, the message of what the stream holds that ``fmt`` cannot
    (a :class:`StreamExportError`; ``name`` when not given)."""
    _check_estimate(src, "export_text")
    _check_stream(stream, "export_text")
    try:
        return _export_text(src, fmt, stream)
    except ExportError as exc:  # h91: a refusal named neither the estimate nor its line
        whose = stream_name if isinstance(exc, StreamExportError) and stream_name else name
        if whose is None:
            raise
        raise type(exc)(f"{'<stdin>' if whose == '-' else whose}: {exc}") from None


def _export_text(src: MapEstimate, fmt: str, stream: Stream | None) -> str:
    if fmt == "tum":
        return to_tum(src, stream)
    if fmt == "kitti":
        return to_kitti(src)
    if fmt == "csv":
        return to_csv(src, stream)
    if fmt == "g2o":
        if stream is None:
            raise ExportError(f"g2o holds the measurements too: give the stream "
                              f"({option_named('--stream', 'stream')})")
        return to_g2o(src, stream)
    raise ConfigError(f"unknown export format {fmt!r}; choose one of {', '.join(FORMATS)}")


def write_text_atomic(text: str, path: str | os.PathLike[str],
                      inputs: Sequence[str | os.PathLike[str]] = ()) -> None:
    """Write ``text`` to ``path`` as every bomgraph output is (:func:`bomgraph.stdio.
    output_file`: atomically, links followed, devices written directly), refusing an input
    file."""
    from .stdio import OutputPathError, write_text

    try:
        write_text(path, text, inputs=inputs)
    except OutputPathError as exc:
        raise ExportError(str(exc)) from None


__all__ = ["FORMATS", "ZERO_SIGMA_FLOOR", "CSV_HEADER", "g2o_header_comment", "ExportError",
           "MapEstimate", "export_text", "to_tum", "to_kitti", "to_csv", "to_g2o",
           "odometry_information", "write_text_atomic", "StreamExportError",
           "unmapped_landmarks"]
