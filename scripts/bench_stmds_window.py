"""Windowed triangulation for BOM-STMDS (issue 8): choice of the window and thresholds.

Measures the landmark MPE of Method 1 / Method 2 with ``tri_window=W`` against the paper's
consecutive-step rule (the default, ``W = 2``) and the ``improved`` preset, with each landmark
triangulated from its two rays furthest apart in the window (``tri_method="pair"``) or from all
its rays by least squares (``tri_method="lsq"``):

* ``--sim``: the paper's 25 runs (``paper_design(0)``, 300 steps), MPE at t = 300 next to the
  paper's 4.78 / 2.87 cm, over a grid of W, fusion rule, ``min_count`` and SMACOF weights;
* ``--real``: MRCLAM6 robots 1-5 and the bearing-only g2o set (final map: mapped landmarks
  and MPE), over a grid of W, ``min_count``, ``min_parallax_rad`` and the depth gate; with
  ``--gtsam`` also ``gtsam-batch`` on the same recordings, for the 3x target.

Usage: ``python scripts/bench_stmds_window.py [--sim] [--real] [--gtsam] [--runs 25]
[--jobs 2] [--quick] [--ba-only]``. Results are printed and saved to ``results/bench_stmds_window.json``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import time
from pathlib import Path

import numpy as np
from joblib import Parallel, delayed

from bomgraph.errors import BomgraphError
from bomgraph.evaluate import error_table, score_estimate
from bomgraph.jsonio import jsonable
from bomgraph.mapper import create_mapper, run
from bomgraph.sim import SimConfig, paper_design, simulate_run

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results"
DATA = ROOT.parent / "shared" / "data"
PAPER = {"stmds-cs": 4.78, "stmds-smacof": 2.87}
G2O = "bearing_only_sim_g2o/slam2D_bearing_only_"


def _limit_blas() -> None:
    from threadpoolctl import threadpool_limits
    threadpool_limits(limits=1)


def sim_run(spec, method: str, options: dict) -> float:
    _limit_blas()
    stream = simulate_run(spec, SimConfig())
    res = run(create_mapper(method, stream.header, **options), stream.steps,
              checkpoint_every=10, method=method)
    return float(error_table(res, stream.truth)["mpe_m"][-1])


def real_stream(name: str):
    from bomgraph.datasets import import_g2o, import_mrclam
    if name == "g2o":
        return import_g2o(DATA / (G2O + "initial_guess.g2o"),
                          truth_path=DATA / (G2O + "ground_truth.g2o"))
    return import_mrclam(DATA / "mrclam6", int(name[-1]))


def real_run(name: str, method: str, options: dict) -> dict:
    _limit_blas()
    stream = real_stream(name)
    t0 = time.perf_counter()
    try:
        res = run(create_mapper(method, stream.header, **options), stream.steps,
                  checkpoint_every=10, method=method)
        score = score_estimate(res.final, stream.truth)
    except BomgraphError as exc:          # no map, or too few landmarks to score
        return {"n_mapped": 0, "mpe_cm": math.nan, "error": str(exc)}
    return {"n_mapped": int(score.n_mapped), "n_truth": int(score.n_truth),
            "mpe_cm": 100 * float(score.mpe_m), "seconds": time.perf_counter() - t0}


def _opts_label(options: dict) -> str:
    return ", ".join(f"{k}={v}" for k, v in options.items()) or "defaults (paper rule)"


def bench_sim(runs: int, jobs: int, quick: bool) -> list[dict]:
    specs = paper_design(0)[:runs]
    grid: list[tuple[str, dict]] = [("stmds-smacof", {}), ("stmds-smacof", {"preset": "improved"})]
    windows = (4, 6) if quick else (2, 4, 6, 8)
    for w, stride, fusion in itertools.product(windows, (1, None), ("relative", "scale-free")):
        grid.append(("stmds-smacof", {"tri_window": w, "tri_stride": stride, "fusion": fusion,
                                      "min_count": 3, "weights": "inverse-variance"}))
    grid += [("stmds-cs", {}), ("stmds-cs", {"preset": "improved"}),
             ("stmds-cs", {"preset": "window"}), ("stmds-smacof", {"preset": "window"})]
    # all rays of a landmark by least squares (tri_method="lsq") against the furthest pair
    for w in ((6, 10) if quick else (4, 6, 8, 10, 14)):
        grid.append(("stmds-smacof", {"preset": "window", "tri_method": "lsq",
                                      "tri_window": w}))
    grid.append(("stmds-cs", {"preset": "window-lsq"}))
    # local bundle adjustment in the window (poses estimated with the landmarks)
    grid += [("stmds-smacof", {"preset": "window-ba", "tri_stride": None}),
             ("stmds-smacof", {"preset": "window-ba"})]
    out = []
    print(f"== paper settings, {len(specs)} runs, MPE at t = 300 ==", flush=True)
    for method, options in grid:
        try:
            mpe = np.array(Parallel(n_jobs=jobs)(delayed(sim_run)(s, method, options)
                                                 for s in specs))
        except BomgraphError as exc:      # e.g. a preset not defined in this version
            print(f"{method:<13s} {_opts_label(options)}: {exc}")
            continue
        row = {"method": method, "options": options, "mpe_cm_mean": 100 * float(mpe.mean()),
               "mpe_cm_median": 100 * float(np.median(mpe)),
               "mpe_cm_max": 100 * float(mpe.max())}
        out.append(row)
        print(f"{method:<13s} {_opts_label(options):<70s} MPE {row['mpe_cm_mean']:6.2f} cm "
              f"(median {row['mpe_cm_median']:5.2f}, max {row['mpe_cm_max']:6.2f}) "
              f"paper {PAPER[method]:.2f}", flush=True)
    return out


REAL = ("mrclam6-r1", "mrclam6-r2", "mrclam6-r3", "mrclam6-r4", "mrclam6-r5", "g2o")


def ba_grid(quick: bool) -> list[tuple[str, dict]]:
    """Windowed bundle adjustment (``tri_method="ba"``, the kernel of the "real" preset):
    window length, stride, the growing solve and the outlier test."""
    grid: list[tuple[str, dict]] = []
    for w, stride in itertools.product((40, 60) if quick else (24, 40, 60, 80), (10, 20)):
        grid.append(("stmds-smacof", {"preset": "real", "tri_window": w, "tri_stride": stride}))
    grid += [("stmds-smacof", {"preset": "real", "tri_grow": 60}),       # one solve per window
             ("stmds-smacof", {"preset": "real", "tri_grow": 5}),
             ("stmds-smacof", {"preset": "real", "tri_grow": 10}),
             ("stmds-smacof", {"preset": "real", "tri_outlier_sigma": None}),
             ("stmds-smacof", {"preset": "real", "tri_window": 60, "tri_stride": 60}),
             ("stmds-cs", {"preset": "real"}), ("stmds-smacof-loc", {"preset": "real"})]
    return grid


def bench_real(jobs: int, quick: bool, gtsam: bool, ba_only: bool = False) -> list[dict]:
    if ba_only:
        return _real_grid(ba_grid(quick) + ([("gtsam-batch", {})] if gtsam else []), jobs)
    grid: list[tuple[str, dict]] = [("stmds-smacof", {}), ("stmds-smacof", {"min_count": 1}),
                                    ("stmds-smacof", {"preset": "improved", "min_count": 1})]
    windows = (6, 16) if quick else (6, 10, 16, 24)
    for w, stride, par in itertools.product(windows, (1, None), (1.0, 5.0)):
        grid.append(("stmds-smacof", {"tri_window": w, "tri_stride": stride,
                                      "fusion": "scale-free", "min_count": 1,
                                      "min_parallax_rad": round(math.radians(par), 6),
                                      "weights": "inverse-variance"}))
    grid += [("stmds-cs", {"preset": "real"}), ("stmds-smacof", {"preset": "real"}),
             ("stmds-smacof", {"preset": "window"})]
    for w, par in itertools.product((8, 16, 24), (1.0, 5.0)):
        grid.append(("stmds-smacof", {"preset": "real", "tri_method": "lsq", "tri_window": w,
                                      "min_parallax_rad": round(math.radians(par), 6)}))
    grid += ba_grid(quick)
    if gtsam:
        grid.append(("gtsam-batch", {}))
    return _real_grid(grid, jobs)


def _real_grid(grid: list[tuple[str, dict]], jobs: int) -> list[dict]:
    out = []
    print("== real data: final map, mapped landmarks and MPE (cm) ==", flush=True)
    print(f"{'':<84s}" + "".join(f"{n:>16s}" for n in REAL))
    for method, options in grid:
        try:
            rows = Parallel(n_jobs=jobs)(delayed(real_run)(n, method, options) for n in REAL)
        except BomgraphError as exc:
            print(f"{method:<13s} {_opts_label(options)}: {exc}")
            continue
        out.append({"method": method, "options": options, "datasets": dict(zip(REAL, rows))})
        cells = "".join(f"{r['n_mapped']:>5d} {r['mpe_cm']:9.1f} cm" for r in rows)
        print(f"{method:<13s} {_opts_label(options):<70s} {cells}", flush=True)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sim", action="store_true", help="the paper's simulation")
    ap.add_argument("--real", action="store_true", help="MRCLAM6 robots 1-5 and g2o")
    ap.add_argument("--gtsam", action="store_true", help="also gtsam-batch on the real data")
    ap.add_argument("--runs", type=int, default=25)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--quick", action="store_true", help="a smaller grid")
    ap.add_argument("--ba-only", action="store_true",
                    help="with --real: only the window bundle adjustment grid")
    ap.add_argument("--out", default=str(RESULTS / "bench_stmds_window.json"))
    args = ap.parse_args()
    if not (args.sim or args.real):
        args.sim = args.real = True
    result: dict = {"paper": PAPER}
    if args.sim:
        result["sim"] = bench_sim(args.runs, args.jobs, args.quick)
    if args.real:
        if (DATA / "mrclam6").is_dir():
            result["real"] = bench_real(args.jobs, args.quick, args.gtsam, args.ba_only)
        else:
            print(f"no real data under {DATA}; skipped")
    path = Path(args.out)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(jsonable(result), indent=1))
    print(f"saved {path}")


if __name__ == "__main__":
    main()
