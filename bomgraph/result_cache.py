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
    return cached


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
        _log.info("removed %d temporary file(s) that killed sweeps left in the cache %s",
                  removed, cache)
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
