"""Benchmark of the EKF baselines on the paper's setup (section IV-A, Exp. 2).

25 runs (``bomgraph.sim.paper_design(seed)``: 5 layouts x 5 starts), 300 steps, N = 50,
sensor range 1 m, sigma_l = 3 cm, sigma_phi = sigma_theta = 3 deg. For each method it reports

* landmark MPE (after the paper's rigid alignment with reflection, no scale) and the error of
  the current robot position at t = 50, 100, 200, 300: mean and median over the runs;
* the robot-pose NEES averaged over the runs at every step, against the two-sided 95%
  chi-square band for the average of ``n_runs`` 3-dof NEES values (the mapper is started at
  the true first pose, so its frame is the truth's and no alignment enters the NEES);
* the wall time of one run (all steps and the 31 map estimates).

Usage::

    python scripts/bench_ekf.py [--methods ekf ekf-invdepth] [--runs 25] [--steps 300]
                                [--jobs 2] [--seed 0] [--out results/bench_ekf.json]
                                [--option key=value ...]

``--speed`` instead times, in one process with single-threaded BLAS, the CPU seconds per paper
run (all steps and map estimates every 10 steps; the best of ``--repeat``) of each method and of
the lean reference loop ``scripts/_ekf_lean.py`` (a bare numpy EKF-SLAM step on the same stream
and state sizes), and prints the ratios; JSON to ``results/bench_ekf_speed.json``.

``--option preset=real`` runs the presets made for recordings (``EkfConfig.PRESETS``);
options are parsed by ``bomgraph.jsonio.parse_options`` (``inf`` is a number). Prints a table and
writes the numbers as JSON (``results/`` is git-ignored). docs/measurements.md holds what it
measured.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")        # small matrices: one BLAS thread is fastest
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from joblib import Parallel, delayed  # noqa: E402
from scipy.stats import chi2  # noqa: E402

from bomgraph.evaluate import Alignment, error_table, pose_nees  # noqa: E402
from bomgraph.jsonio import jsonable, parse_options  # noqa: E402
from bomgraph.mapper import MapEstimate, create_mapper, run  # noqa: E402
from bomgraph.stream import Truth  # noqa: E402
from bomgraph.sim import SimConfig, paper_design, simulate_run  # noqa: E402

TIMES = (50, 100, 200, 300)


#: The mapper starts at the true first pose: its frame is the truth's, no alignment enters.
IDENTITY = Alignment(np.eye(2), np.zeros(2))


def robot_nees(estimate: MapEstimate, truth: Truth) -> np.ndarray:
    """NEES of the filtered pose at every step (``bomgraph.evaluate.pose_nees``), shape (T,).

    NaN where the covariance is singular (the first steps: the first pose is known exactly and
    the simulator's odometry has no lateral noise).
    """
    out = np.full(len(estimate.pose_t), np.nan)
    no_map = np.zeros(0, np.int64), np.zeros((0, 2))
    for k in np.flatnonzero(np.linalg.det(estimate.pose_cov) > 1e-30):
        at_k = MapEstimate(*no_map, pose_t=estimate.pose_t[k:k + 1],
                           poses=estimate.poses[k:k + 1], pose_cov=estimate.pose_cov[k:k + 1])
        out[k] = pose_nees(at_k, truth, IDENTITY)
    return out


def one_run(method: str, spec_index: int, seed: int, n_steps: int,
            options: dict[str, Any]) -> dict[str, Any]:
    spec = paper_design(seed)[spec_index]
    stream = simulate_run(spec, SimConfig(n_steps=n_steps))
    mapper = create_mapper(method, stream.header, start_pose=tuple(stream.truth.poses[0]),
                           **options)
    cpu0 = time.process_time()
    result = run(mapper, stream.steps, checkpoint_every=10, method=method)
    cpu_s = time.process_time() - cpu0
    table = error_table(result, stream.truth)
    final = result.final
    nees = robot_nees(final, stream.truth)
    return {"run": spec.name, "t": table["t"].tolist(), "mpe_m": table["mpe_m"].tolist(),
            "median_m": table["median_m"].tolist(), "robot_m": table["robot_last_m"].tolist(),
            "n_mapped": table["n_mapped"].tolist(), "nees": nees.tolist(),
            "total_s": result.total_s, "cpu_s": cpu_s, "info": {k: v for k, v in final.info.items()
                                                if isinstance(v, (int, float))}}


def summarise(runs: list[dict[str, Any]], n_steps: int) -> dict[str, Any]:
    t = np.array(runs[0]["t"])
    mpe = np.array([r["mpe_m"] for r in runs])
    rob = np.array([r["robot_m"] for r in runs])
    nees = np.array([r["nees"] for r in runs])
    n = len(runs)
    lo, hi = chi2.ppf(0.025, 3 * n) / n, chi2.ppf(0.975, 3 * n) / n
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)      # all-NaN first steps
        avg = np.nanmean(nees, 0)
    valid = np.isfinite(avg)
    times = [x for x in TIMES if x <= n_steps] or [int(t[-1])]
    cols = {x: int(np.flatnonzero(t == x)[0]) for x in times if np.any(t == x)}
    return {
        "n_runs": n,
        "at": {str(x): {"mpe_mean_m": float(np.nanmean(mpe[:, c])),
                        "mpe_median_m": float(np.nanmedian(mpe[:, c])),
                        "robot_mean_m": float(np.nanmean(rob[:, c])),
                        "robot_median_m": float(np.nanmedian(rob[:, c]))}
               for x, c in cols.items()},
        "nees": {"band95": [float(lo), float(hi)],
                 "time_average": float(avg[valid].mean()),
                 "fraction_in_band": float(np.mean((avg[valid] >= lo) & (avg[valid] <= hi))),
                 "fraction_above_band": float(np.mean(avg[valid] > hi)),
                 "by_window": {f"{a}-{min(a + 49, n_steps)}": float(np.nanmean(avg[a:a + 50]))
                               for a in range(0, n_steps, 50)},
                 "per_step": avg.tolist()},
        "run_s": {"mean": float(np.mean([r["total_s"] for r in runs])),
                  "median": float(np.median([r["total_s"] for r in runs])),
                  "max": float(np.max([r["total_s"] for r in runs])),
                  "cpu_mean": float(np.mean([r["cpu_s"] for r in runs])),
                  "cpu_median": float(np.median([r["cpu_s"] for r in runs]))},
    }


def speed(methods: list[str], n_runs: int, seed: int, n_steps: int, repeat: int,
          options: dict[str, Any]) -> dict[str, Any]:
    """CPU seconds per run of each method and of the lean loop, timed in this process."""
    import sys
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _ekf_lean import lean_ekf_slam

    streams = [simulate_run(spec, SimConfig(n_steps=n_steps))
               for spec in paper_design(seed)[:n_runs]]
    cpu: dict[str, list[float]] = {m: [] for m in [*methods, "lean-loop"]}
    for stream in streams:
        truth_xy = dict(zip(stream.truth.landmark_ids.tolist(), stream.truth.landmarks_xy))
        for name in cpu:
            best = math.inf
            for _ in range(repeat):
                t0 = time.process_time()
                if name == "lean-loop":
                    lean_ekf_slam(stream.header, stream.steps, stream.truth.poses[0], truth_xy)
                else:
                    mapper = create_mapper(name, stream.header,
                                           start_pose=tuple(stream.truth.poses[0]), **options)
                    run(mapper, stream.steps, checkpoint_every=10, method=name)
                best = min(best, time.process_time() - t0)
            cpu[name].append(best)
    lean = float(np.mean(cpu["lean-loop"]))
    return {name: {"cpu_s_per_run": float(np.mean(v)), "runs": v,
                   "ratio_to_lean_loop": float(np.mean(v)) / lean} for name, v in cpu.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--methods", nargs="+", default=["ekf", "ekf-invdepth"])
    ap.add_argument("--runs", type=int, default=25)
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--option", nargs="*", default=[], help="mapper option key=value")
    ap.add_argument("--out", default=None, help="JSON output (default results/bench_ekf.json, "
                    "with --speed results/bench_ekf_speed.json)")
    ap.add_argument("--speed", action="store_true", help="CPU per run vs the lean loop")
    ap.add_argument("--repeat", type=int, default=3, help="--speed: best of this many")
    args = ap.parse_args()
    options = parse_options(args.option)
    if args.speed:
        n = min(args.runs, len(paper_design(args.seed)))
        rep = speed(args.methods, n, args.seed, args.steps, args.repeat, options)
        print(f"paper setup, {n} runs x {args.steps} steps, CPU s per run (best of "
              f"{args.repeat}), single-threaded BLAS, load average {os.getloadavg()[0]:.1f}")
        for name, row in rep.items():
            print(f"{name:<14}{row['cpu_s_per_run']:8.3f} s  {row['ratio_to_lean_loop']:6.2f}x "
                  f"the lean loop")
        out = Path(args.out or "results/bench_ekf_speed.json")
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(jsonable({"setup": {"runs": n, "steps": args.steps,
                                                      "repeat": args.repeat,
                                                      "options": options},
                                            "methods": rep}), allow_nan=False))
        print(f"\nwrote {out}")
        return
    args.out = args.out or "results/bench_ekf.json"
    n_runs = min(args.runs, len(paper_design(args.seed)))
    report: dict[str, Any] = {"setup": {"design": "paper_design", "seed": args.seed,
                                        "runs": n_runs, "steps": args.steps,
                                        "options": options, "jobs": args.jobs,
                                        "python": platform.python_version(),
                                        "load_average": [round(v, 2) for v in
                                                         os.getloadavg()],
                                        "machine": platform.machine()},
                              "methods": {}}
    for method in args.methods:
        runs = Parallel(n_jobs=args.jobs)(
            delayed(one_run)(method, k, args.seed, args.steps, options) for k in range(n_runs))
        report["methods"][method] = {"summary": summarise(runs, args.steps), "runs": runs}

    print(f"paper setup, {n_runs} runs x {args.steps} steps, options {options or '{}'}")
    head = f"{'method':<14}{'t':>5}{'MPE mean':>10}{'median':>9}{'robot mean':>12}{'median':>9}"
    print(head)
    for method, rep in report["methods"].items():
        for t, row in rep["summary"]["at"].items():
            print(f"{method:<14}{t:>5}{100 * row['mpe_mean_m']:>8.2f}cm"
                  f"{100 * row['mpe_median_m']:>7.2f}cm{100 * row['robot_mean_m']:>10.2f}cm"
                  f"{100 * row['robot_median_m']:>7.2f}cm")
    print()
    for method, rep in report["methods"].items():
        s = rep["summary"]
        nees, rs = s["nees"], s["run_s"]
        print(f"{method:<14} robot NEES avg {nees['time_average']:.2f} "
              f"(95% band for the mean of {n_runs}: {nees['band95'][0]:.2f}-"
              f"{nees['band95'][1]:.2f}; in band {100 * nees['fraction_in_band']:.0f}% of "
              f"steps, above {100 * nees['fraction_above_band']:.0f}%)")
        print(f"{'':<14} by window: " + ", ".join(f"{k}: {v:.2f}"
                                                  for k, v in nees["by_window"].items()))
        print(f"{'':<14} wall time per run: mean {rs['mean']:.3f} s, median "
              f"{rs['median']:.3f} s, max {rs['max']:.3f} s (CPU time: mean "
              f"{rs['cpu_mean']:.3f} s, median {rs['cpu_median']:.3f} s; load average before "
              f"the runs {report['setup']['load_average']})")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(jsonable(report), allow_nan=False))
    print(f"\nwrote {out}")


if __name__ == "__main__":
    main()
