"""Peak memory and time of ``bomgraph evaluate`` as the stream grows (h62): it reads the
stream once and keeps no steps, so its peak should grow with the poses and landmarks (the
header's truth, the estimate) and not with the bearings.

For each step count: simulate a stream (``--seed 1``), run ``triangulate`` on it (final
checkpoint only), then time ``bomgraph evaluate EST STREAM`` in a child process and read its
peak resident set size (``getrusage`` of the children of a fresh wrapper process). Prints one
line per size and writes them as JSON with ``--out``.

Usage: ``python scripts/bench_evaluate_memory.py [--steps 3000 30000] [--dir DIR] [--out F]``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

#: runs ``argv`` and prints the peak RSS [KB] of it (the wrapper's only child)
_PEAK = ("import resource, subprocess, sys\n"
         "subprocess.run(sys.argv[1:], check=True, stdout=subprocess.DEVNULL)\n"
         "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)")


def _bomgraph(*args: str) -> list[str]:
    return [sys.executable, "-m", "bomgraph", *args]


def measure(steps: int, where: str) -> dict[str, float]:
    stream = os.path.join(where, f"s{steps}.jsonl")
    est = os.path.join(where, f"e{steps}.json")
    if not os.path.exists(stream):
        subprocess.run(_bomgraph("simulate", "--out", stream, "--steps", str(steps),
                                 "--seed", "1"), check=True, stdout=subprocess.DEVNULL)
    if not os.path.exists(est):
        subprocess.run(_bomgraph("run", "-q", stream, "--method", "triangulate", "--out", est,
                                 "--checkpoint-every", str(10 * steps)),
                       check=True, stdout=subprocess.DEVNULL)
    start = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", _PEAK, *_bomgraph("evaluate", est, stream)],
                         check=True, capture_output=True, text=True).stdout
    return {"steps": steps, "stream_mb": os.path.getsize(stream) / 1e6,
            "peak_kb": int(out.split()[-1]), "seconds": time.perf_counter() - start}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, nargs="+", default=[3000, 30000])
    ap.add_argument("--dir", help="keep the streams and estimates here (default: a temporary "
                                  "directory)")
    ap.add_argument("--out", help="write the rows as JSON here")
    args = ap.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    with tempfile.TemporaryDirectory() as tmp:
        where = args.dir or tmp
        os.makedirs(where, exist_ok=True)
        rows = []
        for n in args.steps:
            row = measure(n, where)
            rows.append(row)
            print(f"{row['steps']:>8} steps, {row['stream_mb']:8.1f} MB stream: evaluate peak "
                  f"{row['peak_kb']:,} KB, {row['seconds']:.2f} s", flush=True)
    if args.out:
        with open(args.out, "w") as fh:
            json.dump(rows, fh, indent=1)


if __name__ == "__main__":
    main()
