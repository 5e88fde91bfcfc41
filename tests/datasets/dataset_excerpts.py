"""Synthetic excerpts of the real dataset formats, written by the tests of tests/datasets/.

Small MRCLAM folders, g2o files and Victoria Park lines with exact answers known; ``DATA`` is
the shared data folder (``BOMGRAPH_DATA`` overrides it) for the tests of the real files.
"""

from __future__ import annotations

import gzip
import math
import os
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

from bomgraph.angles import wrap_angle
from bomgraph.geometry import bearings_to
from _shared_data import DATA, missing  # tests/_shared_data.py

needs_data = pytest.mark.skipif(not DATA.is_dir(), reason=missing())

EXACT = dict(command_delay_s=0.0, attach_window_s=0.0)


def exact_repr(x: float) -> str:
    """A float written so that reading it back gives the same float."""
    return repr(float(x))


def rewrite_keeping_size_and_times(path: Path, edit: Callable[[bytes], bytes]) -> None:
    """``path``'s bytes edited, its size and modification time as they were (``touch -r``)."""
    st = path.stat()
    data = path.read_bytes()
    new = edit(data)
    assert new != data and len(new) == len(data)
    path.write_bytes(new)
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert (path.stat().st_size, path.stat().st_mtime_ns) == (st.st_size, st.st_mtime_ns)


# --------------------------------------------------------------------------------------------
# A synthetic MRCLAM folder
# --------------------------------------------------------------------------------------------

HEADER = ["# UTIAS Multi-Robot Cooperative Localization and Mapping Dataset",
          "# synthetic excerpt written by tests/datasets/dataset_excerpts.py",
          "# Data Format:", "# columns"]
LANDMARKS = {6: (2.0, 1.0), 7: (3.0, -1.0), 8: (2.5, 0.2), 9: (-1.0, 2.5), 10: (0.5, -2.5),
             11: (-2.0, -1.0), 12: (1.5, 2.5)}
BARCODES = {1: 5, 2: 14, 3: 41, 4: 32, 5: 23, 6: 63, 7: 81, 8: 7, 9: 70, 10: 45, 11: 27,
            12: 18}


def true_poses(t: np.ndarray, v: np.ndarray, w: np.ndarray, start: tuple) -> np.ndarray:
    """Exact poses under held commands, written in the world frame (independent formula)."""
    x, y, psi = start
    out = [(x, y, psi)]
    for k in range(len(t) - 1):
        dt = t[k + 1] - t[k]
        if abs(w[k]) < 1e-12:
            x, y = x + v[k] * dt * math.cos(psi), y + v[k] * dt * math.sin(psi)
        else:
            r = v[k] / w[k]
            x, y = (x + r * (math.sin(psi + w[k] * dt) - math.sin(psi)),
                    y - r * (math.cos(psi + w[k] * dt) - math.cos(psi)))
        psi = psi + w[k] * dt
        out.append((x, y, psi))
    out = np.array(out)
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def write_table(path: Path, rows: list[str], *, crlf: bool = False, gz: bool = False) -> None:
    text = ("\r\n" if crlf else "\n").join(HEADER + rows) + ("\r\n" if crlf else "\n")
    if gz:
        (path.parent / (path.name + ".gz")).write_bytes(gzip.compress(text.encode()))
    else:
        path.write_bytes(text.encode())


def make_mrclam(folder: Path, *, v: float = 0.08, w: float | np.ndarray = 0.15,
                seconds: float = 40.0, noise_rad: float = 0.0, bias_rad: float = 0.0,
                gross_every: int = 0, seed: int = 0, crlf: bool = False, gz: bool = False,
                extras: bool = True, truth: bool = True, landmarks: dict | None = None,
                listed: dict | None = None, barcodes: dict | None = None) -> dict:
    """Robot 1 driving with held commands; bursts of exact (or noisy) bearings every 0.25 s.

    The detections come from ``landmarks`` (default ``LANDMARKS``); ``Landmark_Groundtruth.dat``
    lists them with the rows of ``listed`` overriding (a faulty table); ``barcodes`` replaces
    ``BARCODES``.

    Odometry and ground truth share 100 Hz time stamps; bursts lie on them, so interpolated
    truth is exact. With ``extras`` every burst also holds a sighting of robot 2, every 10th an
    unknown barcode (99) and a repeat of its first landmark 1 ms later.
    """
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    t0 = 1248444000.0
    n = int(round(seconds * 100)) + 1
    t = t0 + 0.01 * np.arange(n)
    vv = np.full(n, v)
    ww = np.broadcast_to(np.asarray(w, dtype=float), (n,)).copy()
    gt = true_poses(t, vv, ww, (0.3, -0.2, 0.4))
    end = " " if crlf else ""
    landmarks = LANDMARKS if landmarks is None else landmarks
    codes = BARCODES if barcodes is None else barcodes
    write_table(folder / "Barcodes.dat", [f"  {s} \t  {b}{end}" for s, b in codes.items()],
                crlf=crlf, gz=gz)
    write_table(folder / "Landmark_Groundtruth.dat",
                [f"  {s} \t {exact_repr(x)} \t {exact_repr(y)} \t 0.0001 \t 0.0001{end}"
                 for s, (x, y) in {**landmarks, **(listed or {})}.items()], crlf=crlf, gz=gz)
    write_table(folder / "Robot1_Odometry.dat",
                [f"{exact_repr(a)} \t {exact_repr(b)} \t {exact_repr(c)}{end}" for a, b, c in zip(t, vv, ww)],
                crlf=crlf, gz=gz)
    if truth:
        write_table(folder / "Robot1_Groundtruth.dat",
                    [f"{exact_repr(a)} \t {exact_repr(p[0])} \t {exact_repr(p[1])} \t {exact_repr(p[2])}{end}"
                     for a, p in zip(t, gt)],
                    crlf=crlf, gz=gz)
    ids = np.array(list(landmarks))
    xy = np.array(list(landmarks.values()))
    rows, counts = [], {"landmark": 0, "robot": 0, "unknown": 0, "gross": 0, "repeat": 0}
    k_meas = 0
    for b, k in enumerate(range(25, n - 25, 25)):
        brg = bearings_to(gt[k], xy)
        rng_m = np.hypot(*(xy - gt[k, :2]).T)
        seen = np.abs(brg) < 0.6
        for i, lid in enumerate(ids[seen]):
            val = brg[seen][i] + bias_rad + noise_rad * rng.standard_normal()
            k_meas += 1
            if gross_every and k_meas % gross_every == 0:
                val += 0.5
                counts["gross"] += 1
            rows.append(f"{exact_repr(t[k])} \t {codes[int(lid)]} \t {exact_repr(rng_m[seen][i])} \t "
                        f"{exact_repr(float(wrap_angle(val)))}{end}")
            counts["landmark"] += 1
        if extras:
            rows.append(f"{exact_repr(t[k])} \t 14 \t 1.5 \t 0.1{end}")
            counts["robot"] += 1
            if b % 10 == 0:
                rows.append(f"{exact_repr(t[k])} \t 99 \t 2.0 \t -0.2{end}")
                counts["unknown"] += 1
                if seen.any():
                    rows.append(f"{exact_repr(t[k] + 0.001)} \t {codes[int(ids[seen][0])]} \t 2.0 \t "
                                f"0.3{end}")
                    counts["landmark"] += 1
                    counts["repeat"] += 1
    write_table(folder / "Robot1_Measurement.dat", rows, crlf=crlf, gz=gz)
    counts["total"] = len(rows)
    return {"t": t, "gt": gt, "counts": counts}


# --------------------------------------------------------------------------------------------
# g2o
# --------------------------------------------------------------------------------------------

INFO = "500 0 0 500 0 5000"


def write_g2o(path: Path, stream, *, info: str | list[str] = INFO, w: float = 57295.8,
              pose_id0: int = 1200, with_vertices: bool = True, shuffle_seed: int | None = None,
              extra: list[str] = ()) -> None:
    lines = []
    if with_vertices:
        lines += [f"VERTEX_XY {i} {exact_repr(x)} {exact_repr(y)}" for i, (x, y)
                  in zip(stream.truth.landmark_ids, stream.truth.landmarks_xy)]
        lines += [f"VERTEX_SE2 {pose_id0 + t} {exact_repr(p[0])} {exact_repr(p[1])} {exact_repr(p[2])}"
                  for t, p in enumerate(stream.truth.poses)]
    lines.append(f"FIX {pose_id0}")
    for st in stream.steps:
        if st.odom is not None:
            inf = info if isinstance(info, str) else info[st.t - 1]
            lines.append(f"EDGE_SE2 {pose_id0 + st.t - 1} {pose_id0 + st.t} "
                         f"{exact_repr(st.odom[0])} {exact_repr(st.odom[1])} {exact_repr(st.odom[2])} {inf}")
        lines += [f"EDGE_BEARING_SE2_XY {pose_id0 + st.t} {i} {exact_repr(b)} {w}"
                  for i, b in zip(st.landmark_ids, st.bearings_rad)]
    lines += list(extra)
    if shuffle_seed is not None:
        np.random.default_rng(shuffle_seed).shuffle(lines)
    path.write_text("# written by tests/datasets/dataset_excerpts.py\n" + "\n".join(lines) + "\n")


# --------------------------------------------------------------------------------------------
# Victoria Park
# --------------------------------------------------------------------------------------------

VICTORIA = """ODOMETRY 0 1 1.0 0 0.1 0.0001 0 0 4e-06 0 4e-06
LANDMARK 1 2 10 0 0.4 0 0.4
ODOMETRY 1 3 0.5 0.01 -0.2 0.0001 0 0 4e-06 0 4e-06
LANDMARK 3 2 5 5 0.4 0 0.4
LANDMARK 3 4 0 -2 0.4 0 0.4
ODOMETRY 3 5 0.0 0.0 0.0 0.0001 0 0 4e-06 0 4e-06
"""
