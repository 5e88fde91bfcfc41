"""Paired same-process A/B of ``gtsam-isam2`` long-mode settings on a long run (issue 14
items 1-2).

One stream (a simulated run of ``--steps`` steps, ``paper_design(seed)[0]``, the stream of
``bench_speed.py --sections long``; or ``--stream FILE.jsonl``), each variant run
``--repeats`` times in alternating order (A B B A ...), with ``gtsam-batch`` once per round
as the reference. CPU seconds (``time.process_time``), single-threaded BLAS. Per run: CPU s,
final MPE (cm), the final info's ``converged`` and, for ``gtsam-isam2``, the whole-graph
Gauss-Newton check of the final solver state (``polish(accepted, current_values(), 0)``,
the predicted decrease and the cost; ``decrease_tol`` 1) and the window counters.

Variants are ``NAME:key=value,key=value`` (``old:long_window=false`` is the session-7 long
mode; ``new:`` the defaults).

Usage::

    OMP_NUM_THREADS=1 PYTHONPATH=$PWD python scripts/bench_isam2_long.py \\
        [--steps 3000] [--repeats 2] [--variants old:long_window=false new:] [--no-batch]
        [--stream /work/gen/s6/streams/m1dense_r1.jsonl --preset real] [--out results.json]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from typing import Any  # noqa: E402

from baselines.isam2 import Isam2Mapper, polish  # noqa: E402
from bomgraph.errors import BomgraphError  # noqa: E402
from bomgraph.evaluate import score_estimate  # noqa: E402
from bomgraph.jsonio import parse_options  # noqa: E402
from bomgraph.mapper import create_mapper, run  # noqa: E402
from bomgraph.sim import SimConfig, paper_design, simulate_run  # noqa: E402
from bomgraph.stream import Stream  # noqa: E402
from bomgraph.stream_file import read_stream  # noqa: E402


def _mpe_cm(final: Any, stream: Stream) -> float:
    try:
        return 100 * score_estimate(final, stream.truth).mpe_m
    except BomgraphError:
        return float("nan")


def run_isam2(stream: Stream, preset: str | None, options: dict[str, Any],
              every: int) -> dict[str, Any]:
    """One ``gtsam-isam2`` run with ``options``: CPU s, MPE, info, final whole-graph check."""
    mapper = Isam2Mapper(stream.header, preset=preset, **options)
    c0 = time.process_time()
    result = run(mapper, stream.steps, checkpoint_every=every, keep_checkpoints=False)
    cpu = time.process_time() - c0
    final = result.final
    _, step, decrease, cost = polish(mapper.accepted, mapper.current_values(), 0,
                                     mapper.config.decrease_tol)
    info = final.info
    return {"cpu_s": cpu, "mpe_cm": _mpe_cm(final, stream),
            "converged": info.get("converged"), "last_converged": info.get("last_converged"),
            "final_check_decrease": decrease, "final_check_cost": cost,
            "final_check_passes": bool(decrease <= mapper.config.decrease_tol),
            "mode": info.get("mode"), "lm_restarts": info.get("lm_restarts"),
            "window_rebuilds": info.get("window_rebuilds"),
            "update_failures": info.get("update_failures")}


def run_batch(stream: Stream, preset: str | None, every: int) -> dict[str, Any]:
    mapper = create_mapper("gtsam-batch", stream.header, preset=preset)
    c0 = time.process_time()
    result = run(mapper, stream.steps, checkpoint_every=every, keep_checkpoints=False)
    cpu = time.process_time() - c0
    return {"cpu_s": cpu, "mpe_cm": _mpe_cm(result.final, stream),
            "converged": result.final.info.get("converged")}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--stream", default=None, help="a stream file instead of the simulation")
    ap.add_argument("--preset", default=None, help="preset of both methods (e.g. real)")
    ap.add_argument("--every", type=int, default=10, help="checkpoint cadence")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--variants", nargs="+", default=["old:long_window=false", "new:"])
    ap.add_argument("--no-batch", action="store_true")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    if args.stream:
        stream = read_stream(args.stream)
    else:
        stream = simulate_run(paper_design(args.seed)[0], SimConfig(n_steps=args.steps))
    variants = {}
    for v in args.variants:
        name, _, opts = v.partition(":")
        variants[name] = parse_options([o for o in opts.split(",") if o])
    rows: dict[str, list[dict[str, Any]]] = {n: [] for n in variants}
    if not args.no_batch:
        rows["gtsam-batch"] = []
    names = list(variants)
    for r in range(args.repeats):
        order = names if r % 2 == 0 else names[::-1]
        for name in order:
            row = run_isam2(stream, args.preset, variants[name], args.every)
            rows[name].append(row)
            print(f"round {r} {name:>12}: {json.dumps(row)}", flush=True)
        if not args.no_batch:
            row = run_batch(stream, args.preset, args.every)
            rows["gtsam-batch"].append(row)
            print(f"round {r} {'gtsam-batch':>12}: {json.dumps(row)}", flush=True)
    print("\n| variant | CPU s (each run) | median | MPE cm | final check (decrease) | info converged |")
    print("|---|---|---|---|---|---|")
    for name, rs in rows.items():
        cpus = [x["cpu_s"] for x in rs]
        chk = ", ".join(f"{x['final_check_decrease']:.3g}" for x in rs
                        if "final_check_decrease" in x) or "-"
        print(f"| {name} | {', '.join(f'{c:.1f}' for c in cpus)} | {statistics.median(cpus):.1f} "
              f"| {rs[0]['mpe_cm']:.5f} | {chk} | {rs[0]['converged']} |")
    if args.out:
        with open(args.out, "w") as fh:
            json.dump({"args": vars(args), "rows": rows}, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
