"""The final solve of the GTSAM mappers on long runs, paired: with ``finish()`` (what
:func:`bomgraph.mapper.run` does after the last step) and without it (the last scheduled
solve's map, a fixed-lag window's on a long run).

One simulated stream (``--steps`` steps of ``paper_design(seed)[0]``, the stream of
``bench_speed.py --sections long``), or ``--stream FILE.jsonl`` with ``--preset``. Each GTSAM
method runs ``--repeats`` times per variant, in alternating order (A B B A ...), at the default
cadence. Per run: CPU seconds (``time.process_time``, single-threaded BLAS), the final MPE
(cm), ``info["converged"]``, the first solver pass (``window`` for a window's solution) and,
for the LM mappers, the final values' cost on the whole graph, every bearing in
(``state.graph``). The medians are printed and saved as JSON.

With ``--mc K``: K small simulated worlds instead (:func:`monte_carlo`), ``gtsam-batch`` with
and without ``finish()`` against the oracle's whole-graph solves.

Usage::

    python scripts/bench_finish.py [--steps 3000] [--repeats 1]
        [--methods gtsam-batch,gtsam-isam2,hybrid,hybrid-isam2,oracle] [--out FILE.json]
    python scripts/bench_finish.py --mc 12 --steps 300 --long-after 60
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

from bomgraph.errors import BomgraphError  # noqa: E402
from bomgraph.evaluate import score_estimate  # noqa: E402
from bomgraph.mapper import create_mapper, run  # noqa: E402
from bomgraph.sim import SimConfig, paper_design, simulate_run  # noqa: E402
from bomgraph.stream import Stream  # noqa: E402
from bomgraph.stream_file import read_stream  # noqa: E402

METHODS = "gtsam-batch,gtsam-isam2,hybrid,hybrid-isam2,oracle"


def one_run(stream: Stream, method: str, finish: bool, preset: str | None) -> dict[str, Any]:
    """One run of ``method``, with or without ``finish()``."""
    options = {"preset": preset} if preset else {}
    mapper = create_mapper(method, stream.header, truth=stream.truth, **options)
    if not finish:
        mapper.finish = None      # run() then takes the last scheduled solve's map
    c0 = time.process_time()
    final = run(mapper, stream.steps, checkpoint_every=10, keep_checkpoints=False).final
    cpu = time.process_time() - c0
    try:
        mpe = 100 * score_estimate(final, stream.truth).mpe_m
    except BomgraphError:
        mpe = float("nan")
    row = {"method": method, "finish": finish, "cpu_s": cpu, "mpe_cm": mpe,
           "n_mapped": len(final), "converged": final.info.get("converged"),
           "first_pass": (final.info.get("passes") or [None])[0]}
    state = getattr(mapper, "state", None)
    if state is not None:     # the whole graph, every bearing in
        row["cost"] = float(state.graph.error(state.values))
    return row


def monte_carlo(worlds: int, n_steps: int, long_after: int) -> list[dict[str, Any]]:
    """``worlds`` small simulated worlds (30 landmarks, seeds 100, 101, ...): ``gtsam-batch``
    with its long mode from ``long_after`` steps (a 20-pose window, a whole-graph solve when
    the graph has doubled) with and without ``finish()``, and the oracle without the long
    mode (whole-graph solves from the truth): final MPE in cm of each."""
    from bomgraph.sim import simulate
    import numpy as np

    long = {"lag_after_steps": long_after, "lag_steps": 20, "full_growth": 2.0}
    rows = []
    for k in range(worlds):
        stream = simulate(SimConfig(n_steps=n_steps, n_landmarks=30),
                          np.random.default_rng(100 + k))
        row: dict[str, Any] = {"seed": 100 + k}
        for finish in (True, False):
            mapper = create_mapper("gtsam-batch", stream.header, **long)
            if not finish:
                mapper.finish = None
            final = run(mapper, stream.steps).final
            row["finish" if finish else "window"] = 100 * score_estimate(final,
                                                                         stream.truth).mpe_m
        oracle = run(create_mapper("oracle", stream.header, truth=stream.truth,
                                   lag_after_steps=10 ** 9), stream.steps).final
        row["oracle_whole"] = 100 * score_estimate(oracle, stream.truth).mpe_m
        print(json.dumps(row), flush=True)
        rows.append(row)
    for key in ("finish", "window"):
        gaps = [abs(r[key] - r["oracle_whole"]) for r in rows]
        print(f"{key}: mean MPE {statistics.mean(r[key] for r in rows):.4f} cm, "
              f"|MPE - oracle's| mean {statistics.mean(gaps):.4f}, max {max(gaps):.4f} cm")
    print(f"oracle (whole graph): mean MPE {statistics.mean(r['oracle_whole'] for r in rows):.4f} cm")
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--stream", help="a stream file instead of the simulated run")
    ap.add_argument("--preset")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--methods", default=METHODS)
    ap.add_argument("--out")
    ap.add_argument("--mc", type=int, default=0, metavar="K",
                    help="instead: K small worlds of --steps steps, gtsam-batch in long mode "
                         "from --long-after (monte_carlo)")
    ap.add_argument("--long-after", type=int, default=60)
    args = ap.parse_args(argv)
    if args.mc:
        rows = monte_carlo(args.mc, args.steps, args.long_after)
        if args.out:
            with open(args.out, "w") as fh:
                json.dump({"monte_carlo": rows}, fh, indent=1)
        return 0
    stream = (read_stream(args.stream) if args.stream else
              simulate_run(paper_design(args.seed)[0], SimConfig(n_steps=args.steps)))
    rows: list[dict[str, Any]] = []
    for method in args.methods.split(","):
        for r in range(args.repeats):
            for finish in ((True, False) if r % 2 == 0 else (False, True)):
                row = one_run(stream, method, finish, args.preset)
                rows.append(row)
                print(json.dumps(row), flush=True)
    print(f"\n{'method':14s} {'finish':6s} {'CPU s':>7s} {'MPE cm':>8s} {'cost':>12s} "
          f"converged, first pass")
    summary = []
    for method in args.methods.split(","):
        for finish in (True, False):
            rs = [r for r in rows if r["method"] == method and r["finish"] == finish]
            s = {"method": method, "finish": finish,
                 "cpu_s": statistics.median(r["cpu_s"] for r in rs),
                 "mpe_cm": rs[0]["mpe_cm"], "cost": rs[0].get("cost"),
                 "converged": rs[0]["converged"], "first_pass": rs[0]["first_pass"]}
            summary.append(s)
            cost = f"{s['cost']:12.3f}" if s["cost"] is not None else f"{'-':>12s}"
            print(f"{method:14s} {str(finish):6s} {s['cpu_s']:7.2f} {s['mpe_cm']:8.4f} {cost} "
                  f"{s['converged']}, {s['first_pass']}")
    if args.out:
        with open(args.out, "w") as fh:
            json.dump({"steps": len(stream.steps), "stream": args.stream, "rows": rows,
                       "summary": summary}, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
