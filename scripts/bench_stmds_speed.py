"""Speed of BOM-STMDS (issue 3 targets), printed and saved to results/bench_stmds_speed.json.

1. A full 300-step paper run of Method 2 with 30 map updates (target: median < 100 ms, one core).
2. The per-step update with about 10 landmarks in view, amortised over a run (all steps and
   the final flush of the batched triangulation; target: < 0.1 ms, issue 14: <= 0.05 ms).
3. Reconstruction of N = 1000 landmarks (target: < 0.5 s): a 1000-landmark world at the paper's
   landmark density (an 11.2 m square), simulated long enough to see every landmark, then one
   ``estimate()`` of Method 1 and of Method 2, and the parts (DMC-SPL, classical scaling,
   SMACOF) timed on their own.

Usage: ``python scripts/bench_stmds_speed.py [--repeats 7] [--quick]``. Timings depend on the
machine; the script states the one it ran on.
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import os
import platform
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")          # "one core"
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from bomgraph.evaluate import score_estimate  # noqa: E402
from bomgraph.jsonio import jsonable, parse_options  # noqa: E402
from bomgraph.mapper import create_mapper, run  # noqa: E402
from bomgraph.sim import SimConfig, paper_design, simulate, simulate_run  # noqa: E402
from bomgraph.stmds.completion import shortest_path_completion  # noqa: E402
from bomgraph.stmds.mds import classical_scaling, smacof  # noqa: E402

RESULTS = Path(__file__).resolve().parents[1] / "results"


def full_run(repeats: int, options: dict) -> dict:
    stream = simulate_run(paper_design(0)[0])
    totals, cpu, steps, estimates = [], [], [], []
    for _ in range(repeats):
        mapper = create_mapper("stmds-smacof", stream.header, **options)
        c0 = time.process_time()
        res = run(mapper, stream.steps, checkpoint_every=10)
        cpu.append(time.process_time() - c0)
        totals.append(res.total_s)
        steps.append(float(res.step_s.sum()))
        estimates.append(res.timing()["estimates"])
    return {"n_steps": len(stream.steps) - 1, "n_map_updates": len(res.checkpoints),
            "total_ms_median": 1e3 * float(np.median(totals)),
            "total_cpu_ms_median": 1e3 * float(np.median(cpu)),
            "steps_ms_median": 1e3 * float(np.median(steps)),
            "estimates_ms_median": 1e3 * float(np.median(estimates)),
            "estimate_ms_each_median": 1e3 * float(np.median(estimates)) / len(res.checkpoints)}


def per_step(repeats: int, options: dict) -> dict:
    # 26 landmarks in the paper's arena: about 10 in view per step
    cfg = SimConfig(n_landmarks=26, n_steps=300)
    stream = simulate(cfg, np.random.default_rng(7))
    in_view = float(np.mean([len(s.landmark_ids) for s in stream.steps]))
    med, cpu = [], []
    for _ in range(repeats):
        mapper = create_mapper("stmds-smacof", stream.header, **options)
        flush = getattr(mapper, "flush", lambda: None)   # steps held in batches (stmds.batch)
        t0 = time.perf_counter()
        c0 = time.process_time()
        for s in stream.steps:
            mapper.step(s)
        flush()
        cpu.append((time.process_time() - c0) / len(stream.steps))
        med.append((time.perf_counter() - t0) / len(stream.steps))
    # per step = all steps and the final flush of the batch over the number of steps (a
    # single step() call only holds the step when the batched path is on)
    return {"mean_in_view": in_view, "step_ms_median": 1e3 * float(np.median(med)),
            "step_cpu_ms_mean": 1e3 * float(np.median(cpu))}


def big_world(n: int, quick: bool) -> tuple:
    side = 2.5 * math.sqrt(n / 50.0)
    cfg = SimConfig(arena_m=side, n_landmarks=n, n_steps=800 if quick else int(3.2 * n))
    stream = simulate(cfg, np.random.default_rng(11))
    return cfg, stream


def reconstruction(n: int, repeats: int, quick: bool, options: dict) -> dict:
    cfg, stream = big_world(n, quick)
    out: dict = {"n_landmarks": n, "arena_m": cfg.arena_m, "n_steps": cfg.n_steps}
    for name in ("stmds-cs", "stmds-smacof"):
        mapper = create_mapper(name, stream.header, **options)
        for s in stream.steps:
            mapper.step(s)
        times = []
        for _ in range(repeats):
            fresh = copy.deepcopy(mapper)      # the first map of this run: no warm start
            t0 = time.perf_counter()
            est = fresh.estimate()
            times.append(time.perf_counter() - t0)
        mapper.estimate()
        t0 = time.perf_counter()
        mapper.estimate()                       # a later map, warm-started from the last
        warm = time.perf_counter() - t0
        out[name] = {"estimate_s_median": float(np.median(times)), "n_mapped": len(est),
                     "mpe_m": score_estimate(est, stream.truth).mpe_m,
                     "warm_estimate_s": warm,
                     "n_known_pairs": est.info.get("n_mapped_pairs"),
                     "smacof_iterations": est.info.get("smacof_iterations")}
        if name == "stmds-cs":
            known = mapper._store.known()          # the parts, on the mapper's own pairs
            m = len(mapper._ids)
            t0 = time.perf_counter()
            full = shortest_path_completion(m, known.first, known.second, known.distance_m)
            t_sp = time.perf_counter() - t0
            ok = np.isfinite(full[np.argmax(np.isfinite(full).sum(axis=1))])  # largest piece
            sub = full[np.ix_(ok, ok)]
            t0 = time.perf_counter()
            xy, _ = classical_scaling(sub * sub)
            t_cs = time.perf_counter() - t0
            keep = np.flatnonzero(ok)
            local = np.full(m, -1)
            local[keep] = np.arange(len(keep))
            sel = ok[known.first] & ok[known.second]
            t0 = time.perf_counter()
            res = smacof(len(keep), local[known.first[sel]], local[known.second[sel]],
                         known.distance_m[sel], init=xy)
            t_sm = time.perf_counter() - t0
            out["parts_s"] = {"shortest_paths": t_sp, "classical_scaling": t_cs,
                              "smacof_cold_from_cs": t_sm, "smacof_iterations": res.n_iter}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--n-big", type=int, default=1000)
    ap.add_argument("--quick", action="store_true", help="fewer steps in the big world")
    ap.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                    help="a mapper option, e.g. preset=window-ba (repeatable)")
    args = ap.parse_args()
    options = parse_options(args.option)
    print(f"load average (1 min) {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores: wall "
          f"times on a busy machine are inflated; CPU times are reported beside them")
    report = {"machine": {"python": platform.python_version(), "cpu": platform.processor()
                          or platform.machine(), "cores_used": 1,
                          "load_average_1min": os.getloadavg()[0]},
              "options": options}
    report["full_run"] = r1 = full_run(args.repeats, options)
    print(f"full 300-step Method 2 run, {r1['n_map_updates']} map updates: median "
          f"{r1['total_ms_median']:.1f} ms wall, {r1['total_cpu_ms_median']:.1f} ms CPU "
          f"(steps {r1['steps_ms_median']:.1f} ms, estimates "
          f"{r1['estimates_ms_median']:.1f} ms = {r1['estimate_ms_each_median']:.2f} ms each); "
          f"target < 100 ms")
    report["per_step"] = r2 = per_step(args.repeats, options)
    print(f"per-step update (all steps + the final batch flush, per step), "
          f"{r2['mean_in_view']:.1f} landmarks in view: "
          f"{r2['step_ms_median']:.3f} ms wall (CPU {r2['step_cpu_ms_mean']:.3f} ms); "
          f"target < 0.1 ms")
    report["reconstruction"] = r3 = reconstruction(args.n_big, 3, args.quick, options)
    for name in ("stmds-cs", "stmds-smacof"):
        print(f"N = {args.n_big} reconstruction, {name}: first map "
              f"{r3[name]['estimate_s_median']:.3f} s, a later warm-started one "
              f"{r3[name]['warm_estimate_s']:.3f} s ({r3[name]['n_mapped']} mapped, "
              f"{r3[name]['n_known_pairs']} pairs, MPE {100 * r3[name]['mpe_m']:.1f} cm); "
              f"target < 0.5 s")
    print("  parts: " + ", ".join(f"{k} {v:.3f} s" if isinstance(v, float) else f"{k} {v}"
                                  for k, v in r3["parts_s"].items()))
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / "bench_stmds_speed.json"
    path.write_text(json.dumps(jsonable(report), indent=2))
    print(f"saved {path}")


if __name__ == "__main__":
    main()
