"""Instructions of one paper run per method, counted by valgrind's callgrind (issue 14).

A machine-independent measure of a change's cost where wall or CPU time is too noisy (the
machines are shared): each method's run of ``paper_design(0)[RUN]`` (a map every 10 steps)
is run in a fresh ``python`` under ``valgrind --tool=callgrind`` with ``PYTHONHASHSEED=0``,
and a run that only simulates, imports the method and builds its mapper (``import:METHOD``:
bomgraph, the method's module, gtsam or filterpy, a hybrid's seed) is subtracted. Each child
also prints a digest of its final map (landmarks and poses, bit for bit), so two trees'
counts are compared only where they give the same map. Valgrind emulates the CPU: the maps
it gives can differ in the last bits from a native run's, and a run takes about 50x its
native time (about 8 minutes for ``gtsam-isam2``).

    python scripts/count_instructions.py --methods gtsam-isam2,gtsam-batch --out counts.json

Prints one row per method (instructions of the run, in millions, and the map's digest) and
saves them as JSON. Exit 2 if valgrind is missing.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def child(method: str, run_index: int) -> None:
    """The measured process: simulate the run, import ``method``'s factory (with it the
    libraries it uses) and build its mapper (a hybrid's seed with it), then map the run with
    it; ``import:METHOD``: all but the map, the run subtracted from ``METHOD``'s."""
    sys.path.insert(0, str(ROOT))
    import numpy as np

    from bomgraph.mapper import create_mapper, method_factory, run
    from bomgraph.sim import paper_design, simulate_run
    stream = simulate_run(paper_design(0)[run_index])
    only_import = method.startswith("import:")
    method = method.removeprefix("import:")
    factory = method_factory(method)
    # built in both runs: a hybrid imports its seed's module (bomgraph.stmds) as it builds it
    mapper = create_mapper(method, stream.header, truth=stream.truth)
    if only_import:
        print(f"digest import {factory.__module__}")
        return
    final = run(mapper, stream.steps, checkpoint_every=10, keep_checkpoints=False).final
    # a map without poses (stmds-cs, stmds-smacof) hashes no poses: the bytes of
    # np.asarray(None) are None's address, another in every process
    poses = b"" if final.poses is None else np.ascontiguousarray(final.poses).tobytes()
    digest = hashlib.sha1(np.ascontiguousarray(final.landmarks_xy).tobytes()
                          + poses).hexdigest()[:16]
    print(f"digest {digest} landmarks {len(final)}")


def count(method: str, run_index: int) -> tuple[int, str]:
    """Instructions of a child process running ``method``, and its digest line."""
    env = {**os.environ, "PYTHONHASHSEED": "0", "OMP_NUM_THREADS": "1"}
    proc = subprocess.run(
        ["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null", sys.executable,
         __file__, "--child", method, "--run", str(run_index)],
        capture_output=True, text=True, env=env, check=False)
    found = re.search(r"Collected\s*:\s*(\d+)", proc.stderr)
    digest = next((ln for ln in proc.stdout.splitlines() if ln.startswith("digest")), "")
    if proc.returncode != 0 or found is None:
        tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        raise SystemExit(f"count_instructions: {method}: the child failed: {tail}")
    return int(found.group(1)), digest.removeprefix("digest ").strip()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--methods", default="gtsam-isam2",
                    help="comma-separated method names (default: gtsam-isam2)")
    ap.add_argument("--run", type=int, default=0, help="index into paper_design(0)")
    ap.add_argument("--out", type=Path, help="write the counts here as JSON")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child(args.child, args.run)
        return 0
    if args.out is not None and args.out.exists():
        print(f"count_instructions: {args.out} exists; give a new --out", file=sys.stderr)
        return 2
    if shutil.which("valgrind") is None:
        print("count_instructions: valgrind is not installed (apt install valgrind)",
              file=sys.stderr)
        return 2
    rows = []
    for method in [m.strip() for m in args.methods.split(",") if m.strip()]:
        base, _ = count(f"import:{method}", args.run)
        total, digest = count(method, args.run)
        rows.append({"method": method, "run": args.run, "instructions": total - base,
                     "baseline_instructions": base, "digest": digest})
        print(f"{method:16s} {(total - base) / 1e6:10.1f} M instructions   {digest}",
              flush=True)
    if args.out is not None:
        args.out.write_text(json.dumps({"rows": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
