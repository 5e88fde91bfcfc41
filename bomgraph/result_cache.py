"""The sweep cache's files: one JSON result per task key (:func:`bomgraph.bench.task_key`),
read back only when it is a successful result of that key and written atomically."""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import Any, Iterable, Mapping

from .claims import remove_leftovers_like
from .estimate_file import untimed_estimate_text
from .stdio import InputTooLargeError, output_file, read_regular_file
from .tables import counted

_log = logging.getLogger(__name__)


def read_cached(path: Path) -> dict[str, Any] | None:
    """A cached result, or None when there is none or it is unreadable (a corrupt file, not
    UTF-8, or JSON of the wrong shape is a cache miss, logged with its name, and is
    overwritten when the task has run again)."""
    if not path.exists():
        return None
    try:
        cached = json.loads(read_regular_file(path).decode("utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError,
            InputTooLargeError) as exc:
        _log.warning("ignoring the unreadable cache file %s (%s); the task runs again", path,
                     type(exc).__name__)
        return None
    if not (isinstance(cached, dict) and cached.get("ok") is True
            and cached.get("key") == path.stem):
        _log.warning("ignoring the cache file %s: not a result of this task; the task runs "
                     "again", path)
        return None
    problem = _shape_problem(cached)
    if problem:  # h91: a hand-edited entry ended compare in a traceback drawing its figures
        _log.warning("ignoring the cache file %s: %s; the task runs again", path, problem)
        return None
    return cached


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _points(v: Any) -> bool:
    """A list of ``[id, x, y]`` (or ``[t, x, y]``) rows, as ``run_task`` writes them."""
    return isinstance(v, list) and all(
        isinstance(r, list) and len(r) == 3 and isinstance(r[0], int)
        and not isinstance(r[0], bool) and _number(r[1]) and _number(r[2]) for r in v)


def _shape_problem(cached: Mapping[str, Any]) -> str:
    """What in a cached result is not of the shape ``bench.run_task`` writes ("" if nothing):
    the report reads it as such."""
    for k in ("experiment", "arm", "method", "run"):
        if not isinstance(cached.get(k), str):
            return f"'{k}' is not a string"
    fm = cached.get("final_map")
    if fm is not None and not (isinstance(fm, dict) and _points(fm.get("landmarks"))
                               and _points(fm.get("poses", []))):
        return "'final_map' is not {landmarks: [[id, x, y], ...], poses: [[t, x, y], ...]}"
    rows = cached.get("checkpoints")
    if not (isinstance(rows, list) and all(
            isinstance(r, dict) and isinstance(r.get("t"), int)
            and all(v is None or _number(v) for v in r.values()) for r in rows)):
        return "'checkpoints' is not a list of rows of numbers with an integer 't'"
    if not all(_number(cached.get(k)) for k in ("total_s", "step_median_s")):
        return "'total_s' or 'step_median_s' is not a number"
    conv = cached.get("converged")   # not `in (None, True, False)`: 1 == True, 0.0 == False
    if not isinstance(cached.get("info"), dict) or not (conv is None or isinstance(conv, bool)):
        return "'info' is not a table or 'converged' not true, false or null"
    if not isinstance(cached.get("estimate_file", ""), str):
        return "'estimate_file' is not a string"
    return ""


def write_cached(path: Path, result: Mapping[str, Any]) -> None:
    """Write a result as every output is (:func:`bomgraph.stdio.output_file`: under a unique
    temporary name beside ``path``, then renamed): two sweeps sharing a folder never write the
    same temporary file, and a reader never sees half a file. The temporary files killed
    sweeps left are not looked for here: :func:`remove_cache_leftovers` removes them once a
    sweep (a listing of a folder of 10,000 files for each file written cost as much as the
    write itself, and a sweep's listings grew as the square of its runs, h83)."""
    with output_file(path, leftovers=False) as fh:
        fh.write(json.dumps(result, allow_nan=True))


def remove_cache_leftovers(cache: Path) -> int:
    """Remove the temporary files of cache files (``.KEY.json.XXXXXXXX.partial``) in the
    cache folder ``cache`` that sweeps killed while writing left, never one a sweep running
    (sharing the folder) is writing (:func:`bomgraph.claims.remove_leftovers_like`); how
    many, logged."""
    removed = remove_leftovers_like(os.fspath(cache), r"[0-9a-f]+\.json")
    if removed:
        _log.info("removed %s that killed sweeps left in the cache %s",
                  counted(removed, "temporary file"), cache)
    return removed


def strip_timings(results: Iterable[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Results without wall times (which differ between runs), for reproducibility checks."""
    out = []
    for r in results:
        r2 = {k: v for k, v in r.items() if k not in ("total_s", "step_median_s")}
        if "checkpoints" in r2:
            r2["checkpoints"] = [{k: v for k, v in c.items() if k != "estimate_s"}
                                 for c in r2["checkpoints"]]
        if "info" in r2 and isinstance(r2["info"], dict):
            r2["info"] = {k: v for k, v in r2["info"].items() if not k.endswith("_s")}
        if isinstance(r2.get("estimate_file"), str):  # and a kept estimate's own
            r2["estimate_file"] = untimed_estimate_text(r2["estimate_file"])
        out.append(r2)
    return out


__all__ = ["read_cached", "write_cached", "remove_cache_leftovers", "strip_timings"]
