"""Writing the estimate file (version 2; :mod:`bomgraph.estimate_file` reads it, and
re-exports what is here): :class:`EstimateWriter`, checkpoint by checkpoint into a unique
temporary file beside the target, renamed into place once complete, so an exception or SIGTERM
leaves the previous file as it was; :func:`write_estimate` for a whole :class:`RunResult`;
:func:`estimate_to_json` for the version-1 object.

What the reader would refuse is refused before it is written (a negative step, a covariance
that is not finite, symmetric and positive semi-definite, a checkpoint out of order, timings
that are not numbers), naming the argument: a file ``bomgraph run`` writes is one
``bomgraph evaluate`` reads.
"""

from __future__ import annotations

import io
import json
import math
import os
import shutil
import signal
import tempfile
import threading
from typing import IO, Any, Mapping

import numpy as np

from .checks import covariance_problem, file_name, finite, integer, out_named
from .errors import ConfigError
from .jsonio import jsonable, options_to_json
from .mapper import Checkpoint, MapEstimate, RunResult
from .stdio import AtomicOutput, OutputPathError
from .stream_identity import StreamHasher, StreamIdentity


ESTIMATE_FORMAT = "bomgraph-estimate"
ESTIMATE_VERSION = 2


def _flat(cov: np.ndarray) -> list[list[float] | None]:
    """Each matrix row-major; ``None`` (JSON ``null``) for one all NaN: not defined."""
    return [None if np.isnan(c).all() else [float(v) for v in c.ravel()] for c in cov]


def _unreadable(c: Checkpoint, key: str, what: str) -> ConfigError:
    return ConfigError(f"estimate file: the checkpoint at t = {c.t}: '{key}': {what}; "
                       f"read_estimate would refuse the file, so it is not written")


def _writable_cov(cov: np.ndarray, key: str, c: Checkpoint) -> list[list[float] | None]:
    bad = covariance_problem(cov)
    if bad is not None:
        raise _unreadable(c, f"{key}[{bad[0]}]", bad[1])
    return _flat(cov)


def _checkpoint_line(c: Checkpoint, since_t: int | None) -> dict[str, Any]:
    """One checkpoint as a JSON-ready dict: every landmark; the poses with ``t > since_t``
    as ``new_poses`` (or, with ``since_t`` None, all of them as ``poses``). What the reader
    would refuse (a negative step, a covariance that is not one) is refused here."""
    est = c.estimate
    obj: dict[str, Any] = {"t": int(c.t), "landmarks": [
        [int(i), float(x), float(y)] for i, (x, y) in zip(est.landmark_ids, est.landmarks_xy)]}
    if est.landmark_cov is not None:
        obj["landmark_cov"] = _writable_cov(est.landmark_cov, "landmark_cov", c)
    if est.poses is not None:
        keep = (np.ones(len(est.pose_t), bool) if since_t is None else est.pose_t > since_t)
        key = "poses" if since_t is None else "new_poses"
        if keep.any() and est.pose_t[keep].min() < 0:
            raise _unreadable(c, key, f"a pose at step {int(est.pose_t[keep].min())} (steps "
                                      f"are integers >= 0)")
        obj[key] = [[int(t), float(p[0]), float(p[1]), float(p[2])]
                    for t, p in zip(est.pose_t[keep], est.poses[keep])]
        if est.pose_cov is not None:
            obj[key.replace("poses", "pose_cov")] = _writable_cov(
                est.pose_cov[keep], key.replace("poses", "pose_cov"), c)
    if est.info:
        obj["info"] = jsonable(est.info)
    obj["estimate_s"] = float(c.estimate_s)
    return obj


def _dumps(obj: Any) -> str:
    return json.dumps(obj, allow_nan=False, separators=(",", ":")) + "\n"


class EstimateWriter:
    """Writes a version-2 estimate file checkpoint by checkpoint, atomically.

    Use as a context manager and pass :meth:`add` as :func:`bomgraph.mapper.run`'s
    ``on_checkpoint``; :meth:`finish` writes the timings, flushes to disk and renames the
    file into place. Until then the data sit in a uniquely named temporary file beside the
    target (``.NAME.*.partial``), removed if the block exits any other way; while the block
    runs in the main thread with SIGTERM at its default, SIGTERM raises ``SystemExit(143)`` so
    the temporary file is removed too. The target is written as every bomgraph output is
    (:class:`bomgraph.stdio.AtomicOutput`: links followed, devices and FIFOs written
    directly). Memory: one checkpoint is held back (the last one is written with its whole
    trajectory).

    ``stream`` may be a :class:`~bomgraph.stream_identity.StreamHasher` that the steps are
    added to as the run reads them (``bomgraph run`` reads the stream once): the header,
    which names the stream, is then known at :meth:`finish` only (the same bytes as with the
    identity given at the start). The checkpoints then go after room for the longest such
    header in the temporary file, and :meth:`finish` writes the header and moves them back
    onto its end in place: the file takes no more room on the disk than the estimate. A
    device or a FIFO, written in order, gets them from an unnamed temporary file (in the
    temporary directory) copied after the header.
    """

    def __init__(self, path: str | os.PathLike[str], method: str, *,
                 stream: StreamIdentity | StreamHasher | None = None,
                 options: Mapping[str, Any] | None = None,
                 checkpoint_every: int | None = None) -> None:
        self.path = file_name(path, out_named("path"), OutputPathError)
        _check_header(method, stream, options)
        self._header: dict[str, Any] = {"format": ESTIMATE_FORMAT,
                                        "version": ESTIMATE_VERSION, "method": str(method)}
        self._hasher = stream if isinstance(stream, StreamHasher) else None
        if isinstance(stream, StreamIdentity):
            self._header["stream"] = stream.as_dict()
        elif self._hasher is not None:  # its place in the header, filled in by finish()
            self._header["stream"] = None
        if options:
            self._header["options"] = jsonable(options_to_json(dict(options)))
        if checkpoint_every is not None:
            self._header["checkpoint_every"] = integer(
                checkpoint_every, "estimate file: checkpoint_every", ConfigError, minimum=1)
        self._fh: IO[str] | None = None  # where the checkpoints go
        self._out: AtomicOutput | None = None
        self._body: IO[str] | None = None  # with a hasher: the checkpoints until finish()
        self._held: Checkpoint | None = None
        self._since_t: int | None = -1
        self._last_t = -1
        self._estimate_s: list[float] = []
        self._old_handler: Any = None

    def __enter__(self) -> "EstimateWriter":
        self._out = AtomicOutput(self.path)
        try:  # __exit__ does not run when __enter__ raises
            self._fh = self._out.open()
            if self._hasher is not None and self._out.direct:
                self._body = self._fh = _body_file()
            elif self._hasher is not None:  # room for the header, written by finish()
                self._fh.write(" " * (self._room() - 1) + "\n")
            if (threading.current_thread() is threading.main_thread()
                    and signal.getsignal(signal.SIGTERM) == signal.SIG_DFL):
                self._old_handler = signal.signal(signal.SIGTERM, _raise_exit)
            if self._hasher is None:
                self._fh.write(_dumps(self._header))
        except BaseException:
            self.__exit__()
            raise
        return self

    def add(self, c: Checkpoint) -> None:
        """The next checkpoint (in increasing ``t``)."""
        if self._fh is None:
            raise ConfigError("EstimateWriter.add() outside its with-block or after finish() "
                              "(with EstimateWriter(path, method) as w: ...)")
        if not (isinstance(c, Checkpoint) and isinstance(c.estimate, MapEstimate)):
            got = (f"a Checkpoint whose estimate is {type(c.estimate).__name__}"
                   if isinstance(c, Checkpoint) else type(c).__name__)
            raise ConfigError(f"EstimateWriter.add(): needs a Checkpoint(t, MapEstimate, "
                              f"estimate_s) (what run() hands on_checkpoint), got {got}")
        t = integer(c.t, "EstimateWriter.add(): the checkpoint's t", ConfigError)
        estimate_s = finite(c.estimate_s, f"EstimateWriter.add(): the checkpoint at t = {t}: "
                                          f"estimate_s", ConfigError)
        if t <= self._last_t:
            raise ConfigError(f"checkpoints must come in increasing t: {t} after "
                              f"{self._last_t}")
        self._last_t = t
        self._estimate_s.append(estimate_s)
        if self._held is not None:
            self._fh.write(_dumps(_checkpoint_line(self._held, self._since_t)))
            pt = self._held.estimate.pose_t
            if pt is not None and len(pt):
                self._since_t = max(self._since_t, int(pt.max()))
        self._held = c

    def finish(self, result: RunResult | None = None) -> None:
        """Write the last checkpoint and the timings, and move the file into place."""
        if self._fh is None or self._held is None:
            raise ConfigError("an estimate file needs at least one checkpoint" + (
                "" if self._fh else " (EstimateWriter.finish() outside its with-block or "
                                    "twice)"))
        if result is not None and not isinstance(result, RunResult):
            raise ConfigError(f"EstimateWriter.finish(): result must be the RunResult or "
                              f"None, got {type(result).__name__}")
        self._fh.write(_dumps(_checkpoint_line(self._held, None)))
        est = np.array(self._estimate_s)
        timing: dict[str, float] = {}
        if result is not None:
            try:
                step_s = np.asarray(result.step_s, dtype=float)
                timing = {"total": float(result.total_s), "steps": float(step_s.sum()),
                          "step_median": float(np.median(step_s)) if step_s.size else 0.0}
            except (TypeError, ValueError):
                timing = {"total": math.nan}
        timing.update({"estimates": float(est.sum()), "estimate_median": float(np.median(est))})
        if not all(math.isfinite(v) for v in timing.values()):
            raise ConfigError(f"estimate file: the run's timings must be finite numbers of "
                              f"seconds (RunResult.total_s and step_s), got {timing}")
        self._fh.write(_dumps({"timing_s": timing}))
        self._fh = None
        if self._hasher is not None:  # the header, now that the stream is known
            self._header["stream"] = self._hasher.identity.as_dict()
            out = self._out.fh
            if self._body is not None:  # then the checkpoints, copied after it
                out.write(_dumps(self._header))
                out.flush()
                self._body.flush()
                self._body.buffer.seek(0)  # bytes to bytes: the text is UTF-8 either way
                shutil.copyfileobj(self._body.buffer, out.buffer, 1 << 20)
                self._close_body()
            else:
                out.flush()
                _put_header(out.fileno(), _dumps(self._header).encode("utf-8"),
                            self._room())
        self._out.commit()

    def _room(self) -> int:
        """The bytes of the longest header a hashed stream can give: its count of steps
        with 19 digits (more steps than a stream file can hold)."""
        longest = dict(self._header, stream={"steps_sha256": "0" * 64, "n_steps": 10 ** 18})
        return len(_dumps(longest).encode("utf-8"))

    def __exit__(self, *exc: object) -> None:
        try:
            self._fh = None
            self._close_body()
            if self._out is not None:
                self._out.abort()
        finally:
            if self._old_handler is not None:
                signal.signal(signal.SIGTERM, self._old_handler)
                self._old_handler = None


    def _close_body(self) -> None:
        if self._body is not None:
            body, self._body = self._body, None
            body.close()


def _body_file() -> IO[str]:
    """An unnamed temporary file (gone when closed, or when the process dies) in the
    temporary directory: the checkpoints for a device or a FIFO until the header is known."""
    return io.TextIOWrapper(tempfile.TemporaryFile(), encoding="utf-8", newline="\n")


def _put_header(fd: int, header: bytes, room: int) -> None:
    """Write ``header`` at the start of the file ``fd``, whose first ``room`` bytes were kept
    for it, and move what follows them back to its end (front to back, so nothing is
    overwritten before it is read; the file only shrinks)."""
    if len(header) > room:
        raise RuntimeError(f"the estimate's header takes {len(header)} bytes, more than the "
                           f"{room} kept for it")
    end = os.lseek(fd, 0, os.SEEK_END)
    os.lseek(fd, 0, os.SEEK_SET)
    _write_all(fd, header)
    src, dst = room, len(header)
    while src < end and src != dst:
        os.lseek(fd, src, os.SEEK_SET)
        chunk = os.read(fd, min(1 << 20, end - src))
        if not chunk:
            raise OSError(f"the estimate's temporary file ended at byte {src}, not {end}")
        os.lseek(fd, dst, os.SEEK_SET)
        _write_all(fd, chunk)
        src, dst = src + len(chunk), dst + len(chunk)
    os.ftruncate(fd, end - (room - len(header)))
    os.lseek(fd, 0, os.SEEK_END)


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def _check_header(method: Any, stream: Any, options: Any) -> None:
    """Refuse a header the file cannot hold as given (naming the argument)."""
    if not isinstance(method, str):
        raise ConfigError(f"estimate file: method must be the method's name (a str), got "
                          f"{type(method).__name__} {method!r:.40}")
    if stream is not None and not isinstance(stream, (StreamIdentity, StreamHasher)):
        hint = (" (stream_file_identity(path))" if isinstance(stream, (str, os.PathLike)) else
                " (stream_identity(stream.steps))" if hasattr(stream, "steps") else "")
        raise ConfigError(f"estimate file: stream must be a StreamIdentity, a StreamHasher or "
                          f"None, got {type(stream).__name__}{hint}")
    if options is not None and not isinstance(options, Mapping):
        raise ConfigError(f"estimate file: options must be a mapping of option names to "
                          f"values (or None), got {type(options).__name__}")


def _raise_exit(signum: int, frame: Any) -> None:
    raise SystemExit(128 + signum)


def write_estimate(result: RunResult, path: str | os.PathLike[str], *,
                   stream: StreamIdentity | None = None,
                   options: Mapping[str, Any] | None = None,
                   checkpoint_every: int | None = None) -> None:
    """Write a run's estimate file (version 2, atomically)."""
    _check_result(result, "write_estimate")
    with EstimateWriter(path, result.method, stream=stream, options=options,
                        checkpoint_every=checkpoint_every) as w:
        for c in result.checkpoints:
            w.add(c)
        w.finish(result)


def _check_result(result: Any, where: str) -> None:
    if not isinstance(result, RunResult):
        hint = (" (run() returns the RunResult; a MapEstimate is one checkpoint's map)"
                if isinstance(result, MapEstimate) else "")
        raise ConfigError(f"{where}(): result must be a RunResult, got "
                          f"{type(result).__name__}{hint}")


def estimate_to_json(result: RunResult) -> dict[str, Any]:
    """The version-1 object of a run (every checkpoint's whole map; kept for scripts that
    want one JSON value; files are written as version 2)."""
    _check_result(result, "estimate_to_json")
    obj: dict[str, Any] = {"format": ESTIMATE_FORMAT, "version": 1, "method": result.method}
    obj.update(_estimate_parts(result.final))
    obj["checkpoints"] = [{"t": c.t, **_estimate_parts(c.estimate)} for c in result.checkpoints]
    obj["timing_s"] = result.timing()
    return obj


def _estimate_parts(est: MapEstimate) -> dict[str, Any]:
    out: dict[str, Any] = {"landmarks": [[int(i), float(x), float(y)] for i, (x, y)
                                         in zip(est.landmark_ids, est.landmarks_xy)]}
    if est.poses is not None:
        out["poses"] = [[int(t), float(p[0]), float(p[1]), float(p[2])]
                        for t, p in zip(est.pose_t, est.poses)]
    return out


__all__ = ["ESTIMATE_FORMAT", "ESTIMATE_VERSION", "EstimateWriter", "write_estimate",
           "estimate_to_json"]
