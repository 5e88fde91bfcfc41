"""Figure files of ``bomgraph plot``: one run (an estimate file over its stream's truth) and a
``compare`` output folder (its ``results.json``). This module reads and scores; the drawing is
:func:`bomgraph.plots.run_figure` and :func:`bomgraph.plots.results_figure` on arrays. The
format follows the file name: ``.png`` (raster), ``.pdf`` or ``.svg`` (vector).
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .checks import option_named
from .errors import BomgraphError, ConfigError, EvaluationError, shown_path
from .estimate_file import read_estimate
from .file_evaluation import check_stream_identity, method_label, poses_revised
from .evaluate import score_estimate
from .plots import results_figure, run_figure
from .run_scoring import not_drawn_line, scores_left_out, self_scored
from .stdio import check_output_path, read_regular_file, write_figure
from .stream_file import read_stream
from .summaries import error_curves
from .tables import plural

FIGURE_SUFFIXES = (".png", ".pdf", ".svg")
_LANDMARKS = "align_on='landmarks'"


def _check_out(out: str | os.PathLike[str], *inputs: str | os.PathLike[str]) -> Path:
    if not os.fspath(out):  # refuses it: "--out is empty" (Path('') is '.')
        check_output_path(out, inputs, name="out")
    path = Path(out)
    if path.suffix.lower() not in FIGURE_SUFFIXES:
        raise ConfigError(f"{shown_path(out)}: the figure's file name must end in "
                          f"{', '.join(FIGURE_SUFFIXES)}")
    check_output_path(path, inputs, name="out")  # the parameter's name (h103), not 'path'
    return path


def plot_run(estimate_path: str | os.PathLike[str], stream_path: str | os.PathLike[str],
             out: str | os.PathLike[str], *, t: int | None = None, align_on: str = "landmarks",
             dpi: int = 150) -> str:
    """Draw one estimate (the final map, or the checkpoint at step ``t``) over the stream's
    truth, aligned as ``bomgraph evaluate --align``; returns the path written.

    Without truth in the stream, the estimate is drawn in its own frame, uncoloured.
    """
    path = _check_out(out, estimate_path, stream_path)
    est_file = read_estimate(estimate_path)
    stream = read_stream(stream_path)
    check_stream_identity(est_file, stream.steps, estimate_path, stream_path)
    est, at = est_file.final, "final"
    if t is not None:
        cps = {c.t: c for c in est_file.checkpoints}
        if t not in cps:
            raise EvaluationError(f"{shown_path(estimate_path)}: no checkpoint at t = {t}; it has "
                                  f"{', '.join(map(str, sorted(cps))) or 'none'}")
        est, at = cps[t].estimate, f"t = {t}"
    which = "the final map" if t is None else f"the map at {at}"
    # an earlier checkpoint of a method that revised its poses: its trajectory read back is
    # each pose as first estimated, not the method's at t (file_evaluation.poses_revised)
    first = (t is not None and t != est_file.checkpoints[-1].t and est_file.version >= 2
             and poses_revised(est_file))
    truth = stream.truth
    label = method_label(est_file) or "estimate"
    if truth is None:
        _refuse_overflow(est, None, None, f"{shown_path(estimate_path)}: {which}", "")
        fig = run_figure(None, est, None, label=label, landmark_cov=est.landmark_cov,
                         title=f"{label}, {at} (no truth: the estimate's own frame)")
        return write_figure(fig, path, dpi)
    if first and align_on != "landmarks":
        raise EvaluationError(f"{shown_path(estimate_path)}: the poses at t = {t} are as "
                              f"first estimated (the method revised them later), so they "
                              f"cannot place the "
                              f"map: use {option_named('--align landmarks', _LANDMARKS)}, or "
                              f"plot the final map")
    try:
        s = score_estimate(est, truth, align_on=align_on)
    except EvaluationError as exc:  # say which file and map, as evaluate does
        raise type(exc)(f"{shown_path(estimate_path)}: {which}: {exc}") from None
    _refuse_overflow(est, s.alignment, truth, f"{shown_path(estimate_path)}: {which}",
                     f"{shown_path(stream_path)}, line 1: 'truth'")
    if truth.poses is not None and t is not None:
        truth = type(truth)(truth.landmark_ids, truth.landmarks_xy, truth.poses[:t + 1])
    pe = None if s.ape is None or first else (s.ape.t, s.ape.translation_m, s.ape.heading_rad)
    cm = (lambda v: "-" if not math.isfinite(v) else f"{100 * v:.2f} cm")
    robot = f", robot APE {cm(s.ape_trans_rmse_m)}" if pe is not None else ""
    if first:
        robot = ", poses as first estimated (revised later): no robot APE"
    title = (f"{label}, {at}: landmark MPE {cm(s.mpe_m)} ({s.n_common} of {s.n_truth})"
             f"{robot}; aligned on {align_on}{', reflected' if s.alignment.reflected else ''}")
    errors = {int(i): float(e) for i, e in zip(s.landmark_ids, s.errors_m)}
    fig = run_figure(truth, est, s.alignment, label=label, errors_m=errors, pose_errors=pe,
                     landmark_cov=est.landmark_cov, title=title)
    return write_figure(fig, path, dpi)


#: the largest coordinate (metres) ``plot`` accepts: a round bound, not a measured limit
#: (matplotlib drew 1e307 and failed at 1e308, where its span arithmetic overflows; h133),
#: far beyond any map's metres.
MAX_DRAWN_M = 1e100


def _refuse_overflow(est: Any, alignment: Any, truth: Any, est_where: str,
                     truth_where: str) -> None:
    """Refuse to draw a map with a point beyond :data:`MAX_DRAWN_M` (the estimate's as
    aligned onto the truth, or the truth's): an estimate with a coordinate near the float
    limit (1e308, a diverged method's) made matplotlib raise "Axis limits cannot be NaN or
    Inf" (a traceback, exit 1; h126)."""
    drawn = [] if truth is None else [(truth_where, [truth.landmarks_xy[:, :2]] + (
        [] if truth.poses is None else [truth.poses[:, :2]]), None)]   # first: it places the map
    drawn.append((est_where, [est.landmarks_xy] + (
        [] if est.poses is None else [est.poses[:, :2]]), alignment))
    for where, xy, moved_by in drawn:
        with np.errstate(over="ignore", invalid="ignore"):
            pts = np.vstack(xy)
            far = float(np.max(np.abs(pts if moved_by is None else moved_by.apply(pts)),
                               initial=0.0))
        if not far <= MAX_DRAWN_M:  # NaN too
            aligned = "" if moved_by is None else ", aligned onto the truth,"
            hint = (" (a diverged estimate? `bomgraph evaluate` scores it)"
                    if where == est_where else "")
            raise EvaluationError(f"{where}: a point{aligned} is {far:g} m from the origin, "
                                  f"beyond the {MAX_DRAWN_M:g} m plot accepts{hint}")


def plot_results(results_dir: str | os.PathLike[str], out: str | os.PathLike[str], *,
                 kind: str = "box", experiments: Sequence[str] = (), dpi: int = 120) -> str:
    """Box or violin plots of the final landmark MPE per arm across runs and the MPE against
    time, one row per experiment of a ``compare`` folder (``experiments``: a subset)."""
    path = _check_out(out)
    src = Path(results_dir) / "results.json"
    try:
        obj = json.loads(read_regular_file(src))
        final, curves, titles = _results_data(obj, src, experiments)
        failed = _failed_runs(obj)
    except OSError as exc:
        raise ConfigError(f"{shown_path(src)}: cannot read ({exc.strerror}); give a `bomgraph "
                          f"compare` "
                          f"output folder") from None
    except BomgraphError:
        raise
    except (ValueError, KeyError, TypeError, AttributeError, IndexError,
            RecursionError) as exc:  # a row of the wrong shape anywhere in the file
        key = f" {str(exc.args[0])[:40]!r}" if isinstance(exc, KeyError) and exc.args else ""
        raise ConfigError(f"{shown_path(src)}: not a compare results file "
                          f"({type(exc).__name__}{key}); "
                          f"give a folder that `bomgraph compare --out DIR` wrote") from None
    return write_figure(results_figure(final, curves, kind=kind, titles=titles,
                                       failed=failed), path, dpi)


def _failed_runs(obj: Any) -> dict[str, dict[str, int]]:
    """Experiment -> arm -> how many of its runs in a parsed ``results.json`` failed (the
    figure labels an arm with no map as FAILED when its runs raised, not "no map")."""
    failed: dict[str, dict[str, int]] = {}
    for r in obj["results"]:
        arms = failed.setdefault(r["experiment"], {})
        arms[r["arm"]] = arms.get(r["arm"], 0) + (not r.get("ok"))
    return failed


def _results_data(obj: Any, src: Path, experiments: Sequence[str]) -> tuple[
        dict[str, dict[str, np.ndarray]], dict[str, dict[str, Any]], dict[str, str]]:
    """The final MPE per experiment and arm, the error curves and the titles of a parsed
    ``results.json`` (malformed rows raise ValueError, KeyError, TypeError, ...)."""
    results, meta = obj["results"], obj.get("experiments", [])
    # a run scored against its own map (marked by compare; a reference's own run of an
    # older compare by its scored_against): its errors left out, as compare's figures do
    results = [scores_left_out({**r, "self_scored": self_scored(r, ())}) for r in results]
    names = list(dict.fromkeys(r["experiment"] for r in results))
    unknown = sorted(set(experiments) - set(names))
    if unknown:
        raise ConfigError(f"{shown_path(src)}: no experiment {unknown[0]!r}; it has "
                          f"{', '.join(names)}")
    chosen = [n for n in names if not experiments or n in experiments]
    final: dict[str, dict[str, np.ndarray]] = {}
    own: dict[str, list[str]] = {}
    for r in results:
        if r["experiment"] not in chosen:
            continue
        if r["self_scored"]:  # no final map of its own to show: left out, said so
            own.setdefault(r["experiment"], []).append(r["arm"])
            continue
        v = math.nan
        if r.get("ok") and r.get("checkpoints"):
            m = r["checkpoints"][-1].get("mpe_m")
            v = math.nan if m is None else float(m)
        arms = final.setdefault(r["experiment"], {})
        arms[r["arm"]] = np.append(arms.get(r["arm"], np.zeros(0)), v)
    curves: dict[str, dict[str, Any]] = {}
    for (exp, arm), c in error_curves([r for r in results if r["experiment"] in chosen]).items():
        curves.setdefault(exp, {})[arm] = c
    titles = {m["name"]: f"{m.get('title', m['name'])} ({m.get('runs', '?')} "
                         f"{plural(m.get('runs'), 'run')})"
              for m in meta if isinstance(m, dict) and "name" in m}
    for exp in own:
        titles[exp] = titles.get(exp, exp) + not_drawn_line(
            [r for r in results if r["experiment"] == exp])
    return final, curves, titles


__all__ = ["FIGURE_SUFFIXES", "plot_run", "plot_results"]
