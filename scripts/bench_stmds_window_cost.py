"""Per-step cost of windowed BOM-STMDS against the run length (issue 8 target: bounded by the
window, not by the run).

Runs ``stmds-smacof`` with windowed triangulation over one long simulated run (the paper's world,
``--steps`` steps) and prints the mean time of ``step()`` in consecutive blocks of 100 steps;
with a cost bounded by the window the blocks stay flat while the stored pairs grow. Map
estimates are not timed (their cost depends on the number of landmarks, not on the window).

Usage: ``python scripts/bench_stmds_window_cost.py [--steps 900] [--options JSON ...]``.
Prints and saves ``results/bench_stmds_window_cost.json``; timings depend on the machine.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from bomgraph.mapper import create_mapper  # noqa: E402
from bomgraph.jsonio import jsonable  # noqa: E402
from bomgraph.sim import SimConfig, simulate  # noqa: E402

DEFAULT_OPTIONS = (
    {"preset": "window-ba"},
    {"preset": "window-ba", "tri_stride": 1},
    {"preset": "window-lsq"},
    {"preset": "real"},
)


def block_times(options: dict, steps: int, block: int = 100) -> dict:
    stream = simulate(SimConfig(n_steps=steps), np.random.default_rng(0))
    mapper = create_mapper("stmds-smacof", stream.header, **options)
    per_step = np.empty(len(stream.steps))
    for k, st in enumerate(stream.steps):
        t0 = time.perf_counter()
        mapper.step(st)
        if k == len(stream.steps) - 1:
            mapper.flush()          # windows still held (window-lsq runs them in batches)
        per_step[k] = time.perf_counter() - t0
    blocks = [float(per_step[a:a + block].mean() * 1e3) for a in range(0, steps, block)]
    return {"options": options, "steps": steps, "block_ms": blocks,
            "pairs_stored": len(mapper._store)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=900)
    ap.add_argument("--options", action="append", default=None,
                    help="mapper options as JSON (repeatable); default: four windowed variants")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "results"
                                         / "bench_stmds_window_cost.json"))
    args = ap.parse_args()
    grid = [json.loads(o) for o in args.options] if args.options else list(DEFAULT_OPTIONS)
    rows = []
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
          f"mean step() time [ms] per block of 100 steps")
    for options in grid:
        row = block_times(options, args.steps)
        rows.append(row)
        print(f"{json.dumps(options):<80s} " + " ".join(f"{b:6.2f}" for b in row["block_ms"])
              + f"  ({row['pairs_stored']} pairs stored)", flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(jsonable({"rows": rows}), indent=1))
    print(f"saved {args.out}")


if __name__ == "__main__":
    main()
