"""Victoria Park (issue 7, part 3): every method's map of a recording without ground truth.

    python scripts/victoria_map.py [--data FILE] [--out results/victoria] [--methods a,b,...]
                                   [--steps N] [--checkpoint-every 100] [--bearing-sigma RAD]
                                   [--max-seconds S]

Imports GTSAM's ``victoria_park.txt`` (:func:`bomgraph.datasets.victoria.import_victoria`,
bearings only), runs each method (a :class:`bomgraph.experiments.Arm`: a method and a named
preset) through the library (:func:`bomgraph.mapper.create_mapper` and
:func:`bomgraph.mapper.run`), times it, and writes ``victoria_park_maps.png`` (each
method's landmarks and trajectory over the ``gtsam-batch`` map), ``victoria_park.json`` and
``victoria_park.csv``, and each method's final map and trajectory as an estimate file in
``estimates/``.

There is no ground truth, so nothing here is an accuracy. Each map is aligned rigidly
(rotation, translation, reflection allowed, no scale: :func:`bomgraph.evaluate.align` through
:func:`bomgraph.evaluate.score_estimate`, with the ``gtsam-batch`` map in the place of the
truth) onto the ``gtsam-batch`` map on the landmarks both hold, and the table gives the
landmark disagreement after that alignment: AGREEMENT WITH GTSAM-BATCH, NOT ACCURACY.

Checkpoints: ``--checkpoint-every`` (default 100), the same interval for every method. The
final maps do not depend on it: each method admits landmarks, solves and warm-starts on a
schedule of its own (issue 15, item 1); the interval sets how many intermediate maps are made
(and timed).

Bearing sigma: the importer's header value (the file's point covariance propagated to the
bearing, median) unless ``--bearing-sigma`` is given; GTSAM's own example uses 0.2 rad.
What both give is in docs/measurements.md.

A method that raises is reported as a failure with its reason; one that runs longer than
``--max-seconds`` is stopped and reported with the step it reached and its time per step at
the start and at the end (a time per step that grows with the number of steps is why such a
method is unusable on the whole recording).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Mapping, Sequence

import numpy as np

from bomgraph.datasets.victoria import import_victoria
from bomgraph.errors import BomgraphError, DatasetError, TooFewLandmarksError
from bomgraph.evaluate import Alignment, score_estimate
from bomgraph.experiments import Arm
from bomgraph.jsonio import jsonable
from bomgraph.estimate_file import write_estimate
from bomgraph.mapper import MapEstimate, RunResult, create_mapper, run
from bomgraph.report import write_csv
from bomgraph.stream import Step, Stream, Truth
from bomgraph.trajectory import bearing_residuals as trajectory_bearing_residuals

ROOT = Path(__file__).resolve().parents[1]
#: The shared data folder (``BOMGRAPH_DATA`` overrides it, as for scripts/check_identical.py).
DATA = (Path(os.environ.get("BOMGRAPH_DATA", ROOT.parent / "shared" / "data"))
        / "victoria_park" / "victoria_park.txt")
REFERENCE = "gtsam-batch"
FIGURE = "victoria_park_maps.png"


#: The methods tried, in table order (the reference first).
METHODS: dict[str, Arm] = {s.label: s for s in [
    Arm("gtsam-batch", "gtsam-batch"),
    Arm("gtsam-isam2", "gtsam-isam2"),
    Arm("ekf", "ekf"),
    Arm("ekf-real", "ekf", {"preset": "real"}),
    Arm("ekf-invdepth", "ekf-invdepth"),
    Arm("ekf-invdepth-real", "ekf-invdepth", {"preset": "real"}),
    Arm("triangulate", "triangulate"),
    Arm("stmds-smacof", "stmds-smacof"),
    Arm("stmds-smacof-real", "stmds-smacof", {"preset": "real"}),
    Arm("hybrid", "hybrid"),
    Arm("hybrid-real", "hybrid", {"preset": "real-seed"}),
]}


class TimeBudgetExceeded(BomgraphError):
    """A method ran longer than the time budget (raised from the step feed)."""


@dataclass
class Outcome:
    """What one method did: its final map (None if it failed), timings, and why it failed.

    ``step_wall_s[k]`` is the wall time from step ``k`` being handed to the method to step
    ``k + 1`` being asked for (the step and any checkpoint estimate after it). ``cpu_s`` is
    the process's CPU time (user + system) over the run: on a shared machine the wall time
    grows with the load, the CPU time much less.
    """

    spec: Arm
    estimate: MapEstimate | None
    wall_s: float
    steps_done: int
    step_wall_s: np.ndarray
    error: str | None = None
    result: RunResult | None = None
    cpu_s: float = math.nan


def _timed(steps: Sequence[Step], times: list[float], deadline: float | None) -> Iterator[Step]:
    """Yield ``steps``, recording the clock at each hand-over; raise past ``deadline``."""
    clock = time.perf_counter
    for st in steps:
        now = clock()
        times.append(now)
        if deadline is not None and now > deadline:
            raise TimeBudgetExceeded(f"stopped at step {st.t} of {len(steps)}")
        yield st
    times.append(clock())


def run_method(spec: Arm, stream: Stream, *, checkpoint_every: int,
               max_seconds: float | None = None) -> Outcome:
    """Run one method on ``stream``; failures (exceptions, the time budget) become reasons."""
    times: list[float] = []
    t0, c0 = time.perf_counter(), time.process_time()
    deadline = None if max_seconds is None else t0 + max_seconds
    est = res = None
    error = None
    try:
        mapper = create_mapper(spec.method, stream.header, **spec.options)
        res = run(mapper, _timed(stream.steps, times, deadline),
                  checkpoint_every=checkpoint_every, method=spec.label)
        est = res.final
        if not len(est):
            error = f"empty map: {est.info.get('reason', 'no reason given')}"
    except Exception as exc:  # every failure is reported with its reason, never hidden
        error = f"{type(exc).__name__}: {' '.join(str(exc).split())[:300]}"
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    step_wall = np.diff(np.array(times)) if len(times) > 1 else np.zeros(0)
    return Outcome(spec, est, wall, max(len(times) - 1, 0), step_wall, error, res, cpu)


def sightings(stream: Stream) -> dict[int, int]:
    """How many steps saw each landmark."""
    ids = np.concatenate([st.landmark_ids for st in stream.steps] or [np.zeros(0, np.int64)])
    u, c = np.unique(ids, return_counts=True)
    return dict(zip(u.tolist(), c.tolist()))


def bearing_residuals(est: MapEstimate, stream: Stream) -> np.ndarray:
    """:func:`bomgraph.trajectory.bearing_residuals` of ``est``'s own map and trajectory over
    the stream's bearings [rad], shape (m,) (empty without poses): a truth-free check."""
    if est.poses is None:
        return np.zeros(0)
    return trajectory_bearing_residuals(est.landmark_ids, est.landmarks_xy, est.pose_t,
                                        est.poses, stream.steps)


def agreement(est: MapEstimate, reference: MapEstimate) -> dict[str, Any]:
    """Landmark and trajectory disagreement of ``est`` with ``reference`` after the rigid
    alignment (reflection allowed) of ``est``'s landmarks onto the reference's, in metres.

    Raises
    ------
    EvaluationError
        Fewer than 3 landmarks in common.
    """
    ref = Truth(reference.landmark_ids, reference.landmarks_xy, reference.poses)
    sc = score_estimate(est, ref, allow_reflection=True, with_scale=False)
    return {"n_common": sc.n_common, "rms_m": sc.rmse_m, "mean_m": sc.mpe_m,
            "median_m": sc.median_m, "max_m": sc.max_m, "traj_mean_m": sc.robot_mean_m,
            "reflected": sc.alignment.reflected, "alignment": sc.alignment,
            "errors_m": dict(zip(sc.landmark_ids.tolist(), sc.errors_m.tolist()))}


def _scalar_info(info: Mapping[str, Any]) -> dict[str, Any]:
    """The diagnostics that are single finite values (lists, maps and NaN left out)."""
    return {k: v for k, v in jsonable(info).items() if not isinstance(v, (list, dict, type(None)))}


def summarise(outcomes: Sequence[Outcome], stream: Stream
              ) -> tuple[list[dict[str, Any]], dict[str, Alignment]]:
    """One row per method (JSON-ready) and the alignments onto the reference map."""
    n_steps = len(stream.steps)
    ref = next((o.estimate for o in outcomes
                if o.spec.label == REFERENCE and o.error is None), None)
    rows, alignments = [], {}
    for o in outcomes:
        tenth = max(1, len(o.step_wall_s) // 10)
        row: dict[str, Any] = {
            "method": o.spec.label, "registered": o.spec.method, "options": o.spec.options,
            "ok": o.error is None, "error": o.error,
            "landmarks": len(o.estimate) if o.estimate is not None else 0,
            "wall_s": o.wall_s, "cpu_s": o.cpu_s, "steps_done": o.steps_done, "steps": n_steps,
            "ms_per_step_first_10pct": 1e3 * float(np.mean(o.step_wall_s[:tenth]))
            if len(o.step_wall_s) else None,
            "ms_per_step_last_10pct": 1e3 * float(np.mean(o.step_wall_s[-tenth:]))
            if len(o.step_wall_s) else None,
            "info": _scalar_info(dict(o.estimate.info)) if o.estimate is not None else {},
        }
        row["agreement_note"] = None
        res = bearing_residuals(o.estimate, stream) if o.estimate is not None else np.zeros(0)
        row["n_bearings_explained"] = int(res.size)
        row["bearing_rms_rad"] = float(np.sqrt(np.mean(res ** 2))) if res.size else None
        row["bearing_median_abs_rad"] = float(np.median(np.abs(res))) if res.size else None
        if o.estimate is not None and len(o.estimate) and ref is not None:
            try:
                a = agreement(o.estimate, ref)
                alignments[o.spec.label] = a.pop("alignment")
                row.update(a)
            except TooFewLandmarksError:
                common = np.intersect1d(o.estimate.landmark_ids, ref.landmark_ids).size
                row["agreement_note"] = (f"only {common} landmark(s) in common with "
                                         f"{REFERENCE}; alignment needs 3")
        elif ref is None:
            row["agreement_note"] = f"no {REFERENCE} map to compare with"
        rows.append(row)
    return rows, alignments


def victoria_maps(stream: Stream, specs: Iterable[Arm], out_dir: str | Path, *,
                  checkpoint_every: int = 100, max_seconds: float | None = None,
                  title: str = "Victoria Park", dpi: int = 110,
                  progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Run ``specs`` on ``stream``, compare each map with the ``gtsam-batch`` one, and write
    the figure, JSON and CSV into ``out_dir``. Returns ``{"rows", "figure", "json", "csv"}``.

    The reference ``gtsam-batch`` is run first (and added if missing) since every other map is
    aligned to it.
    """
    from bomgraph.plots import map_comparison_figure

    specs = list(specs)
    if REFERENCE not in [s.label for s in specs]:
        specs.insert(0, METHODS[REFERENCE])
    specs.sort(key=lambda s: s.label != REFERENCE)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    outcomes = []
    for s in specs:
        outcomes.append(run_method(s, stream, checkpoint_every=checkpoint_every,
                                   max_seconds=max_seconds))
        if progress is not None:
            o = outcomes[-1]
            progress(f"{s.label}: {o.wall_s:.1f} s ({o.cpu_s:.1f} s CPU), "
                     f"{len(o.estimate) if o.estimate is not None else 0} landmarks"
                     f"{', ' + o.error if o.error else ''}")
    rows, alignments = summarise(outcomes, stream)
    (out / "estimates").mkdir(exist_ok=True)
    for o in outcomes:   # the maps themselves, to be read back with bomgraph.estimate_file.read_estimate
        if o.result is not None:   # the final checkpoint only (all of them: ~20 MB each)
            r = o.result
            write_estimate(RunResult(r.method, r.checkpoints[-1:], r.step_s, r.total_s),
                           out / "estimates" / f"{o.spec.label}.json")
    seen = sightings(stream)

    notes = {}
    for r in rows:
        if not r["ok"]:
            notes[r["method"]] = r["error"]
        elif r["method"] == REFERENCE:
            notes[r["method"]] = f"{r['landmarks']} landmarks (reference), {r['wall_s']:.0f} s"
        elif "rms_m" in r:
            notes[r["method"]] = (f"{r['landmarks']} lm, RMS {r['rms_m']:.2f} m vs batch "
                                  f"({r['n_common']} common), {r['wall_s']:.0f} s")
        else:
            notes[r["method"]] = f"{r['landmarks']} lm, {r['agreement_note']}"[:70]
    ests = {o.spec.label: o.estimate for o in outcomes}
    ref = ests.get(REFERENCE)
    fig = map_comparison_figure(
        ests, reference=ref if ref is not None and len(ref) else None, alignments=alignments,
        notes=notes, title=f"{title}, {len(stream.steps)} steps: maps aligned onto "
                           f"{REFERENCE} (triangles); no ground truth, agreement is not accuracy")
    fig_path = out / FIGURE
    fig.savefig(fig_path, dpi=dpi)

    meta = {"data": stream.header.meta.get("files", {}), "steps": len(stream.steps),
            "bearing_sigma_rad": stream.header.bearing_sigma_rad,
            "odometry_sigma": list(stream.header.odometry_sigma),
            "checkpoint_every": checkpoint_every, "max_seconds": max_seconds,
            "landmarks_seen": len(seen),
            "landmarks_seen_3_or_more": int(sum(c >= 3 for c in seen.values())),
            "reference": REFERENCE,
            "note": "agreement with gtsam-batch after rigid alignment (reflection allowed), "
                    "not accuracy: the recording has no ground truth"}
    json_path = out / "victoria_park.json"
    with open(json_path, "w", encoding="utf-8") as fh:
        json.dump({"meta": meta, "rows": jsonable(rows)}, fh, indent=1, allow_nan=False)
        fh.write("\n")
    csv_path = out / "victoria_park.csv"
    cols = ["method", "ok", "landmarks", "n_common", "rms_m", "mean_m", "median_m", "max_m",
            "traj_mean_m", "reflected", "bearing_rms_rad", "bearing_median_abs_rad",
            "n_bearings_explained", "wall_s", "cpu_s", "steps_done", "ms_per_step_first_10pct",
            "ms_per_step_last_10pct", "error", "agreement_note"]
    write_csv(csv_path, [{c: r.get(c) for c in cols} for r in rows], cols)
    return {"rows": rows, "meta": meta, "figure": fig_path, "json": json_path,
            "csv": csv_path}


def format_table(rows: Sequence[dict[str, Any]]) -> str:
    """The printed table."""
    def f(v: Any, fmt: str) -> str:
        return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else \
            format(v, fmt)

    lines = ["AGREEMENT WITH GTSAM-BATCH, NOT ACCURACY (no ground truth; rigid alignment, "
             "reflection allowed); brg rms: RMS bearing residual [rad] of the method's own "
             "map and trajectory over the bearings they cover",
             f"{'method':<18} {'lm':>4} {'common':>6} {'RMS m':>7} {'mean m':>7} {'max m':>7} "
             f"{'traj m':>7} {'brg rms':>7} {'wall s':>8} {'cpu s':>8} {'ms/step first/last 10%':>23}  "
             f"failure / note"]
    for r in rows:
        ms = (f"{f(r['ms_per_step_first_10pct'], '.2f')}/"
              f"{f(r['ms_per_step_last_10pct'], '.2f')}")
        note = r["error"] or r.get("agreement_note") or ("reference" if r["method"] == REFERENCE
                                                          else "")
        if r.get("reflected"):
            note = (note + "; " if note else "") + "aligned with a reflection"
        lines.append(f"{r['method']:<18} {r['landmarks']:>4} {r.get('n_common', '-')!s:>6} "
                     f"{f(r.get('rms_m'), '.3f'):>7} {f(r.get('mean_m'), '.3f'):>7} "
                     f"{f(r.get('max_m'), '.3f'):>7} {f(r.get('traj_mean_m'), '.3f'):>7} "
                     f"{f(r.get('bearing_rms_rad'), '.4f'):>7} "
                     f"{r['wall_s']:>8.1f} {f(r.get('cpu_s'), '.1f'):>8} {ms:>23}  {note}")
    return "\n".join(lines)


def _data_error(path: str, exc: Exception) -> int:
    """One line on stderr for input that cannot be read (no traceback), and exit status 2."""
    hint = ("" if Path(path).exists() else "; the default is $BOMGRAPH_DATA/victoria_park/"
            "victoria_park.txt: set BOMGRAPH_DATA to the shared data folder, or pass --data FILE")
    print(f"{Path(__file__).name}: error: {exc}{hint}", file=sys.stderr)
    return 2


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=str(DATA), help="victoria_park.txt (GTSAM's format)")
    ap.add_argument("--out", default="results/victoria", help="output folder")
    ap.add_argument("--methods", default=",".join(METHODS),
                    help=f"comma-separated, from: {', '.join(METHODS)}")
    ap.add_argument("--steps", type=int, default=None, help="only the first N steps")
    ap.add_argument("--checkpoint-every", type=int, default=100,
                    help="estimate every N steps (module docstring: why not only at the end)")
    ap.add_argument("--bearing-sigma", type=float, default=None,
                    help="bearing sigma [rad] (default: the importer's header value)")
    ap.add_argument("--max-seconds", type=float, default=None,
                    help="stop a method after this wall time and report it as too slow")
    ap.add_argument("--docs", action="store_true",
                    help=f"also copy the figure to docs/{FIGURE}")
    a = ap.parse_args(argv)
    unknown = [m for m in a.methods.split(",") if m not in METHODS]
    if unknown:
        ap.error(f"unknown method(s) {unknown}; choose from {', '.join(METHODS)}")
    try:
        stream = import_victoria(a.data, bearing_sigma_rad=a.bearing_sigma)
    except DatasetError as exc:
        return _data_error(a.data, exc)
    if a.steps is not None:
        if a.steps < 2:
            ap.error("--steps must be >= 2")
        stream = Stream(stream.header, stream.steps[:a.steps], None)
    res = victoria_maps(stream, [METHODS[m] for m in a.methods.split(",")], a.out,
                        checkpoint_every=a.checkpoint_every, max_seconds=a.max_seconds,
                        progress=lambda msg: print(msg, file=sys.stderr, flush=True))
    m = res["meta"]
    print(f"Victoria Park: {m['steps']} steps, {m['landmarks_seen']} landmarks seen "
          f"({m['landmarks_seen_3_or_more']} at least 3 times), bearing sigma "
          f"{m['bearing_sigma_rad']:.4f} rad, checkpoints every {m['checkpoint_every']} steps")
    print(format_table(res["rows"]))
    for r in res["rows"]:
        info = r["info"]
        if "converged" in info:
            print(f"{r['method']}: converged={info['converged']} cost={info.get('cost')} "
                  f"stop={info.get('stop', '-')}"
                  + (f" seed: {info['seed']}" if "seed" in info else ""))
    print(f"wrote {res['figure']}, {res['json']}, {res['csv']}")
    if a.docs:
        shutil.copyfile(res["figure"], ROOT / "docs" / FIGURE)
        print(f"copied the figure to {ROOT / 'docs' / FIGURE}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
