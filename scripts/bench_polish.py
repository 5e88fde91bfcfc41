"""CPU of the iSAM2 mappers' ``estimate()`` polish, two source trees against each other (issue 14).

Each paper run (seed 0, ``paper_design(0)``, 300 steps, map every 10 steps) is mapped by each
method once per tree per repetition, in a fresh process whose ``PYTHONPATH`` is that tree (the
trees alternate, and their order flips every repetition, so a drift of the machine's load
falls on both). A child times ``run()`` and, inside it, every call of
:func:`baselines.lm_report.polish` (``time.process_time``, single-threaded BLAS), counts the
polish calls and whole-graph linearisations, and hashes every checkpoint's estimate (landmark
ids and points, poses; raw float64 bytes) and scores its MPE.

The parent prints, per method and tree, the sum over the runs of each run's median CPU (whole
run and polish), the polish steps, the median of the per-run ratios against the first tree,
how many runs have every checkpoint bit for bit the same as under the first tree, and the
largest relative MPE change of a checkpoint.

Usage::

    OMP_NUM_THREADS=1 python scripts/bench_polish.py --trees /work/main . --runs 0-24 --reps 3
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import hashlib  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

METHODS = ("gtsam-isam2", "hybrid-isam2")


def child(method: str, index: int) -> dict[str, Any]:
    """One timed run in this process (the tree is whatever ``PYTHONPATH`` imports)."""
    import gtsam
    import numpy as np

    import baselines.isam2 as isam2
    import baselines.isam2_window as isam2_window
    import bomgraph
    from bomgraph.errors import BomgraphError
    from bomgraph.evaluate import score_estimate
    from bomgraph.mapper import create_mapper, run
    from bomgraph.sim import paper_design, simulate_run

    counts = {"calls": 0, "linearize": 0, "cpu": 0.0}
    inner = isam2.polish

    class Counted:
        """The graph handed to ``polish``, counting its linearisations."""

        def __init__(self, graph: gtsam.NonlinearFactorGraph) -> None:
            self.graph = graph

        def linearize(self, values: gtsam.Values) -> gtsam.GaussianFactorGraph:
            counts["linearize"] += 1
            return self.graph.linearize(values)

        def __getattr__(self, name: str) -> Any:
            return getattr(self.graph, name)

    def timed(graph: Any, *args: Any, **kwargs: Any) -> Any:
        c0 = time.process_time()
        try:
            return inner(Counted(graph), *args, **kwargs)
        finally:
            counts["cpu"] += time.process_time() - c0
            counts["calls"] += 1

    isam2.polish = timed            # type: ignore[assignment]
    isam2_window.polish = timed     # type: ignore[assignment]
    design = paper_design(0)
    stream = simulate_run(design[index])
    mapper = create_mapper(method, stream.header, truth=stream.truth)
    c0 = time.process_time()
    result = run(mapper, stream.steps, checkpoint_every=10)
    cpu = time.process_time() - c0
    hashes, mpe = [], []
    for cp in result.checkpoints:
        est = cp.estimate
        h = hashlib.sha256()
        for a in (est.landmark_ids, est.landmarks_xy, est.pose_t, est.poses):
            if a is not None:
                h.update(np.ascontiguousarray(a).tobytes())
        hashes.append(h.hexdigest()[:16])
        try:
            mpe.append(float(score_estimate(est, stream.truth).mpe_m))
        except BomgraphError:
            mpe.append(float("nan"))
    return {"tree": str(Path(bomgraph.__file__).resolve().parents[1]), "method": method,
            "run": design[index].name, "cpu_s": cpu, "polish_s": counts["cpu"],
            "polish_calls": counts["calls"], "linearize": counts["linearize"],
            "t": [cp.t for cp in result.checkpoints], "mpe_m": mpe, "hashes": hashes,
            "converged": result.checkpoints[-1].estimate.info.get("converged")}


def spawn(tree: str, method: str, index: int) -> dict[str, Any]:
    env = dict(os.environ, PYTHONPATH=tree, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    out = subprocess.run([sys.executable, __file__, "--child", method, str(index)], env=env,
                         check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def parse_runs(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out.extend(range(int(a), int(b) + 1) if b else [int(a)])
    return out


def summary(rows: list[dict[str, Any]], trees: list[str]) -> str:
    """Per method and tree: sums of per-run medians, paired ratios, identical runs."""
    lines = []
    for method in sorted({r["method"] for r in rows}):
        per: dict[str, dict[str, list[dict[str, Any]]]] = {}
        for r in rows:
            if r["method"] == method:
                per.setdefault(r["tree"], {}).setdefault(r["run"], []).append(r)
        base = per[trees[0]]
        for tree in trees:
            mine = per[tree]
            runs = sorted(set(mine) & set(base))
            med = {n: statistics.median(r["cpu_s"] for r in mine[n]) for n in runs}
            pmed = {n: statistics.median(r["polish_s"] for r in mine[n]) for n in runs}
            ratio = [med[n] / statistics.median(r["cpu_s"] for r in base[n]) for n in runs]
            steps = sum(mine[n][0]["linearize"] for n in runs)
            calls = sum(mine[n][0]["polish_calls"] for n in runs)
            same = sum(all(r["hashes"] == base[n][0]["hashes"] for r in mine[n]) for n in runs)
            worst = 0.0
            for n in runs:
                for a, b in zip(mine[n][0]["mpe_m"], base[n][0]["mpe_m"]):
                    if a == a and b == b and b:
                        worst = max(worst, abs(a - b) / b)
            conv = sum(bool(mine[n][0]["converged"]) for n in runs)
            lines.append(f"{method:13s} {tree}: runs {len(runs)} cpu {sum(med.values()):7.2f} s "
                         f"(median ratio x{statistics.median(ratio):.3f}) polish "
                         f"{sum(pmed.values()):6.2f} s, {calls} calls, {steps} linearisations; "
                         f"identical {same}/{len(runs)}, worst MPE change {worst:.2e}, "
                         f"converged at the end {conv}/{len(runs)}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--child", nargs=2, metavar=("METHOD", "RUN"), help=argparse.SUPPRESS)
    ap.add_argument("--trees", nargs="+", default=[str(Path(__file__).resolve().parents[1])],
                    help="source trees (the first is the reference)")
    ap.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS))
    ap.add_argument("--runs", default="0-2", help="paper run indices, e.g. 0-24 or 0,3,5")
    ap.add_argument("--reps", type=int, default=3, help="repetitions per run and tree")
    ap.add_argument("--out", help="write the rows (JSON) here")
    ap.add_argument("--summarize", help="only summarise the rows of this JSON file")
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.child[0], int(args.child[1]))))
        return 0
    trees = [str(Path(t).resolve()) for t in args.trees]
    if args.summarize:
        print(summary(json.load(open(args.summarize)), trees))
        return 0
    rows: list[dict[str, Any]] = []
    for index in parse_runs(args.runs):
        for rep in range(args.reps):
            for method in args.methods:
                for tree in (trees if rep % 2 == 0 else trees[::-1]):
                    r = spawn(tree, method, index)
                    if r["tree"] != tree:
                        raise SystemExit(f"the child imported {r['tree']}, not {tree}: "
                                         f"is the tree a bomgraph checkout?")
                    rows.append(r)
                    print(f"{method:13s} {r['run']} rep {rep} {tree}: cpu {r['cpu_s']:.3f} s "
                          f"polish {r['polish_s']:.3f} s ({r['linearize']} linearisations)",
                          flush=True)
            if args.out:
                with open(args.out, "w") as f:
                    json.dump(rows, f)
    print(summary(rows, trees))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
