"""Reports of the comparison (paper section IV): the text tables of the runner's results,
CSV/JSON files, the figures, and :func:`compare`, which runs experiments and writes all of
it. The rows the tables and files hold are :mod:`bomgraph.summaries`' (imported from here
too).

Data flows one way: :mod:`bomgraph.experiments` (what to run) -> :mod:`bomgraph.bench` (run
and score) -> :mod:`bomgraph.summaries` (rows) -> here (format, write) ->
:mod:`bomgraph.plots` (draw arrays).
A result is the dict of :func:`bomgraph.bench.run_task`; its ``checkpoints`` are the rows of
:func:`bomgraph.evaluate.score_checkpoints` as dicts.
"""

from __future__ import annotations

import json
import logging
import math
import os
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from .bench import (Executor, adds_to_cache, execute_counted, refuse_runtime_methods,
                    run_example, which_cached)
from .checks import instance, option_named, out_named
from .errors import ConfigError, StreamFormatError
from .method_code import new_sweep
from .evaluate import score_estimate
from .experiments import Experiment, FileSource, Task
from .jsonio import jsonable
from .paired import (PairedConfig, PairedRow, pairable, paired_comparison,
                     references_for, scored_references)
from .run_scoring import mark_self_scored, not_drawn_line
from .plots import MapPanel, error_vs_time_figure, final_maps_figure, map_figure
from .out_folder import (RESULT_FILES, OutputRecord, compare_locks, estimate_paths,
                         planned_outputs, refuse_inputs_among_outputs)
from .slugs import figure_names
from .stdio import OutputPathError, check_folder, write_figure, write_text
from .summaries import (REPORT_TIMES, error_curves, final_by_run, group_rows,
                        results_to_csv_rows, summarise)
from .tables import HUGE, counted, write_csv
from .worker_log import said_once

_log = logging.getLogger(__name__)


def _cm(v: float | None, fmt: str = "6.2f") -> str:
    """``v`` [m] in cm for the printed tables; from 1e9 cm in exponent form (a diverged map
    8.7e8 m away printed as 87000000000.00)."""
    if v is None or not math.isfinite(v):
        return "   -  "
    return f"{100 * v:{'6.1e' if abs(100 * v) >= HUGE else fmt}}"


def _mpe_cells(r: dict, times: Sequence[int]) -> list[str]:
    """A summary row's ``mean/median±std`` MPE cells [cm], one per checkpoint time."""
    cells = []
    for t in times:
        m, md, sd = (r.get(f"mpe_mean_m@{t}"), r.get(f"mpe_median_m@{t}"),
                     r.get(f"mpe_std_m@{t}"))
        cell = f"{_cm(m).strip()}/{_cm(md).strip()}±{_cm(sd).strip()}"
        scored, ran = r.get(f"n_scored@{t}", 0), r["runs"] - r["failed"]
        if scored < ran:  # runs without a map yet are not averaged in: say so
            cell += f"[{scored}/{ran}]"
        cells.append(cell)
    return cells


def format_summary(summary: Sequence[dict]) -> str:
    """The comparison table as text: one block per experiment, one row per arm."""
    lines = []
    for (exp,), rows in group_rows(summary, "experiment").items():
        times = sorted({int(k.split("@")[1]) for r in rows for k in r
                        if k.startswith("mpe_mean_m@")})
        if all(r.get("scored_against") == "none" for r in rows if r["runs"] > r["failed"]):
            times = []  # no truth, no reference: no MPE to show
        lines.append(f"\n== {exp} ==  landmark MPE [cm] mean/median±std at t; robot: error "
                     f"[cm] of the latest pose at the end; conv: converged runs; NEES: robot "
                     f"pose, after the alignment on the landmarks; wall time per run; [k/n]: "
                     f"only k of n runs had a map (robot, conv, NEES: a value)")
        by_row = [_mpe_cells(r, times) for r in rows]
        w = max([17] + [len(c) for cells in by_row for c in cells])  # wide means widen it
        aw = max([30] + [len(r["arm"]) for r in rows])  # never cut two labels into one
        head = f"{'arm':{aw}s} {'runs':>4s} " + " ".join(f"{'t=' + str(t):>{w}s}" for t in times)
        head += f" {'robot':>7s} {'conv':>5s} {'NEES':>6s} {'wall s':>7s}  paper"
        free = any("bearing_rms_mean_rad" in r for r in rows)
        if free:  # streams without truth: landmarks mapped, bearing RMS [mrad], reference
            lines[-1] += ("; mapped: landmarks at the end; brg: RMS bearing residual [mrad] "
                          "of the map and trajectory against the stream (no truth needed)")
            if any(_own(r) or "no score" in str(r.get("scored_against")) for r in rows):
                lines[-1] += "; [0/n], no score: runs scored against their own map"
            head = head.replace("  paper", f" {'mapped':>6s} {'brg':>6s}  scored against")
        lines.append(head)
        for r, cells in zip(rows, by_row):
            conv = r.get("converged_rate")
            conv_s = "  -  " if conv is None or not math.isfinite(conv) else f"{100 * conv:4.0f}%"
            nees = r.get("nees_pose_mean")
            nees_s = "   -  " if nees is None or not math.isfinite(nees) else f"{nees:6.2f}"
            robot_s = _cm(r.get("robot_last_mean_m"))
            wall = r.get("wall_s_mean")  # NaN: no run of the arm ran to the end
            wall_s = "   -   " if wall is None or not math.isfinite(wall) else f"{wall:7.3f}"
            ran = r["runs"] - r["failed"]
            robot_s, conv_s, nees_s = (  # averaged over fewer runs than ran: say so
                v + (f"[{r[k]}/{ran}]" if 0 < r.get(k, ran) < ran else "")
                for v, k in ((robot_s, "n_robot"), (conv_s, "n_converged_known"),
                             (nees_s, "n_nees_pose")))
            fail = f"  FAILED {r['failed']}: {'; '.join(r['errors'])[:120]}" if r["failed"] else ""
            lines.append(f"{r['arm']:{aw}s} {r['runs']:4d} "
                         + " ".join(f"{c:>{w}s}" for c in cells)
                         + f" {robot_s:>7s} {conv_s:>5s} {nees_s:>6s}"
                         f" {wall_s:>7s}"
                         + (_free_cells(r) if free else f"  {r.get('paper', '')}") + fail)
        lines += _nees_landmark_note(rows)
    return "\n".join(lines)


def _nees_landmark_note(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """A note line when the landmark NEES of ``summary.csv`` (not in the table) leaves values
    out: runs without one (no covariances, a singular one) beside runs with one, and runs
    whose final map has landmarks without a covariance (``info["covariances"]`` is
    ``"partial"``: their NEES is the mean over the others)."""
    parts = []
    for r in rows:
        ran, n = r["runs"] - r["failed"], r.get("n_nees_landmark", 0)
        partial = r.get("n_nees_landmark_partial", 0)
        what = ([f"{ran - n} of {counted(ran, 'run')} without one"] if 0 < n < ran else []) + (
            [f"{counted(partial, 'run')} leaving out landmarks without a covariance "
             f"(info covariances_undefined)"] if partial else [])
        if what:
            parts.append(f"{r['arm']}: {', '.join(what)}")
    if not parts:
        return []
    return [f"note: the landmark NEES (summary.csv nees_landmark_mean) is the mean over the "
            f"values there are; left out: {'; '.join(parts)}"]


def _free_cells(r: Mapping[str, Any]) -> str:
    """The truth-free cells of a summary row: landmarks mapped, bearing RMS [mrad], the
    reference."""
    brg = r.get("bearing_rms_mean_rad", math.nan)
    mapped = r.get("n_mapped_mean", math.nan)
    return (f" {'-' if not math.isfinite(mapped) else f'{mapped:.1f}':>6s}"
            f" {'-' if not math.isfinite(brg) else f'{1000 * brg:.2f}':>6s}"
            f"  {r.get('scored_against', 'truth' if r['runs'] > r['failed'] else '-')}")


def format_by_run(rows: Sequence[dict]) -> str:
    """Final landmark MPE [cm] (landmarks mapped) per arm and run, one block per experiment."""
    lines = []
    for (exp,), rs in group_rows(rows, "experiment").items():
        runs = list(dict.fromkeys(r["run"] for r in rs))
        arms = list(dict.fromkeys(r["arm"] for r in rs))
        cell = {(r["arm"], r["run"]): r for r in rs}
        lines.append(f"\n== {exp}, final map per run ==  landmark MPE [cm] (landmarks mapped); "
                     f"'no map': fewer than 3 landmarks; 'unscored': a map, but nothing to "
                     f"score it by (fewer than 3 landmarks in common with the truth or "
                     f"reference; without either, no poses); FAILED: the run raised; mrad: no "
                     f"truth or reference, RMS bearing residual; reference: the --reference's "
                     f"own run, the map the others are scored against" + (
                         ", or a run of its method and options (another checkpoint cadence): "
                         "no score" if any(r.get("self_scored") == "method" for r in rs) else ""))
        aw = max([30] + [len(a) for a in arms])  # names in full: never two alike
        rw = max([14] + [len(r) for r in runs])
        lines.append(f"{'arm':{aw}s} " + " ".join(f"{r:>{rw}s}" for r in runs))
        for arm in arms:
            cells = []
            for run_name in runs:
                r = cell.get((arm, run_name))
                if r is None:
                    cells.append("")
                elif not r["ok"]:
                    cells.append("FAILED")
                elif _own(r) and r["n_mapped"] >= 3:  # its MPE: 0 by definition
                    cells.append(f"reference ({r['n_mapped']})")
                elif _own(r):
                    cells.append(f"no map ({r['n_mapped']})")  # no map to score by (h68)
                elif not math.isfinite(r["mpe_m"]) and math.isfinite(r["bearing_rms_rad"]):
                    cells.append(f"{1000 * r['bearing_rms_rad']:.1f}mrad ({r['n_mapped']})")
                elif not math.isfinite(r["mpe_m"]) and r["n_mapped"] >= 3:
                    cells.append(f"unscored ({r['n_mapped']})")
                elif not math.isfinite(r["mpe_m"]):
                    cells.append(f"no map ({r['n_mapped']})")
                else:
                    cells.append(f"{_cm(r['mpe_m'], '.1f')} ({r['n_mapped']})")
            lines.append(f"{arm:{aw}s} " + " ".join(f"{c:>{rw}s}" for c in cells))
    return "\n".join(lines)


def _own(row: Mapping[str, Any]) -> bool:
    return bool(row.get("self_scored")) or str(row.get("scored_against")).startswith("itself")


@dataclass(frozen=True)
class CompareResult:
    """What :func:`compare` produced: raw results, the summary table, the files written,
    the paired comparison of each arm with its experiment's reference arm, and how many of
    the results were read from the cache (not run)."""

    results: tuple[dict[str, Any], ...]
    summary: tuple[dict[str, Any], ...]
    files: tuple[str, ...]
    wall_s: float
    paired: tuple[PairedRow, ...] = ()
    n_cached: int = 0


def compare(experiments: Sequence[Experiment], out_dir: str | os.PathLike[str], *,
            executor: Executor = Executor(), use_cache: bool = True, figures: bool = True,
            progress: Callable[[int, int], None] | None = None,
            estimates: bool = False, paired_reference: str | None = None,
            paired: PairedConfig = PairedConfig()) -> CompareResult:
    """Run ``experiments``, write ``results.json``, ``results.csv``, ``summary.csv``,
    ``final_by_run.csv``, ``paired.csv`` and the figures (PNG) into ``out_dir``, and return
    the summary. With ``estimates``, also each run's final estimate file and its stream
    (:func:`write_estimate_files`). ``paired.csv`` compares each arm with its experiment's
    reference arm run by run (:func:`bomgraph.paired.paired_comparison`): the arm labelled
    ``paired_reference`` where there is one, else :func:`bomgraph.paired.default_reference`.

    Finished runs are cached in ``out_dir/cache`` so an interrupted sweep resumes. A file
    compare would replace that its manifest does not list as an earlier compare's, unchanged
    since, is refused before anything runs and again before anything is written
    (:meth:`OutputRecord.refuse_foreign`).
    """
    out = Path(out_dir)
    refs = references_for(experiments, paired_reference)  # a wrong label: before anything runs
    record, planned = _refuse_before_running(out_dir, experiments, use_cache, estimates, figures,
                                             executor)
    if executor.backend != "serial":  # as execute() would, before OUT and its lock are made
        refuse_runtime_methods([t for e in experiments for t in e.tasks()], executor.backend)
    out.mkdir(parents=True, exist_ok=True)   # check_folder above
    with compare_locks(out, planned), said_once():  # out, its linked and written folders
        record.remove_leftovers(planned)  # of compares killed while writing: none writes now
        return _compare(experiments, out, executor, use_cache, figures, progress, estimates,
                        refs, paired, paired_reference, (record, planned))


def plan_compare(experiments: Sequence[Experiment], out_dir: str | os.PathLike[str], *,
                 use_cache: bool = True, estimates: bool = False,
                 executor: Executor = Executor(), figures: bool = True) -> list[dict[str, Any]]:
    """What :func:`compare` with ``executor`` (its default too) would run, without running or
    writing anything: one row per task (``experiment``, ``arm``, ``run``, ``cached``: its
    result is in ``out_dir/cache``, so it would not run again), in the order compare runs
    them. What compare refuses about its folder is refused too."""
    instance(executor, Executor, "plan_compare(): executor", ConfigError)  # as compare's
    _refuse_before_running(out_dir, experiments, use_cache, estimates, figures, executor)
    new_sweep()  # as execute() does: a plugin module reloaded, a value set since
    cache = Path(out_dir) / "cache"
    tasks = _tasks(experiments, estimates)
    if executor.backend != "serial":  # as execute() refuses them
        refuse_runtime_methods(tasks, executor.backend)
    cached = (which_cached(tasks, cache, executor) if use_cache and cache.is_dir()
              else [False] * len(tasks))
    return [{"experiment": t.experiment, "arm": t.arm.label, "run": t.source.name,
             "cached": c} for t, c in zip(tasks, cached)]


def _tasks(experiments: Sequence[Experiment], estimates: bool) -> list[Task]:
    """The tasks compare runs, in its order, each keeping its estimate with ``estimates``."""
    return [replace(t, keep_estimate=estimates) for e in experiments for t in e.tasks()]


def _refuse_before_running(out_dir: str | os.PathLike[str], experiments: Sequence[Experiment],
                           use_cache: bool, estimates: bool, figures: bool, executor: Executor
                           ) -> tuple[OutputRecord, list[Path]]:
    """What :func:`compare` and :func:`plan_compare` refuse about ``out`` before anything
    runs: the folder (``check_folder`` first: Path('') is '.'), inputs among the outputs,
    files not compare's, and a folder it writes into (the cache, ``estimates/``, a figure's)
    that cannot be written, or where it would be made (h119: ``chattr +i OUT/cache`` ran
    every task, then stopped on the first cache file); a cache compare adds no run to (each
    cached or never cached, :func:`~bomgraph.bench.adds_to_cache`) is only read. Returns the
    record and the files."""
    check_folder(out_dir)
    refuse_inputs_among_outputs(out := Path(out_dir), experiments)
    planned = planned_outputs(out, experiments, estimates=estimates, figures=figures)
    cache = [out / "cache"] if use_cache else []
    (record := OutputRecord(out)).refuse_foreign(planned, cache)
    for folder in dict.fromkeys([*cache, *(p.parent for p in planned)]):
        at = folder
        while at != out and not at.is_dir() and not os.path.lexists(at):
            at = at.parent   # made there
        if not at.is_dir() or os.access(at, os.W_OK | os.X_OK):
            continue  # writable: no key computed here (a plugin's package hashed once a sweep)
        if (at in cache and os.access(at, os.R_OK | os.X_OK)  # listed, then read
                and not adds_to_cache(_tasks(experiments, estimates), at, executor)):
            continue  # only read
        no_cache = option_named("--no-cache", "use_cache=False")
        other = f", or run without the cache ({no_cache})" if at in cache else ""
        raise OutputPathError(f"{out_named('out_dir', out)}: the folder {at} is not "
                              f"writable; make it writable or choose another folder{other}")
    return record, planned


def _compare(experiments: Sequence[Experiment], out: Path, executor: Executor,
             use_cache: bool, figures: bool,
             progress: Callable[[int, int], None] | None, estimates: bool,
             references: Mapping[str, str], paired_config: PairedConfig,
             label: str | None,
             planned: tuple[OutputRecord, list[Path]]) -> CompareResult:
    start = time.perf_counter()
    tasks = _tasks(experiments, estimates)
    results, n_cached = execute_counted(tasks, executor, progress=progress,
                                        cache_dir=out / "cache" if use_cache else None)
    record, paths = planned
    record.refuse_foreign(paths)  # a file put there while the runs ran (they are cached)
    record.begin(paths)  # named first: killed writing one, the next removes its leftover
    results = mark_self_scored(results, experiments)  # scored against their own map
    written = write_estimate_files(out, tasks, results, record.ready) if estimates else []
    summary = summarise(results)
    by_run = final_by_run(results)
    rows = pairable(by_run, experiments)  # no pair with a run scored against its own map
    paired = paired_comparison(rows, scored_references(experiments, references, rows, label),
                               paired_config)
    wall = time.perf_counter() - start
    files = [out / n for n in RESULT_FILES] + written
    # compact: without ``indent`` json.dumps takes CPython's C encoder (the main job's file:
    # 0.5 s against 1.6 s indented, docs/measurements.md, "The main job against ...").
    # Strict JSON: a value that is not a number (a run without a map, a robot error of a
    # stream without robot truth) is null, not the bare NaN that jq, JavaScript and R's
    # jsonlite refuse to read.
    write_text(files[0], json.dumps(jsonable(
        {"experiments": [{"name": e.name, "title": e.title,
                          "arms": [a.key() for a in e.arms], **_design(e),
                          "runs": e.n_runs()} for e in experiments],
         "summary": summary,
         "paired": {"n_bootstrap": paired_config.n_bootstrap,
                    "confidence": paired_config.confidence, "seed": paired_config.seed,
                    "rows": [p.as_dict() for p in paired]},
         "results": results, "wall_s": wall}), allow_nan=False), ready=record.ready(files[0]))
    for path, rows, cols in ((files[1], results_to_csv_rows(results), None),
                             (files[2], summary, None), (files[3], by_run, None),
                             (files[4], [p.as_dict() for p in paired],
                              list(PairedRow.__dataclass_fields__))):
        write_csv(path, rows, cols, ready=record.ready(path))  # listed before it is in place
    if figures:
        files += write_compare_figures(out, experiments, results, record.ready)
    record.finish(files, experiments)
    return CompareResult(tuple(results), tuple(summary), tuple(str(f) for f in files), wall,
                         tuple(paired), n_cached)


def _design(e: Experiment) -> dict[str, Any]:
    """``seed`` and ``n_steps`` of an experiment's simulated design for results.json: the
    paper design's; a simulated world's steps when every world has the same; else null (an
    experiment on stream files has no seed, and its streams have their own lengths)."""
    if e.designed:
        return {"seed": e.seed, "n_steps": e.sim.n_steps}
    steps = {w.sim.n_steps for w in e.worlds}
    return {"seed": None,
            "n_steps": steps.pop() if len(steps) == 1 and not e.sources else None}


def write_estimate_files(out: Path, tasks: Sequence[Task], results: Sequence[dict[str, Any]],
                         ready: Callable[[Path], Callable[[str], None] | None] = lambda p: None
                         ) -> list[Path]:
    """Write each run's final estimate (a result's ``estimate_file`` text, taken out of the
    result) and, unless the run read a stream file the user has, its stream (made again here,
    the same bytes the worker ran on) where :func:`bomgraph.out_folder.estimate_paths` says,
    so that ``bomgraph evaluate EST STREAM`` pairs them; ``out/estimates/index.csv`` lists
    each run's estimate and stream (paths relative to ``out``, a user's stream file as given).
    Each file is written with ``ready(path)`` as its ``ready``. Returns the paths; a failed
    run has no estimate and gets none."""
    from .stream_file import write_stream

    paths: list[Path] = []
    index: list[dict[str, Any]] = []
    inputs = sorted({t.source.path for t in tasks if isinstance(t.source, FileSource)})
    streams: set[Path] = set()
    for t, r, (path, spath) in zip(tasks, results, estimate_paths(out, tasks)):
        text = r.pop("estimate_file", None)
        if text is None:
            continue
        path.parent.mkdir(parents=True, exist_ok=True)
        write_text(path, text, ready=ready(path))
        paths.append(path)
        row = {"experiment": t.experiment, "arm": t.arm.label, "run": t.source.name,
               "estimate": str(path.relative_to(out))}
        index.append(row)
        row["stream"] = t.source.path if spath is None else str(spath.relative_to(out))
        if spath is not None and spath not in streams:
            streams.add(spath)
            spath.parent.mkdir(parents=True, exist_ok=True)
            write_stream(t.stream(), spath, inputs=inputs, ready=ready(spath))
            paths.append(spath)
    if index:
        paths.append(out / "estimates" / "index.csv")
        write_csv(paths[-1], index, ready=ready(paths[-1]))
    return paths


def write_compare_figures(out_dir: str | os.PathLike[str], experiments: Sequence[Experiment],
                          results: Sequence[Mapping[str, Any]],
                          ready: Callable[[Path], Callable[[str], None] | None] = lambda p: None
                          ) -> list[Path]:
    """The comparison's figures as PNG files in ``out_dir``; returns their paths.

    One error-against-time figure per experiment (landmark MPE; robot error too for Exp. 2,
    the paper's figs. 4, 6, 7, 8), one figure of every method's final map per recording, and
    an example map with trajectory of the first simulated experiment (figs. 3 and 5:
    ``stmds-smacof-loc`` at t = 100, run again by :func:`bomgraph.bench.run_example`).
    Each file is written with ``ready(path)`` as its ``ready``.
    """
    out = Path(out_dir)
    files = []
    names = figure_names(experiments)  # unique (h103: runs 'a b' and 'a_b' drew one file)
    mpe = error_curves(results, "mpe_m")
    robot = error_curves(results, "robot_last_m")
    for exp in experiments:
        curves = {arm: c for (e, arm), c in mpe.items() if e == exp.name}
        if not curves:
            continue
        rob = {arm: c for (e, arm), c in robot.items()
               if e == exp.name and np.any(np.isfinite(c[1]))}
        own = not_drawn_line([r for r in results if r["experiment"] == exp.name])
        fig = error_vs_time_figure(curves, robot_curves=rob, title=f"{exp.title}: landmarks "
                                   f"({counted(exp.n_runs(), 'run')})" + own)  # self-scored: NaN
        path = out / names[exp.name]
        write_figure(fig, path, dpi=120, ready=ready(path))
        files.append(path)
    for exp in experiments:
        if exp.sources:
            files += _write_source_maps(out, exp, results, ready, names)
    sim_exps = [e for e in experiments if e.designed]
    if not sim_exps:
        return files
    # Example map (fig. 5: Method 2 with localisation at t = 100; fig. 3: the truth)
    exp = sim_exps[0]
    try:
        t_show = 100 if exp.sim.n_steps >= 100 else None
        stream, est = run_example("stmds-smacof-loc", exp, t=t_show)
        al = score_estimate(est, stream.truth).alignment
        traj = np.arange(0, (t_show or exp.sim.n_steps) + 1)
        fig = map_figure(stream.truth, est, al, trajectory_t=traj,
                         title=f"stmds-smacof-loc, run {exp.runs()[0].name}, "
                               f"t = {t_show or exp.sim.n_steps}")
        path = out / "example_map.png"
        write_figure(fig, path, dpi=120, ready=ready(path))
        files.append(path)
    except Exception as exc:  # the map figure is optional; say why it is missing
        files.append(out / "example_map.txt")
        write_text(files[-1], f"example map not drawn: {type(exc).__name__}: {exc}\n",
                   ready=ready(files[-1]))
    return files


def _write_source_maps(out: Path, exp: Experiment, results: Sequence[Mapping[str, Any]],
                       ready: Callable[[Path], Callable[[str], None] | None],
                       names: Mapping[Any, str]) -> list[Path]:
    """One figure per recorded source: every method's final map (aligned) over the truth."""
    files = []
    for src in exp.sources:
        rs = [r for r in results if r["experiment"] == exp.name and r["run"] == src.name]
        if not rs:
            continue
        try:
            truth = src.stream().truth
        except (StreamFormatError, OSError) as exc:  # removed or rewritten since its runs
            unread = all(str(r.get("error", "")).startswith(("StreamFormatError: ",
                                                             "DatasetError: ")) for r in rs)
            # runs that could not read it already say why (the CLI's one error line)
            _log.log(logging.DEBUG if unread else logging.WARNING, "no map figure for %s: %s",
                     src.name, exc)
            continue
        if truth is None:
            continue
        fig = final_maps_figure(truth, [_map_panel(r) for r in rs],
                                title=f"{exp.title}: {src.name}")
        path = out / names[(exp.name, src.name)]
        write_figure(fig, path, dpi=100, ready=ready(path))
        files.append(path)
    return files


def _map_panel(r: Mapping[str, Any]) -> MapPanel:
    """A task result's final map (``run_task``'s ``final_map``) as a figure panel."""
    fm = r.get("final_map")
    if not r.get("ok") or not fm:
        return MapPanel(r["arm"], None, failure=r.get("error", "no map (fewer than 3 landmarks)"))
    mpe = r["checkpoints"][-1].get("mpe_m")
    return MapPanel(r["arm"], np.array(fm["landmarks"], dtype=float).reshape(-1, 3),
                    np.array(fm["poses"], dtype=float).reshape(-1, 3),
                    mpe_m=math.nan if mpe is None else float(mpe))


__all__ = ["REPORT_TIMES", "summarise", "final_by_run", "error_curves", "results_to_csv_rows",
           "format_summary", "format_by_run", "write_csv", "CompareResult", "compare",
           "plan_compare", "write_compare_figures", "write_estimate_files"]
