"""Compare the paper runs' maps of two checkouts to a tolerance (for changes that are not bit
for bit, e.g. a re-associated sum): every checkpoint (a map every 10 steps) of the first
``--runs`` runs of the paper's design (seed 0) for each ``--method`` / ``--preset``.

Run it once per checkout to dump the checkpoints, then compare::

    PYTHONPATH=/work/main python scripts/check_close.py --dump /tmp/old.npz --preset window-ba
    PYTHONPATH=$PWD       python scripts/check_close.py --dump /tmp/new.npz --preset window-ba
    python scripts/check_close.py --compare /tmp/old.npz /tmp/new.npz [--tol-m 1e-9]

A checkpoint matches when the landmark ids are the same and every coordinate agrees to
``--tol-m`` metres; the comparison prints the largest difference and the number of
checkpoints that differ, and exits 1 when any does.
"""

from __future__ import annotations

import argparse
import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402


def dump(path: str, method: str, preset: str | None, runs: int) -> None:
    from bomgraph.mapper import create_mapper, run
    from bomgraph.sim import paper_design, simulate_run

    out: dict[str, np.ndarray] = {}
    opts = {} if preset is None else {"preset": preset}
    for r, spec in enumerate(paper_design(0)[:runs]):
        stream = simulate_run(spec)
        mapper = create_mapper(method, stream.header, truth=stream.truth, **opts)
        result = run(mapper, stream.steps, checkpoint_every=10)
        for cp in result.checkpoints:
            out[f"{r}/{cp.t}/ids"] = np.asarray(cp.estimate.landmark_ids, np.int64)
            out[f"{r}/{cp.t}/xy"] = np.asarray(cp.estimate.landmarks_xy, float).reshape(-1, 2)
    np.savez(path, **out)


def compare(old_path: str, new_path: str, tol_m: float) -> int:
    old, new = np.load(old_path), np.load(new_path)
    keys = sorted({k.rsplit("/", 1)[0] for k in old.files})
    if set(old.files) != set(new.files):
        print(f"checkpoints differ: {len(old.files)} vs {len(new.files)} arrays")
        return 1
    worst, n_bad, n_bits = 0.0, 0, 0
    for key in keys:
        ids_o, ids_n = old[f"{key}/ids"], new[f"{key}/ids"]
        xy_o, xy_n = old[f"{key}/xy"], new[f"{key}/xy"]
        if ids_o.shape != ids_n.shape or np.any(ids_o != ids_n):
            print(f"{key}: landmark ids differ ({ids_o.size} vs {ids_n.size})")
            n_bad += 1
            continue
        diff = float(np.max(np.abs(xy_o - xy_n))) if xy_o.size else 0.0
        n_bits += int(xy_o.tobytes() == xy_n.tobytes())
        worst = max(worst, diff)
        if not diff <= tol_m:
            print(f"{key}: coordinates differ by {diff:.3g} m")
            n_bad += 1
    print(f"{len(keys)} checkpoints: {len(keys) - n_bad} within {tol_m:g} m with the same ids "
          f"({n_bits} bit for bit); largest difference {worst:.3g} m")
    return int(n_bad > 0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dump", help="write this checkout's checkpoints to this .npz")
    ap.add_argument("--compare", nargs=2, metavar=("OLD", "NEW"))
    ap.add_argument("--method", default="stmds-smacof")
    ap.add_argument("--preset", default=None)
    ap.add_argument("--runs", type=int, default=25)
    ap.add_argument("--tol-m", type=float, default=1e-9)
    args = ap.parse_args(argv)
    if args.dump:
        dump(args.dump, args.method, args.preset, args.runs)
    if args.compare:
        return compare(*args.compare, args.tol_m)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
