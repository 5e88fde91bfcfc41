"""The runner's results as rows (paper section IV's numbers): one row per experiment and
arm (:func:`summarise`), one per run (:func:`final_by_run`), each arm's error curves over
time (:func:`error_curves`) and the long format of every checkpoint
(:func:`results_to_csv_rows`); :func:`group_rows` groups rows by their keys' values (the
report's tables too). Plain data, no files and no text: :mod:`bomgraph.report` formats these
rows as tables and writes them with the figures.

A result is the dict of :func:`bomgraph.bench.run_task`; its ``checkpoints`` are the rows of
:func:`bomgraph.evaluate.score_checkpoints` as dicts.
"""

from __future__ import annotations

import math
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from .experiments import PAPER_REPORTED
from .run_scoring import scored_against, scores_left_out

#: The checkpoints the summary reports (and the last one of each experiment).
REPORT_TIMES = (50, 100, 200, 300)


def group_rows(rows: Sequence[Mapping[str, Any]], *keys: str
               ) -> dict[tuple[Any, ...], list[Mapping[str, Any]]]:
    """``rows`` by the values of ``keys``, groups and rows in order of appearance."""
    out: dict[tuple[Any, ...], list[Mapping[str, Any]]] = {}
    for r in rows:
        out.setdefault(tuple(r[k] for k in keys), []).append(r)
    return out


def _finite_stat(stat: Callable[[np.ndarray], Any], values: np.ndarray) -> float:
    """``stat`` (a NaN-ignoring reduction) of ``values``, or NaN when none is finite."""
    return float(stat(values)) if np.any(np.isfinite(values)) else math.nan


def _value_at(res: Mapping[str, Any], t: int, key: str) -> float:
    """The metric at checkpoint ``t`` (the last checkpoint at or before ``t``)."""
    best = math.nan
    for row in res.get("checkpoints", []):
        if row["t"] <= t:
            v = row.get(key)
            best = math.nan if v is None else float(v)
    return best


def summarise(results: Sequence[Mapping[str, Any]],
              times: Sequence[int] = REPORT_TIMES) -> list[dict[str, Any]]:
    """One row per (experiment, arm): MPE at ``times`` (mean, median, std), robot error,
    convergence, NEES, wall time. Failed runs are counted, not hidden; a run scored against
    its own map (``self_scored``) only for its truth-free values (``n_scored@t`` 0)."""
    results = [scores_left_out(r) for r in results]
    groups = group_rows(results, "experiment", "arm")
    exp_last: dict[str, int] = {}
    for r in results:
        if r.get("ok") and r["checkpoints"]:
            exp_last[r["experiment"]] = max(exp_last.get(r["experiment"], 0),
                                            r["checkpoints"][-1]["t"])
    rows = []
    for (exp, arm), rs in groups.items():
        ok = [r for r in rs if r.get("ok")]
        last_t = exp_last.get(exp, 0)
        row: dict[str, Any] = {"experiment": exp, "arm": arm, "method": rs[0]["method"],
                               "runs": len(rs), "failed": len(rs) - len(ok),
                               "errors": sorted({r.get("error", "") for r in rs
                                                 if not r.get("ok")})}
        for t in sorted({*[t for t in times if t <= last_t], last_t} - {0}):
            v = np.array([_value_at(r, t, "mpe_m") for r in ok])
            row[f"n_scored@{t}"] = int(np.sum(np.isfinite(v)))
            row[f"mpe_mean_m@{t}"] = _finite_stat(np.nanmean, v)
            row[f"mpe_median_m@{t}"] = _finite_stat(np.nanmedian, v)
            row[f"mpe_std_m@{t}"] = (float(np.nanstd(v, ddof=1)) if np.sum(np.isfinite(v)) > 1
                                     else math.nan)
        robot = np.array([_value_at(r, last_t, "robot_last_m") for r in ok])
        row["robot_last_mean_m"] = _finite_stat(np.nanmean, robot)
        row["n_robot"] = int(np.sum(np.isfinite(robot)))
        rm = np.array([np.nanmean([c["robot_last_m"] for c in r["checkpoints"]])
                       if any(np.isfinite(c["robot_last_m"]) for c in r["checkpoints"])
                       else math.nan for r in ok])
        row["robot_over_time_mean_m"] = _finite_stat(np.nanmean, rm)
        conv = [r.get("converged") for r in ok if r.get("converged") is not None]
        row["converged_rate"] = float(np.mean(conv)) if conv else math.nan
        row["n_converged_known"] = len(conv)
        nees = np.array([_value_at(r, last_t, "nees_pose") for r in ok])
        row["nees_pose_mean"] = _finite_stat(np.nanmean, nees)
        row["n_nees_pose"] = int(np.sum(np.isfinite(nees)))
        nl = np.array([_value_at(r, last_t, "nees_landmark") for r in ok])
        row["nees_landmark_mean"] = _finite_stat(np.nanmean, nl)
        row["n_nees_landmark"] = int(np.sum(np.isfinite(nl)))
        row["n_nees_landmark_partial"] = sum(  # landmarks without a covariance left out
            1 for r, v in zip(ok, nl)
            if math.isfinite(v) and (r.get("info") or {}).get("covariances") == "partial")
        wall = np.array([r["total_s"] for r in ok])
        row["wall_s_mean"] = float(wall.mean()) if wall.size else math.nan
        row["paper"] = PAPER_REPORTED.get((exp, arm), "")
        row["last_t"] = last_t
        _truth_free_columns(row, ok, last_t)
        rows.append(row)
    return rows


def _truth_free_columns(row: dict[str, Any], ok: Sequence[Mapping[str, Any]],
                        last_t: int) -> None:
    """For runs on streams without ground truth (their checkpoints carry
    ``bearing_rms_rad``): what they were scored against, landmarks mapped and the mean RMS
    bearing residual at the end. Rows of runs with truth are left as they were."""
    free = [r for r in ok if r["checkpoints"] and "bearing_rms_rad" in r["checkpoints"][-1]]
    if not free:
        return
    row["scored_against"] = "; ".join(sorted({scored_against(r) for r in ok}))
    row["n_mapped_mean"] = float(np.mean([r["checkpoints"][-1]["n_mapped"] for r in free]))
    row["bearing_rms_mean_rad"] = _finite_stat(
        np.nanmean, np.array([_value_at(r, last_t, "bearing_rms_rad") for r in free]))


def final_by_run(results: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """One row per run: the final checkpoint's landmark MPE, landmarks mapped and robot error,
    or the failure. For experiments whose runs are different recordings (the real data), where
    a mean over runs hides which recording a method fails on."""
    rows = []
    for r in map(scores_left_out, results):  # no MPE of a map against itself
        row: dict[str, Any] = {"experiment": r["experiment"], "arm": r["arm"], "run": r["run"],
                               "ok": bool(r.get("ok")), "error": r.get("error", "")}
        last = r["checkpoints"][-1] if r.get("ok") and r.get("checkpoints") else {}
        row["t"] = last.get("t", math.nan)
        row["n_mapped"] = last.get("n_mapped", 0)
        for key in ("mpe_m", "robot_last_m", "bearing_rms_rad"):
            v = last.get(key)
            row[key] = math.nan if v is None else float(v)
        row["converged"] = r.get("converged")
        row["total_s"] = r.get("total_s", math.nan)
        if "scored_against" in r:  # a stream without truth (the paper's rows as they were)
            row["scored_against"] = r["scored_against"]
            row["self_scored"] = r.get("self_scored", "")  # "itself", "method" or ""
        rows.append(row)
    return rows


def error_curves(results: Sequence[Mapping[str, Any]], metric: str = "mpe_m"
                 ) -> dict[tuple[str, str], tuple[np.ndarray, np.ndarray]]:
    """Per (experiment, arm): all runs' checkpoint times ``(k,)``, the metric ``(runs, k)``."""
    out: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]] = {}
    for key, rs in group_rows([scores_left_out(r) for r in results if r.get("ok")],
                              "experiment", "arm").items():
        ts = np.array(sorted({c["t"] for r in rs for c in r["checkpoints"]}))
        vals = np.array([[_value_at(r, t, metric) if t <= r["checkpoints"][-1]["t"]
                          else math.nan for t in ts] for r in rs])  # NaN: the stream ended
        out[key] = (ts, vals)
    return out


def results_to_csv_rows(results: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Long format: one row per (experiment, arm, run, checkpoint)."""
    rows = []
    for r in results:
        if not r.get("ok"):
            rows.append({"experiment": r["experiment"], "arm": r["arm"], "run": r["run"],
                         "ok": False, "error": r.get("error", "")})
            continue
        mark = {k: r[k] for k in ("scored_against", "self_scored") if k in r}
        for c in r["checkpoints"]:
            rows.append({"experiment": r["experiment"], "arm": r["arm"], "run": r["run"],
                         "ok": True, "error": "", **c, **mark})
    return rows


__all__ = ["REPORT_TIMES", "summarise", "final_by_run", "error_curves", "results_to_csv_rows",
           "group_rows"]
