"""Writing the estimate file (version 2; :mod:`bomgraph.estimate_file` reads it, and
re-exports what is here): :class:`EstimateWriter`, checkpoint by checkpoint into a unique
temporary file beside the target, renamed into place once complete, so an exception or SIGTERM
leaves the previous file as it was; :func:`write_estimate` for a whole :class:`RunResult`;
:func:`estimate_to_json` for the version-1 object.
"""

from __future__ import annotations

import json
import os
import signal
import threading
from typing import IO, Any, Mapping

import numpy as np

from .checks import file_name
from .jsonio import jsonable
from .mapper import Checkpoint, MapEstimate, RunResult
from .stdio import AtomicOutput, OutputPathError
from .stream_identity import StreamIdentity


ESTIMATE_FORMAT = "bomgraph-estimate"
ESTIMATE_VERSION = 2


def _flat(cov: np.ndarray) -> list[list[float]]:
    return [[float(v) for v in c.ravel()] for c in cov]


def _checkpoint_line(c: Checkpoint, since_t: int | None) -> dict[str, Any]:
    """One checkpoint as a JSON-ready dict: every landmark; the poses with ``t > since_t``
    as ``new_poses`` (or, with ``since_t`` None, all of them as ``poses``)."""
    est = c.estimate
    obj: dict[str, Any] = {"t": int(c.t), "landmarks": [
        [int(i), float(x), float(y)] for i, (x, y) in zip(est.landmark_ids, est.landmarks_xy)]}
    if est.landmark_cov is not None:
        obj["landmark_cov"] = _flat(est.landmark_cov)
    if est.poses is not None:
        keep = (np.ones(len(est.pose_t), bool) if since_t is None else est.pose_t > since_t)
        key = "poses" if since_t is None else "new_poses"
        obj[key] = [[int(t), float(p[0]), float(p[1]), float(p[2])]
                    for t, p in zip(est.pose_t[keep], est.poses[keep])]
        if est.pose_cov is not None:
            obj[key.replace("poses", "pose_cov")] = _flat(est.pose_cov[keep])
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
    """

    def __init__(self, path: str | os.PathLike[str], method: str, *,
                 stream: StreamIdentity | None = None,
                 options: Mapping[str, Any] | None = None,
                 checkpoint_every: int | None = None) -> None:
        self.path = file_name(path, "--out", OutputPathError)
        self._header: dict[str, Any] = {"format": ESTIMATE_FORMAT,
                                        "version": ESTIMATE_VERSION, "method": str(method)}
        if stream is not None:
            self._header["stream"] = stream.as_dict()
        if options:
            self._header["options"] = jsonable(dict(options))
        if checkpoint_every is not None:
            self._header["checkpoint_every"] = int(checkpoint_every)
        self._fh: IO[str] | None = None
        self._out: AtomicOutput | None = None
        self._held: Checkpoint | None = None
        self._since_t: int | None = -1
        self._last_t = -1
        self._estimate_s: list[float] = []
        self._old_handler: Any = None

    def __enter__(self) -> "EstimateWriter":
        self._out = AtomicOutput(self.path)
        try:  # __exit__ does not run when __enter__ raises
            self._fh = self._out.open()
            if (threading.current_thread() is threading.main_thread()
                    and signal.getsignal(signal.SIGTERM) == signal.SIG_DFL):
                self._old_handler = signal.signal(signal.SIGTERM, _raise_exit)
            self._fh.write(_dumps(self._header))
        except BaseException:
            self.__exit__()
            raise
        return self

    def add(self, c: Checkpoint) -> None:
        """The next checkpoint (in increasing ``t``)."""
        if self._fh is None:
            raise RuntimeError("EstimateWriter.add outside its with-block")
        if c.t <= self._last_t:
            raise ValueError(f"checkpoints must come in increasing t: {c.t} after "
                             f"{self._last_t}")
        self._last_t = c.t
        self._estimate_s.append(float(c.estimate_s))
        if self._held is not None:
            self._fh.write(_dumps(_checkpoint_line(self._held, self._since_t)))
            pt = self._held.estimate.pose_t
            if pt is not None and len(pt):
                self._since_t = max(self._since_t, int(pt.max()))
        self._held = c

    def finish(self, result: RunResult | None = None) -> None:
        """Write the last checkpoint and the timings, and move the file into place."""
        if self._fh is None or self._held is None:
            raise ValueError("an estimate file needs at least one checkpoint")
        self._fh.write(_dumps(_checkpoint_line(self._held, None)))
        est = np.array(self._estimate_s)
        timing: dict[str, float] = {}
        if result is not None:
            timing = {"total": float(result.total_s), "steps": float(result.step_s.sum()),
                      "step_median": (float(np.median(result.step_s)) if result.step_s.size
                                      else 0.0)}
        timing.update({"estimates": float(est.sum()), "estimate_median": float(np.median(est))})
        self._fh.write(_dumps({"timing_s": timing}))
        self._fh = None
        self._out.commit()

    def __exit__(self, *exc: object) -> None:
        try:
            self._fh = None
            if self._out is not None:
                self._out.abort()
        finally:
            if self._old_handler is not None:
                signal.signal(signal.SIGTERM, self._old_handler)
                self._old_handler = None


def _raise_exit(signum: int, frame: Any) -> None:
    raise SystemExit(128 + signum)


def write_estimate(result: RunResult, path: str | os.PathLike[str], *,
                   stream: StreamIdentity | None = None,
                   options: Mapping[str, Any] | None = None,
                   checkpoint_every: int | None = None) -> None:
    """Write a run's estimate file (version 2, atomically)."""
    with EstimateWriter(path, result.method, stream=stream, options=options,
                        checkpoint_every=checkpoint_every) as w:
        for c in result.checkpoints:
            w.add(c)
        w.finish(result)


def estimate_to_json(result: RunResult) -> dict[str, Any]:
    """The version-1 object of a run (every checkpoint's whole map; kept for scripts that
    want one JSON value; files are written as version 2)."""
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
