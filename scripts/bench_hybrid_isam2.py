"""``hybrid-isam2`` beside ``gtsam-isam2`` and ``hybrid``, checkpoint by checkpoint (issue 16).

Runs each method on the paper's 25 runs (``bomgraph.sim.paper_design(0)``, 300 steps, the
setup of Exp. 1) and/or on MRCLAM6 streams (``--streams m6_r1.jsonl ...``), maps every 10
steps, and prints per checkpoint ``t``: the mean landmark MPE (cm; rigid alignment with
reflection), the number of landmarks mapped, and the MPE over the landmarks *both*
``gtsam-isam2`` and the method map at that checkpoint (``common``), so that a method that maps
more (hard) landmarks earlier is not judged on different landmarks only. The same numbers go
to JSON (``--out``). CPU seconds per run (``time.process_time``, single-threaded BLAS) are
printed as the ratio to ``gtsam-isam2``.

Usage::

    python scripts/bench_hybrid_isam2.py [--runs 25] [--jobs 2] [--streams FILE ...]
        [--methods gtsam-isam2 hybrid-isam2 hybrid] [--option METHOD:key=value ...]
        [--preset METHOD:NAME ...] [--out results/bench_hybrid_isam2.json]
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from multiprocessing import Pool  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any, Sequence  # noqa: E402

import numpy as np  # noqa: E402

from bomgraph.errors import EvaluationError  # noqa: E402
from bomgraph.evaluate import score_estimate  # noqa: E402
from bomgraph.jsonio import parse_options  # noqa: E402
from bomgraph.mapper import create_mapper, run  # noqa: E402
from bomgraph.sim import SimConfig, paper_design, simulate_run  # noqa: E402
from bomgraph.stream_file import read_stream  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = "gtsam-isam2"


def one(job: tuple[str, str, dict[str, Any], str, int]) -> dict[str, Any]:
    """Run ``label`` (method + options) on one source; per checkpoint, landmark errors."""
    label, method, options, source, every = job
    if source.startswith("paper:"):
        spec = paper_design(0)[int(source.split(":")[1])]
        stream = simulate_run(spec, SimConfig())
    else:
        stream = read_stream(source)
    t0 = time.process_time()
    result = run(create_mapper(method, stream.header, **options), stream.steps,
                 checkpoint_every=every)
    cpu = time.process_time() - t0
    cps = []
    for c in result.checkpoints:
        try:
            s = score_estimate(c.estimate, stream.truth)
            err = {str(i): e for i, e in zip(s.landmark_ids.tolist(), s.errors_m.tolist())}
        except EvaluationError:
            err = {}
        cps.append({"t": c.t, "n_mapped": len(c.estimate), "errors": err})
    return {"label": label, "source": source, "cpu_s": cpu, "checkpoints": cps,
            "info": {k: v for k, v in result.final.info.items()
                     if isinstance(v, (int, float, str, bool))}}


def summarise(rows: Sequence[dict[str, Any]], labels: Sequence[str]) -> dict[str, Any]:
    """Per label and checkpoint t: mean MPE (cm), mean mapped, MPE on the landmarks common
    with the reference at that checkpoint, runs with a map; and the CPU ratio."""
    by = {(r["label"], r["source"]): r for r in rows}
    sources = sorted({r["source"] for r in rows})
    out: dict[str, Any] = {}
    for lab in labels:
        table: dict[int, dict[str, float]] = {}
        for src in sources:
            r, ref = by.get((lab, src)), by.get((REFERENCE, src))
            if r is None:
                continue
            ref_cp = {c["t"]: c for c in ref["checkpoints"]} if ref else {}
            for c in r["checkpoints"]:
                row = table.setdefault(c["t"], {"mpe": [], "n": [], "common": [], "maps": 0})
                row["n"].append(c["n_mapped"])
                if c["errors"]:
                    row["maps"] += 1
                    row["mpe"].append(float(np.mean(list(c["errors"].values()))))
                rc = ref_cp.get(c["t"])
                if rc and rc["errors"] and c["errors"]:
                    common = set(c["errors"]) & set(rc["errors"])
                    if common:
                        row["common"].append(float(np.mean([c["errors"][k] for k in common])))
        out[lab] = {t: {"mpe_cm": 100 * _mean(v["mpe"]), "mapped": _mean(v["n"]),
                        "common_mpe_cm": 100 * _mean(v["common"]), "runs_with_map": v["maps"]}
                    for t, v in sorted(table.items())}
        cpu = [by[(lab, s)]["cpu_s"] for s in sources if (lab, s) in by]
        ref_cpu = [by[(REFERENCE, s)]["cpu_s"] for s in sources if (REFERENCE, s) in by]
        out[lab]["cpu_ratio"] = (float(np.sum(cpu) / np.sum(ref_cpu)) if ref_cpu and cpu
                                 else math.nan)
    return out


def _mean(v: Sequence[float]) -> float:
    return float(np.mean(v)) if len(v) else math.nan


def print_summary(summary: dict[str, Any], ts: Sequence[int]) -> None:
    head = f"{'method':<28}" + "".join(f"{'t=' + str(t):>22}" for t in ts) + f"{'cpu x':>8}"
    print(head)
    print(" " * 28 + "".join(f"{'MPE/common (mapped)':>22}" for _ in ts))
    for lab, rows in summary.items():
        cells = []
        for t in ts:
            r = rows.get(t)
            cells.append(f"{r['mpe_cm']:7.2f}/{r['common_mpe_cm']:6.2f} ({r['mapped']:5.1f})"
                         if r else f"{'-':>21}")
        print(f"{lab:<28}" + "".join(f"{c:>22}" for c in cells)
              + f"{rows['cpu_ratio']:>8.2f}")


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--methods", nargs="+", default=[REFERENCE, "hybrid-isam2", "hybrid"])
    ap.add_argument("--runs", type=int, default=25, help="paper runs (0 for none)")
    ap.add_argument("--streams", nargs="*", default=[], help="stream files (e.g. MRCLAM6)")
    ap.add_argument("--every", type=int, default=10)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--option", action="append", default=[], metavar="LABEL:key=value")
    ap.add_argument("--preset", action="append", default=[], metavar="LABEL:NAME")
    ap.add_argument("--variant", action="append", default=[], metavar="LABEL=METHOD",
                    help="an extra arm LABEL running METHOD (give it options by LABEL)")
    ap.add_argument("--ts", default="10,20,30,40,50,100,200,300")
    ap.add_argument("--out", default=str(ROOT / "results" / "bench_hybrid_isam2.json"))
    args = ap.parse_args(argv)
    arms: dict[str, tuple[str, dict[str, Any]]] = {m: (m, {}) for m in args.methods}
    for v in args.variant:
        lab, _, m = v.partition("=")
        arms[lab] = (m, {})
    for item in args.option:
        lab, _, kv = item.partition(":")
        arms[lab][1].update(parse_options([kv]))
    for item in args.preset:
        lab, _, name = item.partition(":")
        arms[lab][1]["preset"] = name
    if REFERENCE not in arms:
        arms[REFERENCE] = (REFERENCE, {})
    sources = [f"paper:{i}" for i in range(args.runs)] + list(args.streams)
    jobs = [(lab, m, o, s, args.every) for lab, (m, o) in arms.items() for s in sources]
    # finished runs are appended to OUT.rows.jsonl as they come and reused by the next call
    # with the same arms (delete the file after changing the code)
    rows_path = Path(args.out).with_suffix(".rows.jsonl")
    rows_path.parent.mkdir(parents=True, exist_ok=True)
    done = {}
    if rows_path.exists():
        for line in rows_path.read_text().splitlines():
            r = json.loads(line)
            done[(r["label"], r["source"], json.dumps(r["options"], sort_keys=True))] = r
    key = lambda j: (j[0], j[3], json.dumps(j[2], sort_keys=True))  # noqa: E731
    rows = [done[key(j)] for j in jobs if key(j) in done]
    todo = [j for j in jobs if key(j) not in done]
    with Pool(args.jobs) as pool, rows_path.open("a") as fh:
        for j, r in zip(todo, pool.imap(one, todo, chunksize=1)):
            r["options"] = j[2]
            fh.write(json.dumps(r) + "\n")
            fh.flush()
            rows.append(r)
    summary = summarise(rows, list(arms))
    print_summary(summary, [int(t) for t in args.ts.split(",")])
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    per_source = {f"{r['label']} | {r['source']}": {
        "cpu_s": r["cpu_s"], "t": [c["t"] for c in r["checkpoints"]],
        "n_mapped": [c["n_mapped"] for c in r["checkpoints"]],
        "mpe_cm": [100 * float(np.mean(list(c["errors"].values()))) if c["errors"] else None
                   for c in r["checkpoints"]]} for r in rows}
    for key, v in per_source.items():
        if not key.split(" | ")[1].startswith("paper:"):
            last = v["mpe_cm"][-1]
            print(f"final {key}: t = {v['t'][-1]}, "
                  f"MPE {'-' if last is None else f'{last:.1f}'} cm ({v['n_mapped'][-1]})")
    Path(args.out).write_text(json.dumps({"arms": {k: [m, o] for k, (m, o) in arms.items()},
                                          "sources": sources, "summary": summary,
                                          "per_source": per_source},
                                         indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
