"""CPU time of BOM-STMDS on long recordings (issue 14, item 2), with a hash of its maps.

    python scripts/bench_stmds_long.py [STREAM ...] [--method stmds-smacof] [--preset real]
                                       [--every 0] [--steps N] [--repeats 1]

Runs the method over each stream file (default: GTSAM's Victoria Park, imported from the shared
data folder, ``BOMGRAPH_DATA``, into a temporary file) through :func:`bomgraph.mapper.run`,
single-threaded BLAS, and prints per stream the process CPU seconds of the run (the smallest
of ``--repeats``) and a SHA-256 of every checkpoint's map (landmark ids, coordinates, pose
steps and poses as raw bytes), so two trees can be compared for speed and for bit-identical
results in one call each. ``--every 0`` (default) asks for the map at the last step only;
``--every 10`` every 10 steps. ``--steps N`` cuts each stream to its first N steps.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from bomgraph.datasets.victoria import import_victoria  # noqa: E402
from bomgraph.mapper import create_mapper, run  # noqa: E402
from bomgraph.stream_file import read_stream  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("BOMGRAPH_DATA", ROOT.parent / "shared" / "data"))
VICTORIA = DATA / "victoria_park" / "victoria_park.txt"


def map_hash(result) -> str:
    """SHA-256 over every checkpoint's ids, coordinates, pose steps and poses (raw bytes)."""
    h = hashlib.sha256()
    for cp in result.checkpoints:
        est = cp.estimate
        h.update(str(cp.t).encode())
        for arr in (est.landmark_ids, est.landmarks_xy, est.pose_t, est.poses):
            if arr is not None:
                a = np.ascontiguousarray(arr)
                h.update(str((a.dtype.str, a.shape)).encode())
                h.update(a.tobytes())
    return h.hexdigest()


def bench(steps, header, method: str, options: dict, every: int) -> tuple[float, str, int]:
    """``(CPU s, map hash, landmarks in the final map)`` of one run."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        mapper = create_mapper(method, header, **options)
        t0 = time.process_time()
        result = run(mapper, steps, checkpoint_every=every if every > 0 else len(steps) + 1)
        cpu = time.process_time() - t0
    return cpu, map_hash(result), len(result.final.landmark_ids)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("streams", nargs="*", help="stream files (default: Victoria Park)")
    ap.add_argument("--method", default="stmds-smacof")
    ap.add_argument("--preset", default="real")
    ap.add_argument("--every", type=int, default=0, help="map every N steps (0: at the end)")
    ap.add_argument("--steps", type=int, default=None, help="the first N steps only")
    ap.add_argument("--repeats", type=int, default=1)
    args = ap.parse_args(argv)
    options = {"preset": args.preset} if args.preset else {}
    with tempfile.TemporaryDirectory() as tmp:
        paths = [Path(p) for p in args.streams]
        loaded = []
        if not paths:
            stream = import_victoria(VICTORIA)
            loaded.append(("victoria_park", stream))
        for p in paths:
            loaded.append((p.name, read_stream(p)))
        for name, stream in loaded:
            steps = list(stream.steps)[:args.steps]
            best = None
            for _ in range(args.repeats):
                cpu, digest, n_lm = bench(steps, stream.header, args.method, options,
                                          args.every)
                best = cpu if best is None else min(best, cpu)
            print(f"{name}: {len(steps)} steps, {args.method}"
                  f"{'@' + args.preset if args.preset else ''}, every "
                  f"{args.every or 'end'}: CPU {best:.2f} s, {n_lm} landmarks, "
                  f"maps sha256 {digest[:16]}", flush=True)
        del tmp
    return 0


if __name__ == "__main__":
    sys.exit(main())
