"""The bomgraph measurement stream: data classes and the JSON Lines reader and writer.

Implements ``shared/STREAM_FORMAT.md`` (format version 1) exactly. The reader is strict: every
refusal listed in the format raises :class:`~bomgraph.errors.StreamFormatError` naming the file,
the line number and the key; nothing is silently dropped (unknown keys are refused too).

Ground truth travels in :class:`Truth`, apart from :class:`StreamHeader`, so a mapper that is
handed the header and the steps cannot read it by accident.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from typing import IO, Any, Iterable, Iterator, Mapping, Sequence

import numpy as np

from .angles import wrap_angle
from .errors import StreamFormatError

FORMAT_NAME = "bomgraph-stream"
FORMAT_VERSION = 1

_HEADER_KEYS = {"format", "version", "bearing_sigma_rad", "odometry_sigma", "sensor_range_m",
                "priors", "truth", "meta"}
_STEP_KEYS = {"t", "odom", "odom_sigma", "bearings", "time_s"}
_PRIOR_KEYS = {"i", "j", "distance_m", "sigma_m"}
_TRUTH_KEYS = {"landmarks", "poses"}


def _numpy_to_json(v: Any) -> Any:
    """numpy scalars and arrays as plain JSON values (for ``meta``)."""
    if isinstance(v, (np.generic, np.ndarray)):
        return v.tolist()
    raise TypeError(f"Object of type {type(v).__name__} is not JSON serializable")


def _frozen(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class Prior:
    """A known distance between landmarks ``i`` and ``j`` (metres, with its std. dev.)."""

    i: int
    j: int
    distance_m: float
    sigma_m: float


@dataclass(frozen=True)
class StreamHeader:
    """Everything a mapper may know about a run before the first step (no ground truth).

    Attributes
    ----------
    bearing_sigma_rad : float
        Standard deviation of one bearing measurement, > 0.
    odometry_sigma : tuple of 3 floats
        ``(sigma_dx_m, sigma_dy_m, sigma_dpsi_rad)`` of an odometry increment, each >= 0.
    sensor_range_m : float or None
        Maximum range at which landmarks are observed, if known.
    priors : tuple of Prior
        Known inter-landmark distances.
    meta : mapping
        Free-form information (generator, seed, source, licence, ...).
    """

    bearing_sigma_rad: float
    odometry_sigma: tuple[float, float, float]
    sensor_range_m: float | None = None
    priors: tuple[Prior, ...] = ()
    meta: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.bearing_sigma_rad) and self.bearing_sigma_rad > 0):
            raise StreamFormatError("must be a finite number > 0", key="bearing_sigma_rad")
        sig = tuple(float(s) for s in self.odometry_sigma)
        if len(sig) != 3 or not all(math.isfinite(s) and s >= 0 for s in sig):
            raise StreamFormatError("must be 3 finite numbers >= 0", key="odometry_sigma")
        object.__setattr__(self, "odometry_sigma", sig)
        if self.sensor_range_m is not None and not (math.isfinite(self.sensor_range_m)
                                                    and self.sensor_range_m > 0):
            raise StreamFormatError("must be a finite number > 0 or None", key="sensor_range_m")
        priors = tuple(self.priors)
        for k, p in enumerate(priors):
            if p.i == p.j or min(p.i, p.j) < 0:
                raise StreamFormatError(f"prior joins landmarks {p.i} and {p.j}; need two "
                                        f"different non-negative ids", key=f"priors[{k}]")
            if not (math.isfinite(p.distance_m) and p.distance_m > 0
                    and math.isfinite(p.sigma_m) and p.sigma_m > 0):
                raise StreamFormatError("distance_m and sigma_m must be finite and > 0",
                                        key=f"priors[{k}]")
        object.__setattr__(self, "priors", priors)
        try:  # meta must survive the file: normalise it to what JSON gives back
            meta = json.loads(json.dumps(dict(self.meta), allow_nan=False,
                                         default=_numpy_to_json))
        except (TypeError, ValueError) as exc:
            raise StreamFormatError(f"must be JSON-serialisable with finite numbers ({exc})",
                                    key="meta") from None
        object.__setattr__(self, "meta", meta)


@dataclass(frozen=True, eq=False)
class Step:
    """One time step: the odometry since the previous pose and the bearings taken here.

    Attributes
    ----------
    t : int
        Step index, 0 for the first step.
    odom : ndarray of shape (3,) or None
        ``[dx_m, dy_m, dpsi_rad]``, the motion from pose ``t-1`` to pose ``t`` in the frame of
        pose ``t-1``; None at ``t = 0``.
    landmark_ids : ndarray of shape (k,), int64
        Ids of the landmarks observed, unique within the step.
    bearings_rad : ndarray of shape (k,)
        Bearings relative to the robot heading, wrapped to (-pi, pi].
    odom_sigma : ndarray of shape (3,) or None
        Per-step override of the header's ``odometry_sigma``.
    time_s : float or None
        Time stamp.
    """

    t: int
    odom: np.ndarray | None
    landmark_ids: np.ndarray
    bearings_rad: np.ndarray
    odom_sigma: np.ndarray | None = None
    time_s: float | None = None

    def __post_init__(self) -> None:
        ids = _frozen(np.array(self.landmark_ids, dtype=np.int64).reshape(-1))
        brg = _frozen(np.array(wrap_angle(np.asarray(self.bearings_rad, dtype=float)),
                               dtype=float).reshape(-1))
        if ids.shape != brg.shape:
            raise StreamFormatError(f"step {self.t}: {ids.size} landmark ids but "
                                    f"{brg.size} bearings", key="bearings")
        if not np.all(np.isfinite(brg)):
            raise StreamFormatError(f"step {self.t}: bearings must be finite", key="bearings")
        if np.any(ids < 0) or len(np.unique(ids)) != len(ids):
            raise StreamFormatError(f"step {self.t}: landmark ids must be non-negative and "
                                    f"unique within a step", key="bearings")
        object.__setattr__(self, "landmark_ids", ids)
        object.__setattr__(self, "bearings_rad", brg)
        for key in ("odom", "odom_sigma"):
            v = getattr(self, key)
            if v is None:
                continue
            arr = np.array(v, dtype=float).reshape(-1)
            if arr.shape != (3,) or not np.all(np.isfinite(arr)):
                raise StreamFormatError(f"step {self.t}: must be 3 finite numbers", key=key)
            if key == "odom_sigma" and np.any(arr < 0):
                raise StreamFormatError(f"step {self.t}: sigmas must be >= 0", key=key)
            object.__setattr__(self, key, _frozen(arr))
        if self.time_s is not None and not math.isfinite(self.time_s):
            raise StreamFormatError(f"step {self.t}: must be finite", key="time_s")

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Step):
            return NotImplemented
        return (self.t == other.t and self.time_s == other.time_s
                and _opt_equal(self.odom, other.odom)
                and _opt_equal(self.odom_sigma, other.odom_sigma)
                and np.array_equal(self.landmark_ids, other.landmark_ids)
                and np.array_equal(self.bearings_rad, other.bearings_rad))

    __hash__ = None  # type: ignore[assignment]

    def odometry_sigma(self, header: StreamHeader) -> np.ndarray:
        """The std. dev. of this step's odometry components: the override, else the header's."""
        if self.odom_sigma is not None:
            return self.odom_sigma
        return np.asarray(header.odometry_sigma, dtype=float)


@dataclass(frozen=True, eq=False)
class Truth:
    """Ground truth of a run, for evaluation only.

    Attributes
    ----------
    landmark_ids : ndarray of shape (n,)
    landmarks_xy : ndarray of shape (n, 2)
    poses : ndarray of shape (T, 3) or None
        ``[x_m, y_m, psi_rad]`` per step, index = ``t``; None when only the map is known.
    """

    landmark_ids: np.ndarray
    landmarks_xy: np.ndarray
    poses: np.ndarray | None = None

    def __post_init__(self) -> None:
        ids = _frozen(np.array(self.landmark_ids, dtype=np.int64).reshape(-1))
        xy = _frozen(np.array(self.landmarks_xy, dtype=float).reshape(-1, 2))
        if ids.shape[0] != xy.shape[0]:
            raise StreamFormatError("landmark ids and positions differ in number",
                                    key="truth")
        if len(np.unique(ids)) != len(ids) or np.any(ids < 0):
            raise StreamFormatError("landmark ids must be unique and non-negative",
                                    key="truth.landmarks")
        if not np.all(np.isfinite(xy)):
            raise StreamFormatError("landmark positions must be finite", key="truth.landmarks")
        object.__setattr__(self, "landmark_ids", ids)
        object.__setattr__(self, "landmarks_xy", xy)
        if self.poses is not None:
            poses = np.array(self.poses, dtype=float).reshape(-1, 3)
            if not np.all(np.isfinite(poses)):
                raise StreamFormatError("poses must be finite", key="truth.poses")
            object.__setattr__(self, "poses", _frozen(poses))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Truth):
            return NotImplemented
        return (np.array_equal(self.landmark_ids, other.landmark_ids)
                and np.array_equal(self.landmarks_xy, other.landmarks_xy)
                and _opt_equal(self.poses, other.poses))

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True, eq=False)
class Stream:
    """One robot run: the header, the steps and (apart) the ground truth if known."""

    header: StreamHeader
    steps: tuple[Step, ...]
    truth: Truth | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "steps", tuple(self.steps))
        if not self.steps:
            raise StreamFormatError("a stream needs at least the step t = 0", key="t")
        for k, s in enumerate(self.steps):
            if s.t != k:
                raise StreamFormatError(f"step {k} has t = {s.t}; steps must be 0, 1, 2, ...",
                                        key="t")
            if (s.odom is None) != (k == 0):
                raise StreamFormatError(f"step {k}: odom must be None at t = 0 and given after",
                                        key="odom")
        if self.truth is not None and self.truth.poses is not None \
                and len(self.truth.poses) != len(self.steps):
            raise StreamFormatError(f"{len(self.truth.poses)} truth poses for "
                                    f"{len(self.steps)} steps", key="truth")

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Stream):
            return NotImplemented
        return (self.header == other.header and self.steps == other.steps
                and self.truth == other.truth)

    __hash__ = None  # type: ignore[assignment]

    def __len__(self) -> int:
        return len(self.steps)

    def landmark_ids(self) -> np.ndarray:
        """All landmark ids observed in the run, sorted."""
        if not self.steps:
            return np.zeros(0, dtype=np.int64)
        return np.unique(np.concatenate([s.landmark_ids for s in self.steps]))


def _opt_equal(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return np.array_equal(a, b)


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------

class _Ctx:
    """Where we are in a file, for error messages."""

    def __init__(self, path: str, line: int) -> None:
        self.path = path
        self.line = line

    def error(self, key: str | None, message: str) -> StreamFormatError:
        return StreamFormatError(message, path=self.path, line=self.line, key=key)


def _find_nonfinite(obj: Any, where: str) -> str | None:
    if isinstance(obj, float):
        return None if math.isfinite(obj) else where
    if isinstance(obj, dict):
        for k, v in obj.items():
            hit = _find_nonfinite(v, f"{where}.{k}" if where else str(k))
            if hit is not None:
                return hit
    elif isinstance(obj, list):
        for k, v in enumerate(obj):
            hit = _find_nonfinite(v, f"{where}[{k}]")
            if hit is not None:
                return hit
    return None


class _DuplicateKey(Exception):
    pass


def _no_duplicate_keys(pairs: list[tuple[str, Any]]) -> dict:
    out: dict = {}
    for k, v in pairs:
        if k in out:
            raise _DuplicateKey(k)
        out[k] = v
    return out


def _parse_json_line(text: str, ctx: _Ctx) -> dict:
    if not text.strip():
        raise ctx.error(None, "blank line; the format has one JSON object per line and no "
                              "blank lines")
    try:
        obj = json.loads(text, parse_constant=float, object_pairs_hook=_no_duplicate_keys)
    except _DuplicateKey as exc:
        raise ctx.error(str(exc), "appears twice in one object; a reader never drops data")
    except (json.JSONDecodeError, RecursionError, ValueError) as exc:
        msg = getattr(exc, "msg", None) or ("too deeply nested" if isinstance(exc, RecursionError)
                                            else str(exc))
        raise ctx.error(None, f"not valid JSON ({msg})") from None
    if not isinstance(obj, dict):
        raise ctx.error(None, f"expected a JSON object, got {type(obj).__name__}")
    bad = _find_nonfinite(obj, "")
    if bad is not None:
        raise ctx.error(bad, "non-finite number (NaN or Infinity) is not allowed")
    return obj


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


_MAX_ID = int(np.iinfo(np.int64).max)


def _is_id(v: Any) -> bool:
    """A landmark id: a JSON integer in [0, 2**63 - 1]."""
    return _is_int(v) and 0 <= v <= _MAX_ID


def _is_num(v: Any) -> bool:
    """A JSON number that fits a float (huge integers do not)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    if isinstance(v, int):
        try:
            return math.isfinite(float(v))
        except OverflowError:
            return False
    return True


def _check_keys(obj: dict, allowed: set[str], ctx: _Ctx, what: str) -> None:
    unknown = sorted(set(obj) - allowed)
    if unknown:
        raise ctx.error(unknown[0], f"unknown key in {what}; allowed keys are "
                                    f"{', '.join(sorted(allowed))}")


def _num(obj: dict, key: str, ctx: _Ctx, *, positive: bool = False,
         nonneg: bool = False) -> float:
    v = obj[key]
    if not _is_num(v):
        raise ctx.error(key, f"must be a number, got {json.dumps(v)[:40]}")
    if positive and not v > 0:
        raise ctx.error(key, f"must be > 0, got {v}")
    if nonneg and v < 0:
        raise ctx.error(key, f"must be >= 0, got {v}")
    return float(v)


def _triple(v: Any, key: str, ctx: _Ctx, *, nonneg: bool) -> tuple[float, float, float]:
    if not isinstance(v, list) or len(v) != 3:
        n = len(v) if isinstance(v, list) else type(v).__name__
        raise ctx.error(key, f"must be a list of 3 numbers, got {n}")
    for k, e in enumerate(v):
        if not _is_num(e):
            raise ctx.error(key, f"element {k} must be a number, got {json.dumps(e)[:40]}")
        if nonneg and e < 0:
            raise ctx.error(key, f"element {k} is a sigma and must be >= 0, got {e}")
    return (float(v[0]), float(v[1]), float(v[2]))


def _parse_header(obj: dict, ctx: _Ctx) -> tuple[StreamHeader, Truth | None]:
    if "format" not in obj:
        raise ctx.error("format", f"missing; line 1 must be the header with "
                                  f"\"format\": \"{FORMAT_NAME}\"")
    if obj["format"] != FORMAT_NAME:
        raise ctx.error("format", f"must be \"{FORMAT_NAME}\", got {json.dumps(obj['format'])[:60]}")
    if "version" not in obj:
        raise ctx.error("version", "missing required key")
    if not _is_int(obj["version"]) or obj["version"] != FORMAT_VERSION:
        raise ctx.error("version", f"unknown version {json.dumps(obj['version'])[:40]}; this "
                                   f"reader knows version {FORMAT_VERSION}")
    _check_keys(obj, _HEADER_KEYS, ctx, "the header")
    for key in ("bearing_sigma_rad", "odometry_sigma"):
        if key not in obj:
            raise ctx.error(key, "missing required key")
    bearing_sigma = _num(obj, "bearing_sigma_rad", ctx, positive=True)
    odo_sigma = _triple(obj["odometry_sigma"], "odometry_sigma", ctx, nonneg=True)
    sensor_range = obj.get("sensor_range_m")
    if sensor_range is not None:
        sensor_range = _num(obj, "sensor_range_m", ctx, positive=True)
    priors = _parse_priors(obj.get("priors"), ctx)
    meta = obj.get("meta", {})
    if meta is None:
        meta = {}
    if not isinstance(meta, dict):
        raise ctx.error("meta", f"must be a JSON object, got {type(meta).__name__}")
    truth = _parse_truth(obj.get("truth"), ctx)
    header = StreamHeader(bearing_sigma_rad=bearing_sigma, odometry_sigma=odo_sigma,
                          sensor_range_m=sensor_range, priors=priors, meta=meta)
    return header, truth


def _parse_priors(v: Any, ctx: _Ctx) -> tuple[Prior, ...]:
    if v is None:
        return ()
    if not isinstance(v, list):
        raise ctx.error("priors", "must be a list of {\"i\", \"j\", \"distance_m\", \"sigma_m\"}")
    out = []
    for k, p in enumerate(v):
        key = f"priors[{k}]"
        if not isinstance(p, dict):
            raise ctx.error(key, "must be an object with i, j, distance_m, sigma_m")
        _check_keys(p, _PRIOR_KEYS, ctx, key)
        for sub in ("i", "j", "distance_m", "sigma_m"):
            if sub not in p:
                raise ctx.error(f"{key}.{sub}", "missing required key")
        for sub in ("i", "j"):
            if not _is_id(p[sub]):
                raise ctx.error(f"{key}.{sub}", f"must be a non-negative integer landmark id, "
                                                f"got {json.dumps(p[sub])[:40]}")
        if p["i"] == p["j"]:
            raise ctx.error(key, f"names landmark {p['i']} twice; a prior joins two landmarks")
        for sub in ("distance_m", "sigma_m"):
            if not _is_num(p[sub]) or not p[sub] > 0:
                raise ctx.error(f"{key}.{sub}", f"must be a number > 0, got "
                                                f"{json.dumps(p[sub])[:40]}")
        out.append(Prior(int(p["i"]), int(p["j"]), float(p["distance_m"]), float(p["sigma_m"])))
    return tuple(out)


def _parse_truth(v: Any, ctx: _Ctx) -> Truth | None:
    if v is None:
        return None
    if not isinstance(v, dict):
        raise ctx.error("truth", "must be an object with \"landmarks\" and/or \"poses\"")
    _check_keys(v, _TRUTH_KEYS, ctx, "truth")
    lms = v.get("landmarks", [])
    if not isinstance(lms, list):
        raise ctx.error("truth.landmarks", "must be a list of [id, x_m, y_m]")
    ids, xy = [], []
    for k, e in enumerate(lms):
        if not (isinstance(e, list) and len(e) == 3 and _is_id(e[0])
                and _is_num(e[1]) and _is_num(e[2])):
            raise ctx.error(f"truth.landmarks[{k}]", f"must be [id, x_m, y_m] with a "
                                                     f"non-negative integer id, got "
                                                     f"{json.dumps(e)[:60]}")
        ids.append(e[0])
        xy.append((e[1], e[2]))
    if len(set(ids)) != len(ids):
        raise ctx.error("truth.landmarks", "a landmark id appears twice")
    poses = v.get("poses")
    if poses is not None:
        if not isinstance(poses, list):
            raise ctx.error("truth.poses", "must be a list of [x_m, y_m, psi_rad]")
        for k, e in enumerate(poses):
            if not (isinstance(e, list) and len(e) == 3 and all(_is_num(q) for q in e)):
                raise ctx.error(f"truth.poses[{k}]", f"must be [x_m, y_m, psi_rad], got "
                                                     f"{json.dumps(e)[:60]}")
        poses = np.array(poses, dtype=float).reshape(-1, 3)
    return Truth(np.array(ids, dtype=np.int64), np.array(xy, dtype=float).reshape(-1, 2), poses)


def _parse_step(obj: dict, expected_t: int, ctx: _Ctx) -> Step:
    if "t" not in obj:
        raise ctx.error("t", "missing required key")
    t = obj["t"]
    if not _is_int(t):
        raise ctx.error("t", f"must be an integer, got {json.dumps(t)[:40]}")
    if t != expected_t:
        raise ctx.error("t", f"out of sequence: expected {expected_t}, got {t}")
    _check_keys(obj, _STEP_KEYS, ctx, "a step")
    odom = obj.get("odom")
    if t == 0:
        if odom is not None:
            raise ctx.error("odom", "must be absent or null at t = 0 (there is no previous "
                                    "pose)")
    else:
        if odom is None:
            raise ctx.error("odom", f"missing at t = {t}; every step after the first needs "
                                    f"[dx_m, dy_m, dpsi_rad]")
        odom = np.array(_triple(odom, "odom", ctx, nonneg=False))
    odom_sigma = obj.get("odom_sigma")
    if odom_sigma is not None:
        odom_sigma = np.array(_triple(odom_sigma, "odom_sigma", ctx, nonneg=True))
    if "bearings" not in obj:
        raise ctx.error("bearings", "missing required key (use [] when nothing is seen)")
    brg = obj["bearings"]
    if not isinstance(brg, list):
        raise ctx.error("bearings", "must be a list of [landmark_id, bearing_rad]")
    ids = np.empty(len(brg), dtype=np.int64)
    vals = np.empty(len(brg), dtype=float)
    for k, e in enumerate(brg):
        if not (isinstance(e, list) and len(e) == 2 and _is_int(e[0]) and _is_num(e[1])):
            raise ctx.error(f"bearings[{k}]", f"must be [int, number], got "
                                              f"{json.dumps(e)[:60]}")
        if e[0] < 0:
            raise ctx.error(f"bearings[{k}]", f"landmark id must be >= 0, got {e[0]}")
        if e[0] > _MAX_ID:
            raise ctx.error(f"bearings[{k}]", f"landmark id {e[0]} is too large")
        ids[k] = e[0]
        vals[k] = e[1]
    if len(np.unique(ids)) != len(ids):
        uniq, counts = np.unique(ids, return_counts=True)
        raise ctx.error("bearings", f"landmark {int(uniq[counts > 1][0])} appears twice in one "
                                    f"step")
    time_s = obj.get("time_s")
    if time_s is not None:
        time_s = _num(obj, "time_s", ctx)
    return Step(t=t, odom=odom, landmark_ids=ids, bearings_rad=vals, odom_sigma=odom_sigma,
                time_s=time_s)


class StreamReader:
    """Reads a stream file lazily: the header at once, the steps one by one.

    Use as a context manager::

        with StreamReader("run.jsonl") as reader:
            mapper = make(reader.header)
            for step in reader:
                mapper.step(step)

    The truth-pose count is checked once the last step has been read.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = str(path)
        try:
            self._fh: IO[bytes] = open(self.path, "rb")
        except OSError as exc:
            raise StreamFormatError(f"cannot open: {exc.strerror}", path=self.path) from None
        try:
            first = self._fh.readline()
            if not first:
                raise StreamFormatError("empty file; line 1 must be the header",
                                        path=self.path, line=1)
            ctx = _Ctx(self.path, 1)
            self.header, self.truth = _parse_header(_parse_json_line(_decode(first, ctx), ctx),
                                                    ctx)
        except BaseException:
            self._fh.close()
            raise
        self._started = False

    def __enter__(self) -> "StreamReader":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._fh.close()

    def __iter__(self) -> Iterator[Step]:
        if self._started:
            raise StreamFormatError("a StreamReader can be iterated only once; open the file "
                                    "again", path=self.path)
        self._started = True
        line_no = 1
        t = 0
        pending_blank: int | None = None
        for raw in self._fh:
            line_no += 1
            ctx = _Ctx(self.path, line_no)
            text = _decode(raw, ctx)
            if not text.strip():
                pending_blank = pending_blank or line_no
                continue
            if pending_blank is not None:
                raise _Ctx(self.path, pending_blank).error(
                    None, "blank line; the format has one JSON object per line and no blank "
                          "lines")
            yield _parse_step(_parse_json_line(text, ctx), t, ctx)
            t += 1
        if pending_blank is not None:
            raise _Ctx(self.path, pending_blank).error(None, "blank line at the end of the file; "
                                                             "only one final newline is allowed")
        if t == 0:
            raise StreamFormatError("no step lines; a stream needs at least the step t = 0",
                                    path=self.path, line=line_no + 1)
        if self.truth is not None and self.truth.poses is not None \
                and len(self.truth.poses) != t:
            raise StreamFormatError(f"the header has {len(self.truth.poses)} truth poses but "
                                    f"the file has {t} steps; give one pose per step",
                                    path=self.path, line=1, key="truth.poses")


def _decode(raw: bytes, ctx: _Ctx) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ctx.error(None, f"not UTF-8 text (byte {exc.start})") from None


def read_stream(path: str | os.PathLike[str]) -> Stream:
    """Read and validate a whole stream file.

    Raises
    ------
    StreamFormatError
        On any breach of the format, naming the file, line and key.
    """
    with StreamReader(path) as reader:
        steps = tuple(reader)
        return Stream(reader.header, steps, reader.truth)


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------

def _f(x: Any) -> float:
    return float(x)


def header_to_json(header: StreamHeader, truth: Truth | None = None) -> dict:
    """The header line as a JSON-ready dict, keys in the order of the format document."""
    obj: dict[str, Any] = {"format": FORMAT_NAME, "version": FORMAT_VERSION,
                           "bearing_sigma_rad": _f(header.bearing_sigma_rad),
                           "odometry_sigma": [_f(s) for s in header.odometry_sigma]}
    if header.sensor_range_m is not None:
        obj["sensor_range_m"] = _f(header.sensor_range_m)
    if header.priors:
        obj["priors"] = [{"i": int(p.i), "j": int(p.j), "distance_m": _f(p.distance_m),
                          "sigma_m": _f(p.sigma_m)} for p in header.priors]
    if truth is not None:
        tr: dict[str, Any] = {"landmarks": [[int(i), _f(x), _f(y)] for i, (x, y)
                                            in zip(truth.landmark_ids, truth.landmarks_xy)]}
        if truth.poses is not None:
            tr["poses"] = [[_f(a), _f(b), _f(c)] for a, b, c in truth.poses]
        obj["truth"] = tr
    if header.meta:
        obj["meta"] = dict(header.meta)
    return obj


def step_to_json(step: Step) -> dict:
    """One step line as a JSON-ready dict."""
    obj: dict[str, Any] = {"t": int(step.t)}
    if step.odom is not None:
        obj["odom"] = [_f(v) for v in step.odom]
    if step.odom_sigma is not None:
        obj["odom_sigma"] = [_f(v) for v in step.odom_sigma]
    obj["bearings"] = [[int(i), _f(b)] for i, b in zip(step.landmark_ids, step.bearings_rad)]
    if step.time_s is not None:
        obj["time_s"] = _f(step.time_s)
    return obj


def write_stream(stream: Stream, path: str | os.PathLike[str]) -> None:
    """Write a stream as JSON Lines; ``read_stream`` gives back an equal Stream.

    The same Stream always gives the same bytes.
    """
    write_stream_parts(stream.header, stream.steps, path, truth=stream.truth)


def write_stream_parts(header: StreamHeader, steps: Iterable[Step],
                       path: str | os.PathLike[str], truth: Truth | None = None) -> None:
    """Write a header and an iterable of steps (which may be a generator) to ``path``.

    The file appears only when complete (written beside it, then renamed)."""
    tmp = f"{os.fspath(path)}.partial"
    try:
        with open(tmp, "w", encoding="utf-8", newline="\n") as fh:
            fh.write(json.dumps(header_to_json(header, truth), allow_nan=False) + "\n")
            for step in steps:
                fh.write(json.dumps(step_to_json(step), allow_nan=False) + "\n")
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def strip_truth(stream: Stream) -> tuple[StreamHeader, Sequence[Step]]:
    """What a mapper may see of a stream: the header and the steps, never the truth."""
    return stream.header, stream.steps


__all__ = ["Prior", "StreamHeader", "Step", "Truth", "Stream", "StreamReader", "read_stream",
           "write_stream", "write_stream_parts", "header_to_json", "step_to_json",
           "strip_truth", "FORMAT_NAME", "FORMAT_VERSION"]
