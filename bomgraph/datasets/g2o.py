"""Bearing-only g2o files -> a :class:`~bomgraph.stream.Stream` (issue 7, part 2).

Reads the 2-D bearing-only subset of g2o's text format used by the Sapienza "Probabilistic
Robotics" bearing-only SLAM project (``shared/data/bearing_only_sim_g2o/SOURCE.md``)::

    VERTEX_SE2 id x y theta                 a pose (initial estimate, or truth in truth_path)
    VERTEX_XY  id x y                       a landmark (likewise)
    FIX id [id ...]                         gauge: vertices held fixed
    EDGE_SE2 i j dx dy dth  I11 I12 I13 I22 I23 I33
                                            odometry from pose i to pose j in the frame of i,
                                            with the upper triangle of its INFORMATION matrix
    EDGE_BEARING_SE2_XY i l bearing w       bearing from pose i to landmark l, information w

Lines starting with ``#`` and blank lines are skipped, except a ``# bomgraph header: {...}``
comment before the first record (:data:`G2O_HEADER_PREFIX`, written by ``bomgraph export
--format g2o``), whose ``sensor_range_m``, ``time_s`` and ``priors`` (known landmark
distances, for which g2o has no edge) go back into the stream, so that an
export reads back to the same stream but its truth (pass ``truth_path``); any other record is an
error (this is not a general g2o reader). Poses become steps in the order of the ``EDGE_SE2``
chain, which must be one unbroken chain (no loop closures: the stream format holds one odometry
chain). Landmark ids are the g2o vertex ids. Every ``VERTEX_SE2`` of the file must be a pose of
that chain: g2o itself would optimise a pose vertex without odometry as a free vertex, but in a
bearing-only odometry file such a vertex means a lost ``EDGE_SE2`` (a stream cannot hold a pose
without odometry), so it is refused rather than dropped.

**Odometry sigma.** g2o's ``EdgeSE2`` error is ``toVector(Z^-1 (X_i^-1 X_j))`` with ``Z`` the
measurement: its translation part is the deviation of the predicted translation from the
measured one rotated into the frame of ``Z``, ``e_t = R(dth)^T (t_pred - t_meas)``; its angle
part is ``th_pred - th_meas``. The stream's sigmas are on the components of ``[dx, dy, dpsi]``
in the frame of pose i, so the covariance ``Omega^-1`` is mapped by ``J = diag(R(dth), 1)``:
``Sigma_stream = J Omega^-1 J^T``, and each sigma is the square root of a diagonal entry. The
stream keeps no correlations; the largest dropped correlation coefficient goes to
``meta["odometry_max_dropped_correlation"]``. If every edge gives the same sigmas they are the
header's ``odometry_sigma``; otherwise each step carries its own ``odom_sigma`` and the header
holds the per-component median. A header turn sigma above pi/sqrt(3) (edges of rotation
information below 0.3: "turn unknown") would read as degrees: the steps then carry their own
and the header's is capped at pi/sqrt(3).

**Bearing sigma.** ``1 / sqrt(w)`` of the bearing edges (their median if they differ; the
spread goes to meta). The project's notes call ``w`` a placeholder: pass ``bearing_sigma_rad``
to override it. A bearing written beyond a full turn is wrapped, as g2o wraps angles, with a
warning naming the first one's line (degrees, most likely). With ``truth_path`` the residuals
against the truth are measured and recorded in ``meta["truth_check"]`` (they are not used for
the header).

**Truth.** ``truth_path`` is read for its ``VERTEX_SE2`` (one per step, matched by id) and
``VERTEX_XY`` lines; its edges are ignored (the project's ground-truth file repeats the noisy
edges). The vertices of ``path`` itself are initial estimates: they are counted in meta, not
used.
"""

from __future__ import annotations

import array
import logging
import math
import os
import re
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DatasetError, StreamFormatError, shown_path
from ..plausibility import MAX_ABS_ANGLE_RAD, MAX_ODOMETRY_SIGMA, refuse_implausible
from ..stream import Step, Stream, StreamHeader, Truth
from ..tables import counted
from ..stream_file import parse_priors
from ._text import (chain_order, checked_bearing_sigma, dataset_error,
                    file_label, parse_float, parse_int, read_lines)
from .calibration import bearing_residuals, odometry_errors, robust_bearing_stats

#: A comment line of the file that carries what g2o has no record for (written by ``bomgraph
#: export --format g2o``): ``# bomgraph header: {"sensor_range_m": 8.1, "time_s": [...],
#: "priors": [...]}``;
#: read from the comments before the first record (one after it is not read).
G2O_HEADER_PREFIX = "# bomgraph header: "

_log = logging.getLogger(__name__)

_HEADER_COMMENT = re.compile(r"#\s*bomgraph header:\s*(.*)")

_RECORDS = {
    "VERTEX_SE2": ["id", "x", "y", "theta"],
    "VERTEX_XY": ["id", "x", "y"],
    "EDGE_SE2": ["i", "j", "dx", "dy", "dth", "I11", "I12", "I13", "I22", "I23", "I33"],
    "EDGE_BEARING_SE2_XY": ["i", "l", "bearing", "w"],
}
_INT_FIELDS = {"id", "i", "j", "l"}


def _bomgraph_header(path: Path) -> tuple[dict[str, Any], int | None]:
    """The fields of a :data:`G2O_HEADER_PREFIX` comment before the first record (``{}``,
    None without one) and its line number; each field checked."""
    from ..jsonio import DuplicateKeyError, find_nonfinite, loads_strict

    for line in read_lines(path, comment=None):
        text = " ".join(line.tokens)
        if not text.startswith("#"):
            return {}, None
        found = _HEADER_COMMENT.match(text)   # spacing as a hand edit may leave it
        if found is None:
            continue
        try:
            fields = loads_strict(found.group(1))
        except DuplicateKeyError as exc:
            raise dataset_error(path, line.number, "bomgraph header",
                                f"key '{exc}' appears twice") from None
        except (ValueError, RecursionError) as exc:
            raise dataset_error(path, line.number, "bomgraph header",
                                f"not JSON ({exc})") from None
        if not isinstance(fields, dict) or set(fields) - {"sensor_range_m", "time_s", "priors"}:
            raise dataset_error(path, line.number, "bomgraph header",
                                "an object with sensor_range_m, time_s and priors only")
        bad = find_nonfinite(fields)
        rng = fields.get("sensor_range_m")
        times = fields.get("time_s")
        if bad is not None or not (rng is None or (isinstance(rng, (int, float))
                                                   and not isinstance(rng, bool) and rng > 0)) \
                or not (times is None or (isinstance(times, list) and all(
                    isinstance(v, (int, float)) and not isinstance(v, bool) for v in times))):
            raise dataset_error(path, line.number, "bomgraph header",
                                "sensor_range_m must be a number > 0 or null, time_s a list "
                                "of finite numbers")
        try:  # checked as a stream file's header checks them
            fields["priors"] = parse_priors(fields.get("priors"), path, line.number)
        except StreamFormatError as exc:
            raise DatasetError(str(exc)) from None
        return fields, line.number
    return {}, None


#: the most text of a g2o file's vertex, EDGE_SE2 and FIX records (the file as a whole is at
#: most :data:`~bomgraph.datasets._text.MAX_DATASET_BYTES`). They are held as Python objects,
#: 20-27 bytes of memory a byte of text (h96: 32 MiB of VERTEX_SE2 lines peaked at 629 MB, of
#: EDGE_SE2 lines at 886 MB), so 16 MiB is about 450 MB; a simulated run's file has 270 bytes
#: of them a step, so 16 MiB is 60,000 steps. The bearings, most of a file, are held 8 bytes a
#: value (:class:`_Bearings`): a 250 MB file of 18,000 steps and 3.7 million bearings peaked
#: at 404 MB. h91's cap of 16 MiB on the whole file refused a 20,000-step simulated run's own
#: export (29 MB).
MAX_G2O_HELD_BYTES = 16 * 2**20
_TOO_MANY_RECORDS = (f"more than {MAX_G2O_HELD_BYTES >> 20} MiB of VERTEX_SE2, VERTEX_XY, "
                     f"EDGE_SE2 and FIX records (about 60,000 poses), the limit for a g2o file; "
                     f"split it")


class _Bearings:
    """The ``EDGE_BEARING_SE2_XY`` records of a file, in file order: columns ``i``, ``l``,
    ``line`` (int64) and ``bearing``, ``w`` (float64), as arrays by :meth:`columns`."""

    def __init__(self) -> None:
        self._int = [array.array("q") for _ in range(3)]
        self._float = [array.array("d") for _ in range(2)]

    def append(self, i: int, lid: int, line: int, brg: float, w: float) -> None:
        for col, v in zip(self._int, (i, lid, line)):
            col.append(v)
        for colf, x in zip(self._float, (brg, w)):
            colf.append(x)

    def __len__(self) -> int:
        return len(self._int[0])

    def columns(self) -> tuple[np.ndarray, ...]:
        """``i, l, line, bearing, w``: read-only views of the buffers."""
        return (tuple(np.frombuffer(c, dtype=np.int64) for c in self._int)
                + tuple(np.frombuffer(c, dtype=float) for c in self._float))


class _G2oFile:
    """The records of one g2o file, validated line by line."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.poses: dict[int, tuple[np.ndarray, int]] = {}
        self.landmarks: dict[int, tuple[np.ndarray, int]] = {}
        self.odometry: list[tuple[int, int, int, np.ndarray, np.ndarray]] = []
        # the bearings, most of a file's lines, in typed buffers (8 bytes a value): as
        # tuples of Python numbers they took about 10 bytes of memory a byte of text
        self.bearings = _Bearings()
        self.fixed: list[int] = []
        held = 0   # bytes of text of the records held as Python objects
        # a line is split into Python strings before it is checked: bounded as the held
        # records are (h97: one 60 MB line, in a file h91 capped at 16 MiB, took 1.7 GB)
        for line in read_lines(self.path, max_line_chars=MAX_G2O_HELD_BYTES):
            tag = line.tokens[0]
            if tag != "EDGE_BEARING_SE2_XY":
                held += sum(map(len, line.tokens)) + len(line.tokens)
                if held > MAX_G2O_HELD_BYTES:
                    raise dataset_error(self.path, line.number, None, _TOO_MANY_RECORDS)
            if tag == "FIX":
                if len(line.tokens) < 2:
                    raise dataset_error(self.path, line.number, "id",
                                        "FIX needs at least one vertex id")
                self.fixed += [parse_int(tok, self.path, line.number, "id")
                               for tok in line.tokens[1:]]
                continue
            if tag not in _RECORDS:
                raise dataset_error(self.path, line.number, "tag",
                                    f"unsupported record {tag[:40]!r}; this importer reads "
                                    f"{', '.join(sorted(_RECORDS))} and FIX (bearing-only "
                                    f"2-D SLAM); remove the line or convert the file")
            names = _RECORDS[tag]
            if len(line.tokens) - 1 != len(names):
                raise dataset_error(self.path, line.number, None,
                                    f"{tag} needs {len(names)} fields ({' '.join(names)}), got "
                                    f"{len(line.tokens) - 1}; fix or delete this line")
            vals: dict[str, Any] = {}
            for name, tok in zip(names, line.tokens[1:]):
                if name in _INT_FIELDS:
                    vals[name] = parse_int(tok, self.path, line.number, name)
                    if vals[name] < 0:
                        raise dataset_error(self.path, line.number, name,
                                            f"vertex id must be >= 0, got {vals[name]}")
                else:
                    vals[name] = parse_float(tok, self.path, line.number, name)
            self._add(tag, vals, line.number)

    def _add(self, tag: str, v: dict[str, Any], line: int) -> None:
        if tag in ("VERTEX_SE2", "VERTEX_XY"):
            vid = v["id"]
            if vid in self.poses or vid in self.landmarks:
                first = (self.poses.get(vid) or self.landmarks[vid])[1]
                raise dataset_error(self.path, line, "id", f"vertex {vid} is defined twice "
                                                           f"(first on line {first})")
            if tag == "VERTEX_SE2":
                self.poses[vid] = (np.array([v["x"], v["y"], v["theta"]]), line)
            else:
                self.landmarks[vid] = (np.array([v["x"], v["y"]]), line)
        elif tag == "EDGE_SE2":
            info = np.array([[v["I11"], v["I12"], v["I13"]],
                             [v["I12"], v["I22"], v["I23"]],
                             [v["I13"], v["I23"], v["I33"]]])
            if not np.all(np.linalg.eigvalsh(info) > 0):
                raise dataset_error(self.path, line, "information",
                                    "the information matrix (I11 I12 I13 I22 I23 I33) is not "
                                    "positive definite; give a valid information matrix")
            self.odometry.append((v["i"], v["j"], line,
                                  np.array([v["dx"], v["dy"], v["dth"]]), info))
        else:
            if not v["w"] > 0:
                raise dataset_error(self.path, line, "w", f"bearing information must be > 0, "
                                                          f"got {v['w']}")
            self.bearings.append(v["i"], v["l"], line, v["bearing"], v["w"])


def header_odometry_sigma(sig: np.ndarray) -> tuple[tuple[float, float, float], bool]:
    """The header's ``odometry_sigma`` from the steps' sigmas ``sig`` (T, 3), and whether they
    are all the same (then the steps need none of their own): their common value, else the
    per-component median. A turn sigma above :data:`MAX_ODOMETRY_SIGMA` (pi/sqrt(3), edges
    whose rotation is unknown: information below 0.3) is valid on a step, but a header's that
    large reads as degrees: the steps then keep their own and the header's is capped (the
    stream reader still warns when more than half the steps state one, as of a header's:
    :class:`~bomgraph.plausibility.OdometryScale`)."""
    uniform = len(sig) == 0 or bool(np.allclose(sig, sig[0], rtol=1e-9, atol=0.0))
    header = (tuple(float(v) for v in (sig[0] if uniform else np.median(sig, axis=0)))
              if len(sig) else (0.0, 0.0, 0.0))
    if header[2] > MAX_ODOMETRY_SIGMA[2]:
        return (header[0], header[1], MAX_ODOMETRY_SIGMA[2]), False
    return header, uniform


def odometry_sigma_from_information(dth_rad: float, information: np.ndarray
                                    ) -> tuple[np.ndarray, float]:
    """Independent ``[dx, dy, dpsi]`` sigmas of a g2o ``EDGE_SE2`` (module docstring).

    Parameters
    ----------
    dth_rad : float
        The edge's measured rotation (its error is expressed in the measurement's frame).
    information : ndarray of shape (3, 3)
        The edge's information matrix, positive definite.

    Returns
    -------
    sigma : ndarray of shape (3,)
        ``[sigma_dx_m, sigma_dy_m, sigma_dpsi_rad]``.
    max_correlation : float
        The largest absolute correlation coefficient the independent sigmas drop.
    """
    c, s = math.cos(dth_rad), math.sin(dth_rad)
    jac = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    with np.errstate(all="ignore"):  # a denormal or huge entry: the caller names its line
        cov = jac @ np.linalg.inv(information) @ jac.T
        sigma = np.sqrt(np.diag(cov))
        corr = cov / np.outer(sigma, sigma)
    return sigma, float(np.max(np.abs(corr[np.triu_indices(3, 1)])))


def checked_sigma(sigma: np.ndarray, path: Path, line: int, field: str) -> np.ndarray:
    """``sigma`` from a line's odometry information or covariance, refused (naming the file,
    the line and the field) unless finite: a positive definite matrix with a denormal or
    near-overflow entry (``4.9e-324``, ``1.8e308``) has no finite inverse (h91's fuzz: the
    stream's own check refused it naming neither the file nor the line)."""
    if not np.all(np.isfinite(sigma)):
        raise dataset_error(path, line, field, "this matrix has no finite inverse in floating "
                                               "point (an entry too small or too large); fix "
                                               "this line")
    return sigma


def g2o_inputs(path: str | os.PathLike[str], truth_path: str | os.PathLike[str] | None = None
               ) -> dict[str, Path]:
    """Role -> each file :func:`import_g2o` reads: what a recording's cache key hashes."""
    files = {"edges": Path(path)}
    if truth_path is not None:
        files["truth"] = Path(truth_path)
    return files


def import_g2o(path: str | os.PathLike[str], *, truth_path: str | os.PathLike[str] | None = None,
               bearing_sigma_rad: float | None = None) -> Stream:
    """Import a bearing-only g2o file (see the module docstring).

    Parameters
    ----------
    path : path-like
        The g2o file with the measurement edges (e.g. the initial-guess file).
    truth_path : path-like, optional
        A g2o file whose vertices are the ground truth (one ``VERTEX_SE2`` per pose of the
        chain; ``VERTEX_XY`` for the landmarks).
    bearing_sigma_rad : float, optional
        Overrides the sigma derived from the bearing edges' information.

    Returns
    -------
    Stream
        One step per pose along the odometry chain; time stamps and the sensor range only
        from a ``# bomgraph header`` comment.

    Raises
    ------
    DatasetError
        A malformed line (file, line, field), odometry that is not one chain, a pose vertex or
        a bearing from a pose that is not on the chain, a repeated bearing, or truth that
        misses a pose.
    """
    g = _G2oFile(path)
    b_i, b_l, b_line, b_brg, b_w = g.bearings.columns()
    edges = [(i, j, line) for i, j, line, _, _ in g.odometry]
    order = chain_order(edges, g.path)
    if not order:
        observers = np.unique(b_i).tolist()
        if len(observers) > 1:
            raise dataset_error(g.path, None, None,
                                f"bearings from {len(observers)} poses but no EDGE_SE2 "
                                f"odometry joining them; a stream needs one odometry chain")
        if not observers and not g.poses:
            raise dataset_error(g.path, None, None, "no EDGE_SE2 and no EDGE_BEARING_SE2_XY "
                                                    "records: nothing to import")
        order = observers or [min(g.poses)]
    step_of = {pid: t for t, pid in enumerate(order)}
    pose_ids = set(step_of)
    off_chain = sorted(set(g.poses) - pose_ids, key=lambda v: g.poses[v][1])
    if off_chain:
        vid = off_chain[0]
        raise dataset_error(g.path, g.poses[vid][1], "id",
                            f"VERTEX_SE2 {vid} is not on the odometry chain (poses {order[0]} .. "
                            f"{order[-1]}; {len(off_chain)} pose vertices off it): every pose "
                            f"becomes a step, so it needs its EDGE_SE2 (restore the missing "
                            f"edge, or delete the vertex and its bearings)")

    # odometry ------------------------------------------------------------------------------
    by_target = {j: (meas, info) for _, j, _, meas, info in g.odometry}
    line_of = {j: n for _, j, n, _, _ in g.odometry}
    odom_lines = [line_of[pid] for pid in order[1:]]
    odoms = np.zeros((len(order) - 1, 3))
    sig = np.zeros((len(order) - 1, 3))
    max_corr = 0.0
    for t, pid in enumerate(order[1:], start=0):
        meas, info = by_target[pid]
        odoms[t] = meas
        sigma, corr = odometry_sigma_from_information(meas[2], info)
        sig[t] = checked_sigma(sigma, g.path, line_of[pid], "information")
        max_corr = max(max_corr, corr)
    header_odo, uniform = header_odometry_sigma(sig)

    # bearings ------------------------------------------------------------------------------
    steps_of_b, first_bad = _bearing_steps(g, order, b_i, b_l, b_line)
    if first_bad is not None:
        raise first_bad
    beyond = np.flatnonzero(np.abs(b_brg) > MAX_ABS_ANGLE_RAD)  # beyond a full turn
    if beyond.size:   # valid (g2o wraps angles, and so does a Step), but most likely degrees
        _log.warning("%s, line %d: field 'bearing': %g is more than a full turn (%s "
                     "in the file); bearings are radians (degrees?); wrapped to "
                     "(-pi, pi]", shown_path(g.path), int(b_line[beyond[0]]),
                     float(b_brg[beyond[0]]), counted(beyond.size, "such bearing"))
    w_arr = b_w
    if bearing_sigma_rad is not None:
        sigma_b = checked_bearing_sigma(bearing_sigma_rad)
        sigma_source = "given by the caller"
    elif w_arr.size:
        sigma_b = float(np.median(1.0 / np.sqrt(w_arr)))
        sigma_source = "1/sqrt(w) of the EDGE_BEARING_SE2_XY information (median)"
    else:
        raise dataset_error(g.path, None, None, "no EDGE_BEARING_SE2_XY records, so no bearing "
                                                "sigma; pass bearing_sigma_rad")

    extra, extra_line = _bomgraph_header(g.path)
    times = extra.get("time_s")
    if times is not None and len(times) != len(order):
        raise dataset_error(g.path, extra_line, "bomgraph header",
                            f"time_s has {len(times)} stamps for {len(order)} poses")
    by_step = np.lexsort((b_l, steps_of_b))   # by step, then by landmark id
    cuts = np.searchsorted(steps_of_b[by_step], np.arange(len(order) + 1))
    steps = []
    for t in range(len(order)):
        rows = by_step[cuts[t]:cuts[t + 1]]
        steps.append(Step(t=t, odom=None if t == 0 else odoms[t - 1],
                          landmark_ids=b_l[rows].copy(), bearings_rad=b_brg[rows].copy(),
                          odom_sigma=None if (t == 0 or uniform) else sig[t - 1],
                          time_s=None if times is None else float(times[t])))

    meta: dict[str, Any] = {
        "source": "g2o bearing-only SLAM file",
        "files": {"edges": file_label(g.path)},
        "importer": "bomgraph.datasets.g2o.import_g2o",
        "pose_ids": [int(p) for p in order],
        "n_odometry_edges": len(g.odometry), "n_bearing_edges": len(g.bearings),
        "initial_vertices_not_used": {"VERTEX_SE2": len(g.poses), "VERTEX_XY": len(g.landmarks)},
        "fixed_vertex_ids": sorted(set(g.fixed)),
        "fixed_steps": sorted(step_of[v] for v in set(g.fixed) if v in step_of),
        "odometry_sigma_source": "EDGE_SE2 information, mapped to [dx, dy, dpsi] in the frame "
                                 "of pose i (J = diag(R(dth), 1)), diagonal kept",
        "odometry_sigma_per_step": not uniform,
        "odometry_max_dropped_correlation": max_corr,
        "bearing_sigma_source": sigma_source,
        "bearing_information_range": ([float(w_arr.min()), float(w_arr.max())]
                                      if w_arr.size else None),
    }

    truth = None
    if truth_path is not None:
        tg = _G2oFile(truth_path)
        meta["files"]["truth"] = file_label(tg.path)
        missing = [p for p in order if p not in tg.poses]
        if missing:
            raise dataset_error(tg.path, None, None,
                                f"no VERTEX_SE2 for pose {missing[0]} ({len(missing)} of "
                                f"{len(order)} poses missing); the truth needs every pose")
        lm_ids = np.array(sorted(tg.landmarks), dtype=np.int64)
        observed = set(np.unique(b_l).tolist())
        unknown = sorted(observed - set(lm_ids.tolist()))
        if unknown:
            raise dataset_error(tg.path, None, None,
                                f"no VERTEX_XY for observed landmark {unknown[0]} "
                                f"({len(unknown)} missing); the truth needs every landmark")
        truth = Truth(lm_ids, np.array([tg.landmarks[k][0] for k in lm_ids.tolist()]
                                       ).reshape(-1, 2),
                      np.array([tg.poses[p][0] for p in order]).reshape(-1, 3))
        check: dict[str, Any] = {}
        tmp = Stream(StreamHeader(sigma_b, header_odo), tuple(steps), truth)
        r, _, _ = bearing_residuals(tmp)
        if r.size >= 2:
            check["bearing"] = robust_bearing_stats(r)
        if len(order) > 1:
            err, _ = odometry_errors(odoms, truth.poses)
            check["odometry_rms_error"] = [float(v) for v in np.sqrt(np.mean(err ** 2, axis=0))]
            check["odometry_mean_error"] = [float(v) for v in err.mean(axis=0)]
            _check_odometry_fits_truth(g.path, tg.path, odoms, check["odometry_rms_error"],
                                       header_odo)
        meta["truth_check"] = check

    if extra_line is not None:
        meta["bomgraph_header_line"] = extra_line
    header = StreamHeader(bearing_sigma_rad=sigma_b, odometry_sigma=header_odo,
                          sensor_range_m=extra.get("sensor_range_m"),
                          priors=extra.get("priors", ()), meta=meta)
    refuse_implausible(header, steps, DatasetError, str(g.path),
                       landmarks_xy=None if truth is None else truth.landmarks_xy,
                       poses=None if truth is None else truth.poses, odom_lines=odom_lines,
                       priors_line=extra_line)
    return Stream(header, tuple(steps), truth)


def _bearing_steps(g: _G2oFile, order: list[int], b_i: np.ndarray, b_l: np.ndarray,
                   b_line: np.ndarray) -> tuple[np.ndarray, DatasetError | None]:
    """The step of each bearing of ``g`` (``order``: the chain's pose ids), and the refusal
    of the file's first bearing (in file order) that is not from a pose of the chain, not to a
    landmark, or a second one of its pose and landmark (None if none is)."""
    chain = np.array(order, dtype=np.int64)   # never empty (import_g2o)
    perm = np.argsort(chain, kind="stable")
    ids = chain[perm]
    pos = np.minimum(np.searchsorted(ids, b_i), len(ids) - 1)
    on_chain = ids[pos] == b_i
    steps = np.where(on_chain, perm[pos], -1).astype(np.int64)
    to_pose = ids[np.minimum(np.searchsorted(ids, b_l), len(ids) - 1)] == b_l
    pair = np.lexsort((b_l, b_i))     # stable: a pair's rows in file order
    again = np.zeros(len(b_i), dtype=bool)
    again[pair[1:]] = (b_i[pair[1:]] == b_i[pair[:-1]]) & (b_l[pair[1:]] == b_l[pair[:-1]])
    bad = np.flatnonzero(~on_chain | to_pose | again)
    if not bad.size:
        return steps, None
    k = int(bad[0])
    i, lid, line = int(b_i[k]), int(b_l[k]), int(b_line[k])
    if not on_chain[k]:
        kind = "a landmark" if i in g.landmarks else "not on the odometry chain"
        return steps, dataset_error(g.path, line, "i", f"bearing from vertex {i}, which is "
                                                       f"{kind}; the first id must be a pose "
                                                       f"of the chain")
    if to_pose[k]:
        return steps, dataset_error(g.path, line, "l", f"bearing to vertex {lid}, which is a "
                                                       f"pose; the second id must be a landmark")
    first = int(b_line[np.flatnonzero((b_i == i) & (b_l == lid))[0]])
    return steps, dataset_error(g.path, line, None,
                                f"a second bearing from pose {i} to landmark {lid} (first on "
                                f"line {first}); one landmark appears at most once per step: "
                                f"merge or delete one")


#: the truth check refuses odometry whose RMS translation error against the truth exceeds
#: this fraction of the median step length while some component's RMS error exceeds this many
#: of its sigmas (a reversed chain or another run's truth; the file's own data give 0.9 sigma
#: and a few % of a step).
MAX_ODOMETRY_ERROR_STEP_FRACTION = 0.5
MAX_ODOMETRY_ERROR_SIGMAS = 10.0


def _check_odometry_fits_truth(path: Path, truth_path: Path, odoms: np.ndarray,
                               rms: list[float], sigma: tuple[float, float, float]) -> None:
    """Refuse a truth the odometry contradicts (the chain reversed, or another run's truth)."""
    step = float(np.median(np.hypot(odoms[:, 0], odoms[:, 1])))
    trans = math.hypot(rms[0], rms[1])
    ratio = max(e / s if s > 0 else (math.inf if e > 0 else 0.0) for e, s in zip(rms, sigma))
    if trans > MAX_ODOMETRY_ERROR_STEP_FRACTION * step and ratio > MAX_ODOMETRY_ERROR_SIGMAS:
        raise DatasetError(
            f"{shown_path(path)}: the odometry disagrees with the truth in {truth_path.name}: RMS "
            f"translation error {trans:.3g} m per step (the median step is {step:.3g} m; up to "
            f"{ratio:.3g} odometry sigmas); is the EDGE_SE2 chain reversed (edges from j to "
            f"i), or is the truth another run's?")
