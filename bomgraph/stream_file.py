"""The JSON Lines stream file: strict reader and exact writer (``shared/STREAM_FORMAT.md``).

The reader is strict: every refusal listed in the format raises
:class:`~bomgraph.errors.StreamFormatError` naming the file, the line number and the key;
nothing is silently dropped (unknown keys are refused too). :class:`StreamReader` reads lazily,
one step at a time. The writer gives the same bytes for the same stream, and a file appears
only when complete.
"""

from __future__ import annotations

import json
import logging
import os
from typing import IO, Any, Callable, Iterable, Iterator, Sequence

import numpy as np

from .checks import file_name
from .errors import StreamFormatError, StreamValueError, shown_path
from .jsonio import (MAX_ID, DuplicateKeyError, decode_utf8, find_nonfinite, is_id, is_int,
                     is_num, line_not_json, loads_strict, version_problem)
from .plausibility import (OdometryScale, PriorLandmarks, bearings_problem, header_problems,
                           step_problem, truth_problem)
from .stdio import MAX_LINE_BYTES, bounded_lines, line_too_long, open_input, output_file
from .stream import Prior, Step, Stream, StreamHeader, Truth
from .worker_log import OnceInASweep

_log = logging.getLogger(__name__)
_log.addFilter(OnceInASweep())  # a warning read again in a sweep is said once (h103)

FORMAT_NAME = "bomgraph-stream"
FORMAT_VERSION = 1

_HEADER_KEYS = {"format", "version", "bearing_sigma_rad", "odometry_sigma", "sensor_range_m",
                "priors", "truth", "meta"}
_STEP_KEYS = {"t", "odom", "odom_sigma", "bearings", "time_s"}
_PRIOR_KEYS = {"i", "j", "distance_m", "sigma_m"}
_TRUTH_KEYS = {"landmarks", "poses"}


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


#: Deepest nesting of a header's ``meta`` the reader accepts (importers write 2-3 levels).
MAX_META_DEPTH = 64
#: the most bearings one step may hold (docs/FORMATS.md): a real sensor sees at most thousands
#: of landmarks at a time, and a step line is parsed whole (a 62 MB line of 5.5 M bearings took
#: 1.4 GB), so 100,000 bounds one step's memory near 30 MB. Counted on the text before parsing.
MAX_BEARINGS_PER_STEP = 100_000


def _depth(value: object) -> int:
    """Nesting depth of JSON data (iterative: no recursion limit; only containers are
    queued, so a long list of numbers costs nothing)."""
    deepest, todo = 0, [(value, 1)]
    while todo:
        v, d = todo.pop()
        if isinstance(v, (dict, list)):
            deepest = max(deepest, d)
            todo.extend((c, d + 1) for c in (v.values() if isinstance(v, dict) else v)
                        if isinstance(c, (dict, list)))
    return deepest


def _parse_json_line(text: str, ctx: _Ctx) -> dict:
    if not text.strip():
        raise ctx.error(None, "blank line; the format has one JSON object per line and no "
                              "blank lines")
    try:
        obj = loads_strict(text)
    except DuplicateKeyError as exc:
        raise ctx.error(str(exc), "appears twice in one object; a reader never drops data")
    except (json.JSONDecodeError, RecursionError, ValueError) as exc:
        raise ctx.error(None, line_not_json(exc, text, ctx.line)) from None
    if not isinstance(obj, dict):
        raise ctx.error(None, f"expected a JSON object, got {type(obj).__name__}")
    bad = find_nonfinite(obj)
    if bad is not None:
        raise ctx.error(bad, "non-finite number (NaN or Infinity) is not allowed")
    return obj


def _check_keys(obj: dict, allowed: set[str], ctx: _Ctx, what: str) -> None:
    unknown = sorted(set(obj) - allowed)
    if unknown:
        raise ctx.error(unknown[0], f"unknown key in {what}; allowed keys are "
                                    f"{', '.join(sorted(allowed))}")


def _num(obj: dict, key: str, ctx: _Ctx, *, positive: bool = False,
         nonneg: bool = False) -> float:
    v = obj[key]
    if not is_num(v):
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
        if not is_num(e):
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
    problem = version_problem(obj["version"], (FORMAT_VERSION,))
    if problem:
        raise ctx.error("version", problem)
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
    if _depth(meta) > MAX_META_DEPTH:  # Python 3.13's json parses what cannot be walked
        raise ctx.error("meta", f"is nested more than {MAX_META_DEPTH} levels deep")
    truth = _parse_truth(obj.get("truth"), ctx)
    header = StreamHeader(bearing_sigma_rad=bearing_sigma, odometry_sigma=odo_sigma,
                          sensor_range_m=sensor_range, priors=priors, meta=meta)
    return header, truth


def parse_priors(value: Any, path: str | os.PathLike[str], line: int) -> tuple[Prior, ...]:
    """A header's ``priors`` (JSON data; None: none) as :class:`Prior`, checked as the stream
    reader checks them; a :class:`StreamFormatError` names ``path``, ``line`` and the key."""
    return _parse_priors(value, _Ctx(str(path), line))


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
            if not is_id(p[sub]):
                raise ctx.error(f"{key}.{sub}", f"must be a non-negative integer landmark id, "
                                                f"got {json.dumps(p[sub])[:40]}")
        if p["i"] == p["j"]:
            raise ctx.error(key, f"names landmark {p['i']} twice; a prior joins two landmarks")
        for sub in ("distance_m", "sigma_m"):
            if not is_num(p[sub]) or not p[sub] > 0:
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
        if not (isinstance(e, list) and len(e) == 3 and is_id(e[0])
                and is_num(e[1]) and is_num(e[2])):
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
            if not (isinstance(e, list) and len(e) == 3 and all(is_num(q) for q in e)):
                raise ctx.error(f"truth.poses[{k}]", f"must be [x_m, y_m, psi_rad], got "
                                                     f"{json.dumps(e)[:60]}")
        poses = np.array(poses, dtype=float).reshape(-1, 3)
    return Truth(np.array(ids, dtype=np.int64), np.array(xy, dtype=float).reshape(-1, 2), poses)


def _too_many_bearings(ctx: _Ctx) -> StreamFormatError:
    return ctx.error("bearings", f"more than {MAX_BEARINGS_PER_STEP:,} bearings in one step "
                                 f"(the limit, MAX_BEARINGS_PER_STEP: a real sensor sees at "
                                 f"most thousands of landmarks at a time); split the step or "
                                 f"drop far landmarks")


def _parse_step(obj: dict, expected_t: int, ctx: _Ctx,
                problems: list[tuple[str, str]] | None = None) -> Step:
    """The step of line ``ctx.line``; with ``problems``, the bearings' plausibility as written
    (:func:`~bomgraph.plausibility.bearings_problem`; the step holds them wrapped) is added."""
    if "t" not in obj:
        raise ctx.error("t", "missing required key")
    t = obj["t"]
    if not is_int(t):
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
    if len(brg) > MAX_BEARINGS_PER_STEP:
        raise _too_many_bearings(ctx)
    ids = np.empty(len(brg), dtype=np.int64)
    vals = np.empty(len(brg), dtype=float)
    for k, e in enumerate(brg):
        if not (isinstance(e, list) and len(e) == 2 and is_int(e[0]) and is_num(e[1])):
            raise ctx.error(f"bearings[{k}]", f"must be [int, number], got "
                                              f"{json.dumps(e)[:60]}")
        if e[0] < 0:
            raise ctx.error(f"bearings[{k}]", f"landmark id must be >= 0, got {e[0]}")
        if e[0] > MAX_ID:
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
    if problems is not None and (problem := bearings_problem(t, vals)) is not None:
        problems.append(problem)
    return Step(t=t, odom=odom, landmark_ids=ids, bearings_rad=vals, odom_sigma=odom_sigma,
                time_s=time_s)


class StreamReader:
    """Reads a stream file lazily: the header at once, the steps one by one.

    Use as a context manager::

        with StreamReader("run.jsonl") as reader:
            mapper = make(reader.header)
            for step in reader:
                mapper.step(step)

    The truth-pose count is checked once the last step has been read. Lines are bounded
    (:data:`bomgraph.stdio.MAX_LINE_BYTES`, :data:`~bomgraph.stdio.MAX_INPUT_BYTES`). With
    ``warn`` (default) implausible but valid values (:mod:`bomgraph.plausibility`) are logged
    as warnings naming the line and the key: the header's, the first implausible step's, and
    (after the last step) odometry that contradicts its stated sigmas.
    """

    def __init__(self, path: str | os.PathLike[str], *, warn: bool = True) -> None:
        self.path = file_name(path, "stream path", StreamFormatError)
        self._warn = warn
        try:
            self._fh: IO[bytes] = open_input(self.path)
        except OSError as exc:
            raise StreamFormatError(f"cannot open: {exc.strerror}", path=self.path) from None
        try:
            first = self._fh.readline(MAX_LINE_BYTES + 1)
            if len(first) > MAX_LINE_BYTES:
                raise line_too_long(self.path, 1)
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
        for key, msg in header_problems(self.header) if warn else ():  # valid, but no method can use it
            _log.warning("%s, line 1: '%s': %s", shown_path(self.path), key, msg)
        if warn and self.truth is not None:
            msg = truth_problem(self.truth.landmarks_xy, self.truth.poses)
            if msg:
                _log.warning("%s, line 1: 'truth': %s", shown_path(self.path), msg)

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
        warned = not self._warn
        scale = OdometryScale(self.header.odometry_sigma)
        priors = PriorLandmarks(self.header.priors)
        for raw in bounded_lines(self._fh, self.path, first_line=2):
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
            if text.count("[") > MAX_BEARINGS_PER_STEP + 3:  # one per bearing; odom, sigma
                raise _too_many_bearings(ctx)
            as_written: list[tuple[str, str]] | None = None if warned else []
            step = _parse_step(_parse_json_line(text, ctx), t, ctx, as_written)
            if not warned and (problem := (as_written or [None])[0] or step_problem(
                    step, self.header.odometry_sigma[2])) is not None:
                warned = True
                _log.warning("%s, line %d: '%s': %s (implausible; later steps are not "
                             "checked)", shown_path(self.path), line_no, *problem)
            if self._warn:
                scale.add(step, line_no)
                priors.add(step)
            yield step
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
        for key, msg, line in scale.problems():
            _log.warning("%s, line %d: '%s': %s", shown_path(self.path), line or 1, key, msg)
        if self._warn and (unseen := priors.problem()):
            _log.warning("%s, line 1: '%s': %s", shown_path(self.path), *unseen)


def _decode(raw: bytes, ctx: _Ctx) -> str:
    try:
        return decode_utf8(raw)
    except UnicodeDecodeError as exc:
        hint = "; it is gzip data: decompress it first (gunzip)" if raw[:2] == b"\x1f\x8b" else ""
        raise ctx.error(None, f"not UTF-8 text (byte {exc.start}){hint}") from None


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
    _check_type(header, StreamHeader, "header")
    if truth is not None:
        _check_type(truth, Truth, "truth")
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
    _check_type(step, Step, "step")
    obj: dict[str, Any] = {"t": int(step.t)}
    if step.odom is not None:
        obj["odom"] = [_f(v) for v in step.odom]
    if step.odom_sigma is not None:
        obj["odom_sigma"] = [_f(v) for v in step.odom_sigma]
    obj["bearings"] = [[int(i), _f(b)] for i, b in zip(step.landmark_ids, step.bearings_rad)]
    if step.time_s is not None:
        obj["time_s"] = _f(step.time_s)
    return obj


def write_stream(stream: Stream, path: str | os.PathLike[str], *,
                 inputs: Sequence[str | os.PathLike[str] | None] = (),
                 ready: Callable[[str], None] | None = None) -> None:
    """Write a stream as JSON Lines; ``read_stream`` gives back an equal Stream.

    The same Stream always gives the same bytes (see :func:`write_stream_parts`).
    """
    _check_type(stream, Stream, "stream")
    write_stream_parts(stream.header, stream.steps, path, truth=stream.truth, inputs=inputs,
                       ready=ready)


def write_stream_parts(header: StreamHeader, steps: Iterable[Step],
                       path: str | os.PathLike[str], truth: Truth | None = None, *,
                       inputs: Sequence[str | os.PathLike[str] | None] = (),
                       ready: Callable[[str], None] | None = None) -> None:
    """Write a header and an iterable of steps (which may be a generator) to ``path``.

    Written as every bomgraph output is (:func:`bomgraph.stdio.output_file`): a regular file
    appears only when complete (written beside it under a unique name, then renamed), a link
    is followed, a device or FIFO is written directly; ``inputs`` (the files the stream is
    made from) are refused as ``path``. What :func:`read_stream` would refuse (steps out of
    order, odometry against the rule, no step, truth poses that are not one per step) is
    refused, and no file is left."""
    _check_type(header, StreamHeader, "header")   # before the output is made
    if truth is not None:
        _check_type(truth, Truth, "truth")
    if isinstance(steps, (Step, Stream, str)) or not isinstance(steps, Iterable):
        raise StreamFormatError(f"must be an iterable of Step, got {type(steps).__name__}"
                                + (" (pass stream.steps)" if isinstance(steps, Stream) else ""),
                                key="steps")
    with output_file(path, inputs=inputs, ready=ready) as fh:
        fh.write(json.dumps(header_to_json(header, truth), allow_nan=False) + "\n")
        n = 0
        for step in steps:
            if not isinstance(step, Step):
                raise StreamFormatError(f"steps[{n}] is a {type(step).__name__}, not a Step",
                                        key="steps")
            if step.t != n or (step.odom is None) != (n == 0):
                raise StreamFormatError(f"step {n} has t = {step.t} and odom "
                                        f"{'None' if step.odom is None else 'given'}; steps "
                                        f"must be t = 0, 1, 2, ... with odom None at t = 0 "
                                        f"only (read_stream would refuse the file)", key="t")
            fh.write(json.dumps(step_to_json(step), allow_nan=False) + "\n")
            n += 1
        if n == 0:
            raise StreamFormatError("no steps; a stream needs at least the step t = 0", key="t")
        if truth is not None and truth.poses is not None and len(truth.poses) != n:
            raise StreamFormatError(f"{len(truth.poses)} truth poses for {n} steps; give one "
                                    f"pose per step", key="truth")


def _check_type(value: Any, kind: type, key: str) -> None:
    if not isinstance(value, kind):
        hint = (" (write_stream(stream) writes a Stream)" if isinstance(value, Stream) else
                " (read_stream(path) reads one)" if kind is Stream and isinstance(
                    value, (str, os.PathLike)) else "")
        raise StreamFormatError(f"must be a {kind.__name__}, got {type(value).__name__}{hint}",
                                key=key)


def count_steps(stream_path: str | os.PathLike[str]) -> int:
    """The number of step lines of a stream file (its lines after the header), without
    parsing them: for a progress bar's total."""
    with open_input(stream_path) as fh:  # bounded: /dev/zero is refused, not counted forever
        n = sum(1 for _ in bounded_lines(fh, stream_path))
    return max(n - 1, 0)


def located(exc: StreamValueError, path: str | os.PathLike[str],
            method: str | None = None) -> StreamValueError:
    """A method's refusal of a value of the stream file ``path``, naming the file and the
    line, as the reader names a line it refuses: the header's line 1, step ``t``'s line
    ``t + 2`` (the format has no blank lines and no gaps in ``t``); and naming ``method``, the
    method run, rather than the part of it that refused (``GTSAM``, a hybrid's ``STMDS``)."""
    return exc if exc.path is not None else exc.in_file(
        path, 1 if exc.t is None else exc.t + 2, method)


__all__ = ["StreamReader", "read_stream", "write_stream", "write_stream_parts", "header_to_json",
           "step_to_json", "parse_priors", "count_steps", "located", "FORMAT_NAME",
           "FORMAT_VERSION"]
