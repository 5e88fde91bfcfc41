"""Each method's sensitivity to a mis-stated bearing sigma on simulated streams, where the
noise is known to be Gaussian with the simulated sigma (issue 15, item 3).

``bench_generality.py`` measures the same thing on MRCLAM6 (the header's bearing sigma halved
or doubled): there even the oracle moves by 1.5-1.6x, and the recordings' errors are neither
Gaussian nor independent, so the cause cannot be told apart from the data. Here the streams are
simulated, so the stated sigma is exactly right at scale 1, and each stream is run three times
with only its header's ``bearing_sigma_rad`` multiplied by 0.5, 1 and 2 (the bearings, the
odometry and its sigmas the same). Two worlds:

* ``paper``: the paper's design (seed 0; 2.5 m, 50 landmarks, 1 m range, 3 deg bearings),
  its first ``--runs`` runs;
* ``sparse``: a recording-like world (5 m, 15 landmarks, 3 m range, a 60 deg field of view,
  1 deg bearings, steps of 0.15-0.3 m and turns up to 0.3 rad, 500 steps; about 2 bearings a
  step, as the MRCLAM imports), seeds 0, 1, ... (``--runs`` of them).

Every method runs its ``real`` preset (the recording setting issue 15 asks for), and the
paper world also each method's defaults (``paper``). Final map only is scored (landmark MPE
after the paper's rigid alignment), the map asked for every 10 steps.

Usage::

    python scripts/bench_sigma_sim.py [--runs 5] [--worlds paper,sparse] [--jobs 2]
        [--methods stmds-smacof,ekf,...] [--option KEY=VALUE ...] [--out /tmp/bench_sigma_sim.json]

``--option KEY=VALUE`` (repeatable; the value read as JSON, else as a string) is passed to
every method's ``create_mapper`` on top of its preset, e.g. ``--option
bearing_variance_scale=innovation --methods ekf,ekf-invdepth,oracle`` (the oracle then runs
without it: it takes no such option).

Prints, per world, preset and method, the mean MPE at each scale, the ratio of the means
(x0.5 / x1, x2 / x1) and the largest per-run ratio either way (issue 15's measure:
``max(a / b, b / a)``); the JSON has every run.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any, Sequence  # noqa: E402

import numpy as np  # noqa: E402

from bomgraph.errors import BomgraphError  # noqa: E402
from bomgraph.evaluate import score_estimate  # noqa: E402
from bomgraph.mapper import create_mapper, run  # noqa: E402
from bomgraph.sim import SimConfig, paper_design, simulate, simulate_run  # noqa: E402
from bomgraph.stream import Stream  # noqa: E402

METHODS = ("stmds-smacof", "ekf", "ekf-invdepth", "gtsam-batch", "gtsam-isam2", "hybrid",
           "oracle")
SCALES = (0.5, 1.0, 2.0)
SPARSE = SimConfig(arena_m=5.0, n_landmarks=15, sensor_range_m=3.0, fov_rad=math.radians(60),
                   sigma_theta_rad=math.radians(1.0), step_min_m=0.15, step_max_m=0.3,
                   turn_max_rad=0.3, n_steps=500)


def world_stream(world: str, k: int, steps: int | None = None) -> Stream:
    """Run ``k`` of ``world`` (the same stream whatever the process), ``steps`` long if given
    (else the world's own length)."""
    if world == "paper":
        cfg = SimConfig() if steps is None else SimConfig(n_steps=steps)
        return simulate_run(paper_design(0)[k], cfg)
    if world == "sparse":
        cfg = SPARSE if steps is None else dataclasses.replace(SPARSE, n_steps=steps)
        return simulate(cfg, np.random.default_rng(1000 + k), meta={"world": "sparse",
                                                                    "seed": 1000 + k})
    raise ValueError(f"unknown world {world!r} (paper, sparse)")


def one(world: str, k: int, method: str, preset: str, scale: float,
        steps: int | None = None, options: dict[str, Any] | None = None) -> dict[str, Any]:
    """One run: ``method`` with ``preset`` on run ``k`` of ``world``, the header's bearing
    sigma multiplied by ``scale`` (nothing else changed); its final map's MPE."""
    stream = world_stream(world, k, steps)
    header = dataclasses.replace(stream.header,
                                 bearing_sigma_rad=stream.header.bearing_sigma_rad * scale)
    row: dict[str, Any] = {"world": world, "run": k, "method": method, "preset": preset,
                           "scale": scale}
    t0 = time.process_time()
    try:
        opts = dict(options or {}) if method.startswith("ekf") else {}
        mapper = create_mapper(method, header, truth=stream.truth, preset=preset, **opts)
        result = run(mapper, stream.steps, checkpoint_every=10, keep_checkpoints=False)
        score = score_estimate(result.final, stream.truth)
        row.update(mpe_cm=100 * score.mpe_m, mapped=len(result.final),
                   converged=result.final.info.get("converged"))
    except BomgraphError as exc:  # a failed run is a result, with its reason
        row.update(mpe_cm=math.nan, mapped=0, error=f"{type(exc).__name__}: {exc}")
    row["cpu_s"] = time.process_time() - t0
    return row


def _ratio(a: float, b: float) -> float:
    return a / b if b > 0 and math.isfinite(a) and math.isfinite(b) else math.nan


def summarise(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (world, preset, method): mean MPE per scale, ratio of means, largest per-run
    ratio either way against scale 1."""
    out = []
    keys = dict.fromkeys((r["world"], r["preset"], r["method"]) for r in rows)
    for w, p, m in keys:
        by = {(r["run"], r["scale"]): r for r in rows
              if (r["world"], r["preset"], r["method"]) == (w, p, m)}
        runs = sorted({k for k, _ in by})
        mean = {s: float(np.mean([by[k, s]["mpe_cm"] for k in runs])) for s in SCALES}
        worst = {}
        for s in (0.5, 2.0):
            rs = [_ratio(by[k, s]["mpe_cm"], by[k, 1.0]["mpe_cm"]) for k in runs]
            worst[s] = float(max(max(x, 1 / x) for x in rs)) if all(
                math.isfinite(x) and x > 0 for x in rs) else math.nan
        out.append({"world": w, "preset": p, "method": m, "runs": len(runs),
                    "mean_mpe_cm": {str(s): mean[s] for s in SCALES},
                    "mean_ratio": {"0.5": _ratio(mean[0.5], mean[1.0]),
                                   "2.0": _ratio(mean[2.0], mean[1.0])},
                    "worst_run_ratio": {"0.5": worst[0.5], "2.0": worst[2.0]},
                    "mapped": {str(s): float(np.mean([by[k, s]["mapped"] for k in runs]))
                               for s in SCALES}})
    return out


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--worlds", default="paper,sparse")
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--steps", type=int, default=None,
                    help="steps of every run (default: 300 paper, 500 sparse)")
    ap.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                    help="an option of the EKF methods, on top of the preset (repeatable)")
    ap.add_argument("--out", type=Path, default=Path("/tmp/bench_sigma_sim.json"))
    a = ap.parse_args(argv)
    options: dict[str, Any] = {}
    for kv in a.option:
        key, _, value = kv.partition("=")
        try:
            options[key] = json.loads(value)
        except json.JSONDecodeError:
            options[key] = value
    worlds = [w for w in a.worlds.split(",") if w]
    methods = [m for m in a.methods.split(",") if m]
    tasks = [(w, k, m, p, s, a.steps, options) for w in worlds for k in range(a.runs)
             for p in (("real", "paper") if w == "paper" else ("real",))
             for m in methods
             for s in SCALES]
    from joblib import Parallel, delayed

    t0 = time.perf_counter()
    rows = Parallel(n_jobs=a.jobs)(delayed(one)(*t) for t in tasks)
    wall = time.perf_counter() - t0
    summary = summarise(rows)
    print(f"{'world':7s} {'preset':6s} {'method':13s} {'MPE x0.5':>9s} {'x1':>7s} {'x2':>7s} "
          f"{'mean x0.5/x1':>12s} {'x2/x1':>6s} {'worst run x0.5':>14s} {'x2':>6s}")
    for s in summary:
        mm, mr, wr = s["mean_mpe_cm"], s["mean_ratio"], s["worst_run_ratio"]
        print(f"{s['world']:7s} {s['preset']:6s} {s['method']:13s} {mm['0.5']:9.3f} "
              f"{mm['1.0']:7.3f} {mm['2.0']:7.3f} {mr['0.5']:12.3f} {mr['2.0']:6.3f} "
              f"{wr['0.5']:14.3f} {wr['2.0']:6.3f}")
    failed = [r for r in rows if "error" in r]
    print(f"\n{len(rows)} runs in {wall:.0f} s ({len(failed)} failed); wrote {a.out}")
    a.out.write_text(json.dumps({"argv": vars(a) | {"out": str(a.out)}, "rows": rows,
                                 "summary": summary}, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
