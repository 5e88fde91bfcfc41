"""The estimate file: what ``bomgraph run`` writes and ``bomgraph evaluate`` reads.

Version 2 (written; ``docs/FORMATS.md``, "Estimate file") is JSON Lines, linear in the
number of steps: a header line (method, the stream's identity, options), one line per
checkpoint (the landmarks with optional 2x2 covariances, the poses new since the previous
checkpoint, the method's ``info``; the last checkpoint carries its whole trajectory: it is the
final map) and a last line with the timings. :class:`EstimateWriter` writes it checkpoint by
checkpoint into a unique temporary file beside the target and renames it into place once
complete, so an exception or SIGTERM leaves the previous file as it was (the writer is
:mod:`bomgraph.estimate_writer`, re-exported here).

Version 1 (one JSON object with every checkpoint's whole map) is still read. The reader is
strict: unknown keys, duplicate keys, non-finite numbers and malformed entries are refused,
naming the file, the line and the key (in version 1, the line on which the key is found).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from dataclasses import dataclass
from typing import IO, Any, Mapping

import numpy as np

from .checks import COV_RTOL, covariance_problem, file_name
from .errors import StreamFormatError
from .estimate_writer import (ESTIMATE_FORMAT, ESTIMATE_VERSION, EstimateWriter,
                              estimate_to_json, write_estimate)
from .jsonio import (DuplicateKeyError, decoder_problem, find_nonfinite, is_id, is_int, is_num,
                     line_not_json, line_of_key, loads_strict, options_from_json, path_of,
                     unparsable_at, version_problem)
from .mapper import Checkpoint, MapEstimate
from .stdio import MAX_LINE_BYTES, bounded_lines, line_too_long, open_input
from .stream_identity import StreamIdentity, stream_file_identity, stream_identity


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class EstimateFile:
    """An estimate file read back: the final map, the checkpoints (each with the whole
    trajectory up to its ``t``), the timings and (version 2) the header's record."""

    method: str
    final: MapEstimate
    checkpoints: tuple[Checkpoint, ...]
    timing_s: Mapping[str, float]
    version: int = 1
    stream: StreamIdentity | None = None
    options: Mapping[str, Any] | None = None


_ESTIMATE_KEYS = {"format", "version", "method", "landmarks", "poses", "checkpoints",
                  "timing_s"}
_CHECKPOINT_KEYS = {"t", "landmarks", "poses"}


class _Whole:
    """Where we are in a version-1 file (one JSON value, maybe over many lines), for error
    messages: the line is found from the key (:func:`bomgraph.jsonio.line_of_key`)."""

    def __init__(self, path: str, text: str) -> None:
        self.path, self.text = path, text

    def error(self, key: str | None, message: str) -> StreamFormatError:
        return StreamFormatError(message, path=self.path, line=line_of_key(self.text, key),
                                 key=key)


def _parse_estimate_parts(obj: Mapping[str, Any], ctx: _Whole, where: str) -> MapEstimate:
    def bad(key: str, msg: str) -> StreamFormatError:
        return ctx.error(f"{where}{key}", msg)

    lms = obj.get("landmarks")
    if not isinstance(lms, list):
        raise bad("landmarks", "missing or not a list of [id, x_m, y_m]")
    ids, xy = [], []
    for k, e in enumerate(lms):
        if not (isinstance(e, list) and len(e) == 3 and is_id(e[0]) and is_num(e[1])
                and is_num(e[2])):
            raise bad(f"landmarks[{k}]", f"must be [id, x_m, y_m] with a non-negative integer "
                                         f"id, got {json.dumps(e)[:60]}")
        ids.append(e[0])
        xy.append((float(e[1]), float(e[2])))
    if len(set(ids)) != len(ids):
        k = _second(ids)
        raise bad(f"landmarks[{k}]", f"landmark id {ids[k]} appears twice")
    pose_t = poses = None
    if obj.get("poses") is not None:
        if not isinstance(obj["poses"], list):
            raise bad("poses", "must be a list of [t, x_m, y_m, psi_rad]")
        ts, ps = [], []
        for k, e in enumerate(obj["poses"]):
            if not (isinstance(e, list) and len(e) == 4 and is_id(e[0])
                    and all(is_num(v) for v in e[1:])):
                raise bad(f"poses[{k}]", f"must be [t, x_m, y_m, psi_rad] with an integer "
                                         f"t >= 0, got {json.dumps(e)[:60]}")
            ts.append(e[0])
            ps.append([float(v) for v in e[1:]])
        if len(set(ts)) != len(ts):
            k = _second(ts)
            raise bad(f"poses[{k}]", f"step t = {ts[k]} appears twice")
        pose_t, poses = np.array(ts, dtype=np.int64), np.array(ps).reshape(-1, 3)
    return MapEstimate(np.array(ids, dtype=np.int64), np.array(xy).reshape(-1, 2),
                       pose_t=pose_t, poses=poses)


def _second(values: list[int]) -> int:
    """The index of the first value that appeared before."""
    seen: set[int] = set()
    for k, v in enumerate(values):
        if v in seen:
            return k
        seen.add(v)
    raise ValueError("no value appears twice")


def _read_v1(obj: dict, ctx: _Whole) -> EstimateFile:
    """A version-1 file (one JSON object) already parsed."""
    unknown = sorted(set(obj) - _ESTIMATE_KEYS)
    if unknown:
        raise ctx.error(unknown[0], f"unknown key; allowed: {', '.join(sorted(_ESTIMATE_KEYS))}")
    if not isinstance(obj.get("method", ""), str):
        raise ctx.error("method", "must be a string")
    final = _parse_estimate_parts(obj, ctx, "")
    raw_cps = obj.get("checkpoints") or []
    if not isinstance(raw_cps, list):
        raise ctx.error("checkpoints", "must be a list of {t, landmarks, poses}")
    cps = []
    for k, c in enumerate(raw_cps):
        if not isinstance(c, dict) or not is_id(c.get("t")):
            raise ctx.error(f"checkpoints[{k}]" + (".t" if isinstance(c, dict) else ""),
                            "each checkpoint needs an integer t >= 0")
        extra = sorted(set(c) - _CHECKPOINT_KEYS)
        if extra:
            raise ctx.error(f"checkpoints[{k}].{extra[0]}", "unknown key in a checkpoint")
        if cps and c["t"] <= cps[-1].t:
            raise ctx.error(f"checkpoints[{k}].t", "checkpoints must be in increasing t")
        cps.append(Checkpoint(c["t"], _parse_estimate_parts(c, ctx, f"checkpoints[{k}]."),
                              0.0))
    timing = obj.get("timing_s") or {}
    if not isinstance(timing, dict):
        raise ctx.error("timing_s", "must be an object of numbers")
    for name, v in timing.items():
        if not (isinstance(v, (int, float)) and not isinstance(v, bool)):
            raise ctx.error(f"timing_s.{name}", "must be a number (seconds)")
    return EstimateFile(str(obj.get("method", "")), final, tuple(cps), dict(timing))


_HEADER_KEYS_V2 = {"format", "version", "method", "stream", "options", "checkpoint_every"}
_LINE_KEYS_V2 = {"t", "landmarks", "landmark_cov", "poses", "pose_cov", "new_poses",
                 "new_pose_cov", "info", "estimate_s"}


class _Line:
    """Where we are in a version-2 file, for error messages."""

    def __init__(self, path: str, line: int) -> None:
        self.path, self.line = path, line

    def error(self, key: str | None, message: str) -> StreamFormatError:
        return StreamFormatError(message, path=self.path, line=self.line, key=key)


def _parse_line(text: str, ctx: _Line) -> dict:
    try:
        obj = loads_strict(text)
    except DuplicateKeyError as exc:
        raise ctx.error(str(exc), "appears twice in one object") from None
    except (json.JSONDecodeError, RecursionError, ValueError) as exc:
        raise ctx.error(None, line_not_json(exc, text, ctx.line)) from None
    if not isinstance(obj, dict):
        raise ctx.error(None, f"expected a JSON object, got {type(obj).__name__}")
    bad = find_nonfinite(obj)
    if bad is not None:
        raise ctx.error(bad, "non-finite number (NaN or Infinity) in the file; an estimate "
                             "file holds finite numbers only")
    return obj


def _rows(v: Any, width: int, key: str, ctx: _Line, what: str, *, int_first: bool,
          null: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``[[id, v1, ...], ...]`` (``int_first``) or ``[[v1, ...], ...]`` as (ids, values);
    with ``null``, an entry ``null`` is a row of NaN (a covariance not defined)."""
    if not isinstance(v, list):
        raise ctx.error(key, f"must be a list of {what}")
    ids, vals = [], []
    for k, e in enumerate(v):
        if null and e is None:
            vals.append([math.nan] * width)
            continue
        ok = isinstance(e, list) and len(e) == width
        if ok and int_first:
            ok = is_id(e[0]) and all(is_num(x) for x in e[1:])
        elif ok:
            ok = all(is_num(x) for x in e)
        if not ok:
            raise ctx.error(f"{key}[{k}]", f"must be {what}, got {json.dumps(e)[:60]}")
        if int_first:
            ids.append(e[0])
        vals.append([float(x) for x in (e[1:] if int_first else e)])
    n = width - 1 if int_first else width
    return np.array(ids, dtype=np.int64), np.array(vals, dtype=float).reshape(-1, n)


def _check_cov(cov: np.ndarray, key: str, ctx: _Line) -> None:
    """Refuse a covariance ``(n, k, k)`` that is not finite, symmetric and positive
    semi-definite (:func:`bomgraph.checks.covariance_problem`, to :data:`COV_RTOL`)."""
    bad = covariance_problem(cov)
    if bad is not None:
        raise ctx.error(f"{key}[{bad[0]}]", bad[1])


class _Trajectory:
    """The poses a version-2 file has given so far, in buffers grown by doubling: each
    checkpoint's trajectory is a read-only prefix view of them, not a copy. Each checkpoint
    held a copy of the whole trajectory before (h126): a file of n checkpoints adding one
    pose each (``run --checkpoint-every 1``) held n^2/2 poses, 8,000 checkpoints (a 700 kB
    file) 1.5 GB."""

    def __init__(self) -> None:
        self.started = False   # a checkpoint gave poses (perhaps none): not None from then on
        self._restart()

    def _restart(self) -> None:  # new buffers: earlier checkpoints' views keep the old ones
        self.n = 0
        self.top: int | None = None  # the largest t so far (a trajectory need not be sorted)
        self.t = np.zeros(0, np.int64)
        self.poses = np.zeros((0, 3))
        self.cov: np.ndarray | None = np.zeros((0, 3, 3))  # None once a segment has none

    def last_t(self) -> int | None:
        """The trajectory's largest t, as the writer's ``since_t``: new poses come after it
        (its last row's t let ``new_poses`` repeat an earlier t of an unsorted one; h133)."""
        return self.top

    def extend(self, t: np.ndarray, poses: np.ndarray, cov: np.ndarray | None,
               restart: bool) -> None:
        if restart:
            self._restart()
        self.started = True
        k = self.n + len(t)
        if k > len(self.t):   # new buffers; the old stay alive only as earlier views
            size = max(k, 2 * len(self.t), 16)
            self.t = _grown(self.t, self.n, size)
            self.poses = _grown(self.poses, self.n, size)
            self.cov = None if self.cov is None else _grown(self.cov, self.n, size)
        self.t[self.n:k], self.poses[self.n:k] = t, poses
        if len(t):
            self.top = int(t.max()) if self.top is None else max(self.top, int(t.max()))
        if cov is None:
            self.cov = None
        elif self.cov is not None:
            self.cov[self.n:k] = cov
        self.n = k

    def views(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        out = [None if a is None else a[:self.n] for a in (self.t, self.poses, self.cov)]
        for a in out:
            if a is not None:
                a.setflags(write=False)
        return out[0], out[1], out[2]  # type: ignore[return-value]


def _grown(a: np.ndarray, n: int, size: int) -> np.ndarray:
    out = np.empty((size,) + a.shape[1:], a.dtype)
    out[:n] = a[:n]
    return out


def _parse_checkpoint_v2(obj: dict, ctx: _Line, traj: _Trajectory
                         ) -> tuple[int, MapEstimate, float]:
    unknown = sorted(set(obj) - _LINE_KEYS_V2)
    if unknown:
        raise ctx.error(unknown[0], f"unknown key in a checkpoint line; allowed: "
                                    f"{', '.join(sorted(_LINE_KEYS_V2))}")
    if not is_id(obj.get("t")):
        raise ctx.error("t", "a checkpoint line needs an integer t >= 0")
    if "landmarks" not in obj:
        raise ctx.error("landmarks", "missing (a list of [id, x_m, y_m])")
    ids, xy = _rows(obj["landmarks"], 3, "landmarks", ctx, "[id, x_m, y_m]", int_first=True)
    if len(set(ids.tolist())) != len(ids):
        raise ctx.error("landmarks", "a landmark id appears twice")
    lcov = None
    if "landmark_cov" in obj:
        _, lc = _rows(obj["landmark_cov"], 4, "landmark_cov", ctx,
                      "[xx, xy, yx, yy] (m^2) or null", int_first=False, null=True)
        if len(lc) != len(ids):
            raise ctx.error("landmark_cov", f"{len(lc)} covariances for {len(ids)} landmarks")
        lcov = lc.reshape(-1, 2, 2)
        _check_cov(lcov, "landmark_cov", ctx)
    if "poses" in obj and "new_poses" in obj:
        raise ctx.error("new_poses", "a checkpoint has either poses or new_poses")
    for cov_key, pose_key in (("pose_cov", "poses"), ("new_pose_cov", "new_poses")):
        if cov_key in obj and pose_key not in obj:
            raise ctx.error(cov_key, f"given without {pose_key}")
    key = "poses" if "poses" in obj else "new_poses" if "new_poses" in obj else None
    if key is not None:
        pose_t, poses = _rows(obj[key], 4, key, ctx, "[t, x_m, y_m, psi_rad]", int_first=True)
        pcov = None
        ck = key.replace("poses", "pose_cov")
        if ck in obj:
            _, pc = _rows(obj[ck], 9, ck, ctx, "9 numbers (row-major 3x3) or null",
                          int_first=False, null=True)
            if len(pc) != len(pose_t):
                raise ctx.error(ck, f"{len(pc)} covariances for {len(pose_t)} poses")
            pcov = pc.reshape(-1, 3, 3)
            _check_cov(pcov, ck, ctx)
        last = traj.last_t() if key == "new_poses" else None
        if last is not None and len(pose_t) and pose_t.min() <= last:
            raise ctx.error(key, f"new poses must come after the previous checkpoint's "
                                 f"last pose t = {last}")
        if len(set(pose_t.tolist())) != len(pose_t):  # with the above: none in the whole
            raise ctx.error(key, "a step t appears twice")
        if len(poses):
            MapEstimate(np.zeros(0, np.int64), np.zeros((0, 2)), pose_t=pose_t,  # its checks
                        poses=poses[:, :3], pose_cov=pcov)
        traj.extend(pose_t, poses, pcov, restart=key == "poses")
    info = obj.get("info", {})
    if not isinstance(info, dict):
        raise ctx.error("info", "must be an object")
    est_s = obj.get("estimate_s", 0.0)
    if not is_num(est_s):
        raise ctx.error("estimate_s", "must be a number (seconds)")
    est = MapEstimate(ids, xy, landmark_cov=lcov, info=info)
    if traj.started:  # the trajectory so far, as views (no copy, no re-check)
        for name, view in zip(("pose_t", "poses", "pose_cov"), traj.views()):
            object.__setattr__(est, name, view)
    return obj["t"], est, float(est_s)


def _parse_header_v2(obj: dict, ctx: _Line) -> tuple[str, StreamIdentity | None, Any]:
    bad = find_nonfinite(obj)
    if bad is not None:
        raise ctx.error(bad, "non-finite number (NaN or Infinity) in the header; an estimate "
                             "file holds finite numbers only")
    unknown = sorted(set(obj) - _HEADER_KEYS_V2)
    if unknown:
        raise ctx.error(unknown[0], f"unknown key in the header; allowed: "
                                    f"{', '.join(sorted(_HEADER_KEYS_V2))}")
    if not isinstance(obj.get("method"), str):
        raise ctx.error("method", "must be a string")
    ident = None
    if "stream" in obj:
        s = obj["stream"]
        if not (isinstance(s, dict) and set(s) == {"steps_sha256", "n_steps"}
                and isinstance(s["steps_sha256"], str) and len(s["steps_sha256"]) == 64
                and is_id(s["n_steps"])):
            raise ctx.error("stream", "must be {\"steps_sha256\": 64 hex digits, "
                                      "\"n_steps\": integer}")
        ident = StreamIdentity(s["steps_sha256"], s["n_steps"])
    if "options" in obj and not isinstance(obj["options"], dict):
        raise ctx.error("options", "must be an object")
    if "checkpoint_every" in obj and not (is_int(obj["checkpoint_every"])
                                          and obj["checkpoint_every"] >= 1):
        raise ctx.error("checkpoint_every", "must be an integer >= 1")
    return obj["method"], ident, options_from_json(obj.get("options"))  # infinities again


def _read_v2(fh: IO[bytes], header: dict, path: str) -> EstimateFile:
    method, ident, options = _parse_header_v2(header, _Line(path, 1))
    cps: list[Checkpoint] = []
    traj = _Trajectory()
    timing: dict[str, float] | None = None
    line_no = 1
    last_has_poses = False
    for raw in bounded_lines(fh, path, first_line=2):
        line_no += 1
        ctx = _Line(path, line_no)
        if timing is not None:
            raise ctx.error(None, "nothing may follow the timing_s line")
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise ctx.error(None, f"not UTF-8 text (byte {exc.start})") from None
        obj = _parse_line(text, ctx)
        if "timing_s" in obj:
            if set(obj) != {"timing_s"} or not isinstance(obj["timing_s"], dict) or not all(
                    is_num(v) for v in obj["timing_s"].values()):
                raise ctx.error("timing_s", "the last line is {\"timing_s\": {name: seconds}}")
            timing = {k: float(v) for k, v in obj["timing_s"].items()}
            continue
        t, est, est_s = _parse_checkpoint_v2(obj, ctx, traj)
        if cps and t <= cps[-1].t:
            raise ctx.error("t", f"checkpoints must be in increasing t ({t} after {cps[-1].t})")
        cps.append(Checkpoint(t, est, est_s))
        last_has_poses = "poses" in obj or "new_poses" in obj
    if timing is None:
        raise StreamFormatError("ends before the timing_s line (truncated?)", path=path,
                                line=line_no + 1, key="timing_s")
    if not cps:
        raise StreamFormatError("no checkpoint line; the final map is the last checkpoint",
                                path=path, line=2, key="t")
    if not last_has_poses and cps[-1].estimate.pose_t is not None:
        # the final map is exact: without poses of its own it has none (an earlier line
        # without poses keeps the trajectory so far; h102: the final map kept it too)
        final = dataclasses.replace(cps[-1].estimate, pose_t=None, poses=None, pose_cov=None)
        cps[-1] = Checkpoint(cps[-1].t, final, cps[-1].estimate_s)
    return EstimateFile(method, cps[-1].estimate, tuple(cps), timing, 2, ident, options)


#: the largest version-1 estimate file read: one JSON object is parsed whole, and Python's
#: objects take about 12.4x the file's bytes (a 59 MB file: 739 MB peak RSS), so this bounds
#: the reader's memory near 1.6 GB. Version 2 is read a line at a time.
MAX_V1_BYTES = 128 * 2**20


def read_estimate(path: str | os.PathLike[str]) -> EstimateFile:
    """Read an estimate file written by ``bomgraph run`` (version 2, or version 1), strictly:
    unknown and duplicate keys, non-finite numbers and malformed entries are refused, naming
    the file, the line and the key (of a version-1 file, one JSON value over any number of
    lines, the line the key is on)."""
    path = file_name(path, "estimate path", StreamFormatError)
    try:
        fh = open_input(path)
    except OSError as exc:
        raise StreamFormatError(f"cannot open: {exc.strerror}", path=path) from None
    with fh:
        first = fh.readline(MAX_LINE_BYTES + 1)
        if not first.strip() and not fh.read(1 << 16).strip():
            raise StreamFormatError("empty file; an estimate file is what `bomgraph run --out` "
                                    "writes", path=path, line=1)
        fh.seek(len(first))
        if len(first) > MAX_LINE_BYTES and not first.lstrip().startswith(b"{"):
            raise line_too_long(path, 1)  # a version-1 file may be one long JSON line
        try:
            head, head_error = loads_strict(first.rstrip(b"\r\n").decode("utf-8")), None
        except (ValueError, DuplicateKeyError, RecursionError, UnicodeDecodeError) as exc:
            head, head_error = None, exc
        version = head.get("version") if isinstance(head, dict) else None
        if isinstance(head, dict) and head.get("format") == ESTIMATE_FORMAT:
            if is_int(version) and version == 2:
                return _read_v2(fh, head, path)
            if not (is_int(version) and version == 1):
                what = ("missing; this reader knows versions 1 and 2" if "version" not in head
                        else version_problem(version, (1, 2)))
                newer = " (a newer bomgraph's file? run the method again with this one)"
                raise StreamFormatError(f"{what}{newer if is_int(version) else ''}",
                                        path=path, line=1, key="version")
        if isinstance(head, dict) and head.get("format") == "bomgraph-stream":
            raise StreamFormatError("this is a stream file, not an estimate file (arguments "
                                    "swapped? an estimate comes from `bomgraph run`)",
                                    path=path, line=1, key="format")
        if isinstance(head, dict) and head.get("format", ESTIMATE_FORMAT) != ESTIMATE_FORMAT:
            # h151: was read as one version-1 object and refused at line 2 ("Extra data")
            raise StreamFormatError(f"must be \"{ESTIMATE_FORMAT}\", got "
                                    f"{json.dumps(head['format'])[:60]}", path=path, line=1,
                                    key="format")
        fh.seek(0)
        try:
            chunks: list[bytes] = []  # in 1 MiB reads: read(4 GiB) reserves 4 GiB at once
            size = 0
            while chunk := fh.read(1 << 20):
                size += len(chunk)
                if size > MAX_V1_BYTES:
                    raise StreamFormatError(
                        f"a version-1 estimate (one JSON object, parsed whole: about 12 bytes "
                        f"of memory per byte of file) may be at most {MAX_V1_BYTES >> 20} MiB; "
                        f"write version 2, one checkpoint per line, as `bomgraph run` does",
                        path=path)
                chunks.append(chunk)
            data = b"".join(chunks)
            del chunks
            try:
                text = data.decode("utf-8")
            except UnicodeDecodeError as exc:
                raise StreamFormatError(f"not UTF-8 text (byte {exc.start})", path=path,
                                        line=data.count(b"\n", 0, exc.start) + 1) from None
            del data   # the text is kept (for the lines of messages), not a copy of it too
            repeated = _FirstRepeat()
            obj = json.loads(text, parse_constant=float, object_pairs_hook=repeated)
        except StreamFormatError:
            raise
        except json.JSONDecodeError as exc:
            if exc.lineno > 1 and isinstance(head_error, DuplicateKeyError):  # a v2 header
                raise StreamFormatError("appears twice in one object", path=path, line=1,
                                        key=str(head_error)) from None
            second = text.split("\n", 2)[1:2]
            if (exc.lineno > 1 and isinstance(head_error, json.JSONDecodeError) and second
                    and second[0].lstrip().startswith('{"t"')):  # a broken version-2 header
                raise StreamFormatError(f"not valid JSON ({decoder_problem(head_error)}); a version-2 "
                                        f"header is one JSON object on line 1",
                                        path=path, line=1) from None
            raise StreamFormatError(f"not valid JSON ({decoder_problem(exc)})", path=path,
                                    line=exc.lineno) from None
        except (RecursionError, ValueError) as exc:
            line, why = unparsable_at(text)
            raise StreamFormatError(f"not a JSON estimate file ({why or type(exc).__name__})",
                                    path=path, line=line) from None
    ctx = _Whole(path, text)
    if repeated.first is not None:
        holder, name = repeated.first
        where = path_of(obj, holder)
        if where is None:   # in an object a repeat of an outer key replaced: name that one
            holder, name = repeated.last
            where = path_of(obj, holder)
        # the root's keys bare ("" is also the path of the root's key "": "".b is ".b")
        raise ctx.error(name if holder is obj else f"{where}.{name}",
                        "appears twice in one object")
    if not isinstance(obj, dict) or obj.get("format") != ESTIMATE_FORMAT:
        raise ctx.error("format", f"must be a JSON object with \"format\": "
                                  f"\"{ESTIMATE_FORMAT}\"")
    version = obj.get("version")
    if not (is_int(version) and version == 1):
        problem = (version_problem(version, (1, 2)) if "version" in obj
                   else "missing required key")
        raise ctx.error("version", problem or "a version-2 header is one JSON object on line 1")
    bad = find_nonfinite(obj)
    if bad is not None:
        raise ctx.error(bad, "non-finite number (NaN or Infinity) in the file; an estimate "
                             "file holds finite numbers only")
    return _read_v1(obj, ctx)


class _FirstRepeat:
    """``object_pairs_hook`` that notes the first repeated key (``first``: the object and the
    key) rather than raising, so that the reader can say where it is; and the last object
    closed with a repeated key (``last``), which is always in the parsed data: an object
    that is not (its value replaced by a repeat of an outer key) has a later-closed
    ancestor with a repeat."""

    def __init__(self) -> None:
        self.first: tuple[dict, str] | None = None
        self.last: tuple[dict, str] | None = None

    def __call__(self, pairs: list[tuple[str, Any]]) -> dict:
        out: dict = {}
        repeat = None
        for k, v in pairs:
            if repeat is None and k in out:
                repeat = (out, k)
            out[k] = v
        if repeat is not None:
            self.last = repeat
            if self.first is None:
                self.first = repeat
        return out




def untimed_estimate_text(text: str) -> str:
    """An estimate file's text without its timings (each checkpoint's ``estimate_s``, the
    last line's ``timing_s``; a line left empty is dropped), each line written compactly:
    what two runs of the same method on the same stream agree on bit for bit."""
    lines = []
    for line in text.splitlines():
        obj = {k: v for k, v in json.loads(line).items() if k not in ("estimate_s", "timing_s")}
        if obj:
            lines.append(json.dumps(obj, separators=(",", ":")) + "\n")
    return "".join(lines)


__all__ = ["ESTIMATE_FORMAT", "ESTIMATE_VERSION", "COV_RTOL", "StreamIdentity", "stream_identity",
           "stream_file_identity", "EstimateWriter", "EstimateFile", "estimate_to_json",
           "write_estimate", "read_estimate", "untimed_estimate_text"]
