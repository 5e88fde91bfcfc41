"""The estimate file: what ``bomgraph run`` writes and ``bomgraph evaluate`` reads.

One JSON object (``STREAM_FORMAT.md``, last section): the method, the final map (landmarks
``[id, x_m, y_m]`` and poses ``[t, x_m, y_m, psi_rad]``), every checkpoint and the timings.
The reader is strict: unknown keys, duplicate keys and malformed entries are refused, naming
the file and the key.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from .errors import StreamFormatError
from .jsonio import DuplicateKeyError, is_id, is_num, no_duplicate_keys
from .mapper import Checkpoint, MapEstimate, RunResult


ESTIMATE_FORMAT = "bomgraph-estimate"


def _estimate_parts(est: MapEstimate) -> dict[str, Any]:
    out: dict[str, Any] = {"landmarks": [[int(i), float(x), float(y)] for i, (x, y)
                                         in zip(est.landmark_ids, est.landmarks_xy)]}
    if est.poses is not None:
        out["poses"] = [[int(t), float(p[0]), float(p[1]), float(p[2])]
                        for t, p in zip(est.pose_t, est.poses)]
    return out


def estimate_to_json(result: RunResult) -> dict[str, Any]:
    """The estimate file of a run: the final map, every checkpoint and the timings."""
    obj: dict[str, Any] = {"format": ESTIMATE_FORMAT, "version": 1, "method": result.method}
    obj.update(_estimate_parts(result.final))
    obj["checkpoints"] = [{"t": c.t, **_estimate_parts(c.estimate)} for c in result.checkpoints]
    obj["timing_s"] = result.timing()
    return obj


def write_estimate(result: RunResult, path: str | os.PathLike[str]) -> None:
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(estimate_to_json(result), fh, allow_nan=False)
        fh.write("\n")


@dataclass(frozen=True)
class EstimateFile:
    """An estimate file read back: the final map and the checkpoints."""

    method: str
    final: MapEstimate
    checkpoints: tuple[Checkpoint, ...]
    timing_s: Mapping[str, float]


_ESTIMATE_KEYS = {"format", "version", "method", "landmarks", "poses", "checkpoints",
                  "timing_s"}
_CHECKPOINT_KEYS = {"t", "landmarks", "poses"}


def _parse_estimate_parts(obj: Mapping[str, Any], path: str, where: str) -> MapEstimate:
    def bad(key: str, msg: str) -> StreamFormatError:
        return StreamFormatError(msg, path=path, key=f"{where}{key}")

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
        raise bad("landmarks", "a landmark id appears twice")
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
            raise bad("poses", "a step t appears twice")
        pose_t, poses = np.array(ts, dtype=np.int64), np.array(ps).reshape(-1, 3)
    return MapEstimate(np.array(ids, dtype=np.int64), np.array(xy).reshape(-1, 2),
                       pose_t=pose_t, poses=poses)


def read_estimate(path: str | os.PathLike[str]) -> EstimateFile:
    """Read an estimate file written by ``bomgraph run`` (strictly: unknown keys, duplicate
    keys and malformed entries are refused, naming the file and the key)."""
    path = str(path)
    try:
        with open(path, encoding="utf-8") as fh:
            obj = json.load(fh, object_pairs_hook=no_duplicate_keys)
    except OSError as exc:
        raise StreamFormatError(f"cannot open: {exc.strerror}", path=path) from None
    except DuplicateKeyError as exc:
        raise StreamFormatError("appears twice in one object", path=path, key=str(exc)) from None
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError, ValueError) as exc:
        raise StreamFormatError(f"not a JSON estimate file ({type(exc).__name__})",
                                path=path) from None
    if not isinstance(obj, dict) or obj.get("format") != ESTIMATE_FORMAT:
        raise StreamFormatError(f"must be a JSON object with \"format\": \"{ESTIMATE_FORMAT}\"",
                                path=path, key="format")
    version = obj.get("version")
    if not (isinstance(version, int) and not isinstance(version, bool) and version == 1):
        raise StreamFormatError("unknown version; this reader knows version 1", path=path,
                                key="version")
    unknown = sorted(set(obj) - _ESTIMATE_KEYS)
    if unknown:
        raise StreamFormatError(f"unknown key; allowed: {', '.join(sorted(_ESTIMATE_KEYS))}",
                                path=path, key=unknown[0])
    if not isinstance(obj.get("method", ""), str):
        raise StreamFormatError("must be a string", path=path, key="method")
    final = _parse_estimate_parts(obj, path, "")
    raw_cps = obj.get("checkpoints") or []
    if not isinstance(raw_cps, list):
        raise StreamFormatError("must be a list of {t, landmarks, poses}", path=path,
                                key="checkpoints")
    cps = []
    for k, c in enumerate(raw_cps):
        if not isinstance(c, dict) or not is_id(c.get("t")):
            raise StreamFormatError("each checkpoint needs an integer t >= 0", path=path,
                                    key=f"checkpoints[{k}].t")
        extra = sorted(set(c) - _CHECKPOINT_KEYS)
        if extra:
            raise StreamFormatError("unknown key in a checkpoint", path=path,
                                    key=f"checkpoints[{k}].{extra[0]}")
        if cps and c["t"] <= cps[-1].t:
            raise StreamFormatError("checkpoints must be in increasing t", path=path,
                                    key=f"checkpoints[{k}].t")
        cps.append(Checkpoint(c["t"], _parse_estimate_parts(c, path, f"checkpoints[{k}]."),
                              0.0))
    timing = obj.get("timing_s") or {}
    if not isinstance(timing, dict) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in timing.values()):
        raise StreamFormatError("must be an object of numbers", path=path, key="timing_s")
    return EstimateFile(str(obj.get("method", "")), final, tuple(cps), dict(timing))


__all__ = ["ESTIMATE_FORMAT", "EstimateFile", "estimate_to_json", "write_estimate",
           "read_estimate"]
