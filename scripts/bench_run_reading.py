"""CPU and peak memory of ``bomgraph run STREAM --method M --out EST``, two source trees against
each other (h71, issue 14): ``run`` read and validated the stream twice, once for its identity
(the estimate header's SHA-256 of the steps) and once for the run.

For each step count a stream is simulated once (``bomgraph simulate --steps N --seed 1``, by the
first tree), then each method runs on it once per tree per repetition, in a fresh process whose
``PYTHONPATH`` is that tree (the trees alternate, their order flipping every repetition, so a
drift of the machine's load falls on both). A wrapper process reads the child's CPU
(user + system) and peak RSS (``getrusage`` of its children). The estimate files of the trees
are compared byte for byte with the timings (``estimate_s``, ``timing_s``) blanked: they must
be the same.

Prints, per step count and method, each tree's median CPU and peak RSS and its ratio to the
first tree's.

Usage::

    OMP_NUM_THREADS=1 python scripts/bench_run_reading.py --trees /work/main . \\
        --steps 30000 300000 --methods triangulate stmds-smacof --reps 1
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

#: runs ``argv`` and prints the CPU seconds and peak RSS [KB] of it (the wrapper's only child)
_USAGE = ("import resource, subprocess, sys\n"
          "subprocess.run(sys.argv[1:], check=True, stdout=subprocess.DEVNULL)\n"
          "r = resource.getrusage(resource.RUSAGE_CHILDREN)\n"
          "print(r.ru_utime + r.ru_stime, r.ru_maxrss)")

_TIMINGS = re.compile(rb'"estimate_s":[^,}]*|"timing_s":\{[^}]*\}')


#: the children's working directory: not a tree (``python -c`` imports from it first)
_CWD = os.path.dirname(os.path.abspath(os.sep))


def _env(tree: str) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": tree, "OMP_NUM_THREADS": "1"}


def _bomgraph(*args: str) -> list[str]:
    return [sys.executable, "-m", "bomgraph", *args]


def without_timings(path: str) -> bytes:
    """The file's bytes with every timing blanked (they differ from run to run)."""
    with open(path, "rb") as fh:
        return _TIMINGS.sub(b"T", fh.read())


def measure(tree: str, stream: str, method: str, out: str, every: int) -> dict[str, Any]:
    argv = _bomgraph("run", stream, "--method", method, "--out", out,
                     "--checkpoint-every", str(every))
    text = subprocess.run([sys.executable, "-c", _USAGE, *argv], env=_env(tree), cwd=_CWD,
                          check=True, capture_output=True, text=True).stdout
    cpu, rss = text.split()[-2:]
    return {"tree": tree, "method": method, "stream": stream, "cpu_s": float(cpu),
            "peak_kb": int(rss)}


def summary(rows: list[dict[str, Any]], trees: list[str]) -> str:
    lines = []
    for steps in sorted({r["steps"] for r in rows}):
        for method in sorted({r["method"] for r in rows}):
            mine = [r for r in rows if r["steps"] == steps and r["method"] == method]
            if not mine:
                continue
            base_cpu = statistics.median(r["cpu_s"] for r in mine if r["tree"] == trees[0])
            base_kb = max(r["peak_kb"] for r in mine if r["tree"] == trees[0])
            for tree in trees:
                rs = [r for r in mine if r["tree"] == tree]
                cpu = statistics.median(r["cpu_s"] for r in rs)
                kb = max(r["peak_kb"] for r in rs)
                lines.append(f"{steps:>7} steps {method:<13} {tree:<24.24} CPU {cpu:8.2f} s "
                             f"(x{cpu / base_cpu:.3f})  peak {kb / 1024:7.1f} MB "
                             f"(x{kb / base_kb:.3f})  n={len(rs)}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trees", nargs="+", default=[str(Path(__file__).resolve().parents[1])],
                    help="source trees (the first is the reference)")
    ap.add_argument("--steps", type=int, nargs="+", default=[30000, 300000])
    ap.add_argument("--methods", nargs="+", default=["triangulate", "stmds-smacof"])
    ap.add_argument("--reps", type=int, default=1, help="repetitions per stream, method, tree")
    ap.add_argument("--checkpoint-every", type=int, default=100000)
    ap.add_argument("--dir", help="keep the streams here (default: a temporary directory)")
    ap.add_argument("--out", help="write the rows (JSON) here")
    args = ap.parse_args(argv)
    trees = [str(Path(t).resolve()) for t in args.trees]
    for tree in trees:
        got = subprocess.run([sys.executable, "-c", "import bomgraph; print(bomgraph.__file__)"],
                             env=_env(tree), cwd=_CWD, check=True, capture_output=True,
                             text=True).stdout
        if not got.startswith(tree + os.sep):
            raise SystemExit(f"PYTHONPATH={tree} imports {got.strip()}: not a bomgraph tree?")
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        where = args.dir or tmp
        os.makedirs(where, exist_ok=True)
        for steps in args.steps:
            stream = os.path.join(where, f"s{steps}.jsonl")
            if not os.path.exists(stream):
                subprocess.run(_bomgraph("simulate", "--out", stream, "--steps", str(steps),
                                         "--seed", "1"), env=_env(trees[0]), cwd=_CWD, check=True,
                               stdout=subprocess.DEVNULL)
            for method in args.methods:
                for rep in range(args.reps):
                    for tree in (trees if rep % 2 == 0 else trees[::-1]):
                        est = os.path.join(tmp, f"e{trees.index(tree)}.est")
                        r = measure(tree, stream, method, est, args.checkpoint_every)
                        r.update(steps=steps, rep=rep)
                        rows.append(r)
                        print(f"{steps:>7} {method:<13} rep {rep} {tree}: {r['cpu_s']:.2f} s "
                              f"CPU, {r['peak_kb'] / 1024:.1f} MB", flush=True)
                    same = {without_timings(os.path.join(tmp, f"e{k}.est"))
                            for k in range(len(trees))}
                    if len(same) != 1:
                        raise SystemExit(f"{steps} steps, {method}: the trees' estimate files "
                                         f"differ (beyond their timings)")
    print(summary(rows, trees))
    if args.out:
        with open(args.out, "w") as fh:
            json.dump(rows, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
