"""BOM-STMDS at scale (issue 14 item 5): stmds-smacof maps N = 1,000 / 5,000 / 10,000 landmarks.

The world grows at the paper's density and the run at the paper's length per landmark: the
paper maps N = 50 landmarks in a 2.5 m square (8 per m^2) in 300 steps, so a world of N
landmarks is a square of side ``2.5 sqrt(N / 50)`` m explored for ``6 N`` steps (everything
else as in the paper: 1 m sensor range, the same noise and motion). The mapper runs every
step and makes one map at the end (no checkpoints). Each size runs in a fresh process, so the
peak resident memory (``resource.getrusage``) is that size's own; it includes the simulated
stream held in memory, and the increase over the process before mapping is given beside it.

Targets (issue 14): N = 10,000 in <= 30 s CPU and <= 8 GB. The fitted exponent is the slope of
log CPU time over log N (least squares over the sizes run). CPU seconds with single-threaded
BLAS; each row also times the paper run (300 steps, 50 landmarks, a map every 10 steps) in the
same process as a reference for the machine's speed.

Usage: ``python scripts/bench_scale.py [--sizes 1000 5000 10000] [--out results/bench_scale.json]``.
From Python: ``scale_rows([1000, 5000]) -> list[dict]`` (one subprocess per size).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results"
#: Paper density and run length per landmark (section IV-A: 50 landmarks, 2.5 m, 300 steps).
PAPER_N, PAPER_SIDE_M, PAPER_STEPS = 50, 2.5, 300
SIZES = (1000, 5000, 10000)


def _rss_bytes() -> int:
    import resource

    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024   # Linux: KiB


def _paper_run_cpu_s(method: str) -> float:
    """CPU seconds of one paper run of ``method`` (map every 10 steps), best of 3."""
    from bomgraph.mapper import create_mapper, run
    from bomgraph.sim import paper_design, simulate_run

    stream = simulate_run(paper_design(0)[0])
    best = math.inf
    for _ in range(3):
        c0 = time.process_time()
        run(create_mapper(method, stream.header), stream.steps, checkpoint_every=10)
        best = min(best, time.process_time() - c0)
    return best


def one_size(n: int, method: str = "stmds-smacof", seed: int = 11) -> dict:
    """Map one world of ``n`` landmarks in this process (see the module docstring)."""
    import numpy as np

    from bomgraph.evaluate import score_estimate
    from bomgraph.mapper import create_mapper
    from bomgraph.sim import SimConfig, simulate

    side = PAPER_SIDE_M * math.sqrt(n / PAPER_N)
    n_steps = PAPER_STEPS * n // PAPER_N
    c0 = time.process_time()
    stream = simulate(SimConfig(arena_m=side, n_landmarks=n, n_steps=n_steps),
                      np.random.default_rng(seed))
    sim_s = time.process_time() - c0
    rss_before = _rss_bytes()
    mapper = create_mapper(method, stream.header)
    c0 = time.process_time()
    for s in stream.steps:
        mapper.step(s)
    c1 = time.process_time()
    if callable(getattr(mapper, "finish", None)):   # as bomgraph.mapper.run after the last step
        mapper.finish()
    est = mapper.estimate()
    c2 = time.process_time()
    rss_peak = _rss_bytes()
    score = score_estimate(est, stream.truth)
    info = est.info
    return {"n_landmarks": n, "method": method, "arena_m": side, "n_steps": n_steps,
            "mean_in_view": float(np.mean([len(s.landmark_ids) for s in stream.steps])),
            "cpu_s": c2 - c0, "steps_cpu_s": c1 - c0, "estimate_cpu_s": c2 - c1,
            "step_cpu_ms": 1e3 * (c1 - c0) / max(len(stream.steps), 1),
            "peak_rss_bytes": rss_peak, "rss_increase_bytes": rss_peak - rss_before,
            "simulate_cpu_s": sim_s, "n_mapped": len(est), "mpe_m": float(score.mpe_m),
            "n_known_pairs": info.get("n_known_pairs"),
            "n_mapped_pairs": info.get("n_mapped_pairs"),
            "smacof_iterations": info.get("smacof_iterations"),
            "init_completion": info.get("init_completion", "DMC-SPL + classical scaling"),
            "reference_paper_run_cpu_s": _paper_run_cpu_s(method)}


def scale_rows(sizes=SIZES, method: str = "stmds-smacof") -> list[dict]:
    """One row per size, each measured in a fresh Python process (this tree's bomgraph);
    adds ``fitted_exponent`` (slope of log CPU over log N) to every row when >= 2 sizes."""
    rows = []
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT)] + ([os.environ["PYTHONPATH"]] if os.environ.get("PYTHONPATH") else []))}
    for n in sizes:
        out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--one", str(n),
                              "--method", method], check=True, capture_output=True, text=True,
                             env=env)
        rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
    expo = fitted_exponent([r["n_landmarks"] for r in rows], [r["cpu_s"] for r in rows])
    for r in rows:
        r["fitted_exponent"] = expo
    return rows


def fitted_exponent(sizes, seconds) -> float | None:
    """Least-squares slope of ``log(seconds)`` over ``log(sizes)`` (None for < 2 sizes)."""
    import numpy as np

    if len(sizes) < 2:
        return None
    return float(np.polyfit(np.log(sizes), np.log(seconds), 1)[0])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    ap.add_argument("--method", default="stmds-smacof")
    ap.add_argument("--out", type=Path, default=RESULTS / "bench_scale.json")
    ap.add_argument("--one", type=int, help=argparse.SUPPRESS)   # child process: one size
    args = ap.parse_args()
    if args.one is not None:
        print(json.dumps(one_size(args.one, args.method)))
        return
    rows = scale_rows(args.sizes, args.method)
    print(f"{'N':>7} {'arena m':>8} {'steps':>7} {'CPU s':>7} {'steps s':>8} {'map s':>7} "
          f"{'peak RSS MB':>11} {'+MB':>7} {'MPE cm':>7} {'paper run s':>11}")
    for r in rows:
        print(f"{r['n_landmarks']:>7} {r['arena_m']:>8.1f} {r['n_steps']:>7} {r['cpu_s']:>7.2f} "
              f"{r['steps_cpu_s']:>8.2f} {r['estimate_cpu_s']:>7.2f} "
              f"{r['peak_rss_bytes'] / 2 ** 20:>11.0f} {r['rss_increase_bytes'] / 2 ** 20:>7.0f} "
              f"{100 * r['mpe_m']:>7.2f} {r['reference_paper_run_cpu_s']:>11.3f}")
    if rows and rows[0]["fitted_exponent"] is not None:
        print(f"fitted exponent of CPU time in N: {rows[0]['fitted_exponent']:.2f}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"rows": rows, "target": {"n": 10000, "cpu_s": 30.0,
                                                             "peak_bytes": 8 * 2 ** 30}},
                                   indent=2) + "\n")
    print(f"saved {args.out}")


if __name__ == "__main__":
    main()
