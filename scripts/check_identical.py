"""Check that a refactoring changed no result: every method and every named preset on a fixed
set of streams, each run's estimates hashed bit for bit and compared with a reference file.

The streams: three runs of the paper's design (seed 0, layouts 0-2, start 0; Exp. 3 priors on
the first for the priors task), MRCLAM6 robot 3 and the bearing-only g2o set (both read from the
shared data folder); and, for the GTSAM methods' paper settings, the paper's two worlds with two
minima (seed 0, layout 1 start 1 and layout 3 start 0). Every checkpoint of every task (map every 10 steps) is hashed: landmark
ids and coordinates, pose steps and poses, and the covariances, as raw float64 bytes. Timings
and the free-form ``info`` are left out.

Usage::

    python scripts/check_identical.py --write        # make the reference (before a change)
    python scripts/check_identical.py                # compare against it (after)
    python scripts/check_identical.py --only hybrid  # tasks whose label contains 'hybrid'

Exit status 0 when every task matches, 1 otherwise; the table shows each task's final MPE
before and after where they differ.

The reference holds for one machine. On the seventeenth session's machine the committed
reference (written in the sixteenth) matched 110 of 177 tasks before any change: every GTSAM
method on the three simulated streams differed in the last bits (MPE by ~1e-9 relative), the
same code giving the same bits run after run there. So for a change, write a reference from
the tree before it on the same machine first (``--write --reference FILE``, then compare with
``--reference FILE``).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = ROOT / "tests" / "data" / "identical_reference.json"
#: The shared data folder (``BOMGRAPH_DATA`` overrides it, e.g. for a checkout elsewhere).
DATA = Path(os.environ.get("BOMGRAPH_DATA", ROOT.parent / "shared" / "data"))

#: (label, method, options). Options name presets wherever a preset exists.
CONFIGS: list[tuple[str, str, dict[str, Any]]] = [
    ("triangulate", "triangulate", {}),
    ("stmds-cs", "stmds-cs", {}),
    ("stmds-cs@paper-fusion", "stmds-cs", {"fusion": "paper"}),
    ("stmds-cs@improved", "stmds-cs", {"preset": "improved"}),
    ("stmds-cs@real", "stmds-cs", {"preset": "real"}),
    ("stmds-smacof", "stmds-smacof", {}),
    ("stmds-smacof@paper-fusion", "stmds-smacof", {"fusion": "paper"}),
    ("stmds-smacof@improved", "stmds-smacof", {"preset": "improved"}),
    ("stmds-smacof@window", "stmds-smacof", {"preset": "window"}),
    ("stmds-smacof@window-lsq", "stmds-smacof", {"preset": "window-lsq"}),
    ("stmds-smacof@window-ba", "stmds-smacof", {"preset": "window-ba"}),
    # 100-pose windows: the window fit's arrow path (bundle_lm.WindowInverse), which the
    # 10-pose paper windows never take
    ("stmds-smacof@window-ba-long", "stmds-smacof", {"preset": "window-ba-long"}),
    ("stmds-smacof@real", "stmds-smacof", {"preset": "real"}),
    ("stmds-smacof@real-keyframes", "stmds-smacof", {"preset": "real-keyframes"}),
    ("stmds-cs-loc", "stmds-cs-loc", {}),
    ("stmds-smacof-loc", "stmds-smacof-loc", {}),
    ("stmds-smacof-loc@improved", "stmds-smacof-loc", {"preset": "improved"}),
    ("stmds-smacof-loc@real", "stmds-smacof-loc", {"preset": "real"}),
    ("ekf", "ekf", {}),
    ("ekf@real", "ekf", {"preset": "real"}),
    ("ekf-invdepth", "ekf-invdepth", {}),
    ("ekf-invdepth@real", "ekf-invdepth", {"preset": "real"}),
    ("gtsam-batch", "gtsam-batch", {}),
    ("gtsam-batch@robust", "gtsam-batch", {"preset": "robust"}),
    ("gtsam-batch@real", "gtsam-batch", {"preset": "real"}),
    ("gtsam-isam2", "gtsam-isam2", {}),
    ("gtsam-isam2@real", "gtsam-isam2", {"preset": "real"}),
    ("hybrid-isam2", "hybrid-isam2", {}),
    ("hybrid-isam2@real", "hybrid-isam2", {"preset": "real"}),
    ("hybrid", "hybrid", {}),
    ("hybrid@real-seed", "hybrid", {"preset": "real-seed"}),
    ("hybrid@real-seed-robust", "hybrid", {"preset": "real-seed-robust"}),
    ("hybrid@real", "hybrid", {"preset": "real"}),
    ("oracle", "oracle", {}),
    ("oracle@robust", "oracle", {"preset": "robust"}),
    ("oracle@real", "oracle", {"preset": "real"}),
]

STREAMS = ("sim-l0", "sim-l1", "sim-l2", "mrclam6-r3", "g2o")
#: The paper's two-minima worlds (README, "The main job"): where LM stops there is decided by
#: small things, so a change that moves any GTSAM map shows there first. h85 moved
#: ``hybrid-isam2``'s paper maps on both and on none of ``STREAMS``.
TWO_MINIMA = ("sim-l1-r1", "sim-l3-r0")
GTSAM_PAPER = ("gtsam-batch", "gtsam-isam2", "hybrid", "hybrid-isam2", "oracle")


def load_stream(name: str, prior_fraction: float = 0.0):
    from bomgraph.sim import RunSpec, SimConfig, simulate_run

    if name.startswith("sim-l"):  # sim-lA: layout A, start 0; sim-lA-rB: start B
        layout, _, start = name[5:].partition("-r")
        return simulate_run(RunSpec(0, int(layout), int(start or 0)), SimConfig(),
                            prior_fraction=prior_fraction)
    from bomgraph import datasets

    if name == "mrclam6-r3":
        return datasets.import_mrclam(str(DATA / "mrclam6"), 3)
    g2o = DATA / "bearing_only_sim_g2o"
    return datasets.import_g2o(str(g2o / "slam2D_bearing_only_initial_guess.g2o"),
                               truth_path=str(g2o / "slam2D_bearing_only_ground_truth.g2o"))


def tasks() -> list[tuple[str, str, str, dict[str, Any], float]]:
    out = [(f"{label} | {s}", s, method, opts, 0.0)
           for label, method, opts in CONFIGS for s in STREAMS]
    out += [(f"{m} | {s}", s, m, {}, 0.0) for m in GTSAM_PAPER for s in TWO_MINIMA]
    out.append(("stmds-smacof+priors | sim-l0", "sim-l0", "stmds-smacof", {}, 0.1))
    out.append(("stmds-smacof@improved+priors | sim-l0", "sim-l0", "stmds-smacof",
                {"preset": "improved"}, 0.1))
    return out


def _digest(result) -> str:
    h = hashlib.sha256()
    for cp in result.checkpoints:
        est = cp.estimate
        h.update(str(cp.t).encode())
        for a in (est.landmark_ids, est.landmarks_xy, est.pose_t, est.poses,
                  est.landmark_cov, est.pose_cov):
            if a is None:
                h.update(b"none")
            else:
                arr = np.ascontiguousarray(a)
                h.update(str(arr.shape).encode())
                h.update(arr.astype(np.int64 if arr.dtype.kind in "iu" else np.float64).tobytes())
    return h.hexdigest()


def run_one(task: tuple[str, str, str, dict[str, Any], float]) -> dict[str, Any]:
    from threadpoolctl import threadpool_limits

    from bomgraph.evaluate import score_estimate
    from bomgraph.mapper import create_mapper, method_info, run

    label, stream_name, method, options, prior_fraction = task
    with threadpool_limits(limits=1):
        stream = load_stream(stream_name, prior_fraction)
        truth = stream.truth if method_info(method).needs_truth else None
        t0 = time.perf_counter()
        try:
            mapper = create_mapper(method, stream.header, truth=truth, **options)
            result = run(mapper, stream.steps, checkpoint_every=10)
        except Exception as exc:  # a failure is a result to compare too
            return {"label": label, "digest": f"error: {type(exc).__name__}: {exc}",
                    "mpe_m": None, "n": 0, "seconds": time.perf_counter() - t0}
        try:
            mpe = float(score_estimate(result.final, stream.truth).mpe_m)
        except Exception as exc:  # too few landmarks to align
            mpe = f"{type(exc).__name__}"
        return {"label": label, "digest": _digest(result), "mpe_m": mpe,
                "n": len(result.final), "seconds": time.perf_counter() - t0}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true", help="write the reference file")
    ap.add_argument("--only", default="", help="run only tasks whose label contains this")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument("--reference", type=Path, default=REFERENCE, help="the reference file")
    args = ap.parse_args(argv)

    from joblib import Parallel, delayed

    todo = [t for t in tasks() if args.only in t[0]]
    t0 = time.perf_counter()
    rows = Parallel(n_jobs=args.jobs)(delayed(run_one)(t) for t in todo)
    wall = time.perf_counter() - t0
    if args.write:
        ref = {} if not args.reference.exists() or not args.only else \
            json.loads(args.reference.read_text())
        ref.update({r["label"]: {"digest": r["digest"], "mpe_m": r["mpe_m"], "n": r["n"]}
                    for r in rows})
        args.reference.parent.mkdir(parents=True, exist_ok=True)
        args.reference.write_text(json.dumps(dict(sorted(ref.items())), indent=1) + "\n")
        print(f"wrote {len(rows)} tasks to {args.reference} in {wall:.0f} s")
        return 0
    ref = json.loads(args.reference.read_text())
    bad = 0
    for r in rows:
        want = ref.get(r["label"])
        if want is None:
            print(f"NEW       {r['label']}: not in the reference")
            bad += 1
        elif want["digest"] != r["digest"]:
            bad += 1
            print(f"DIFFERENT {r['label']}: MPE {want['mpe_m']} -> {r['mpe_m']} m, "
                  f"n {want['n']} -> {r['n']}" + (f" ({r['digest']})"
                                                  if r["digest"].startswith("error") else ""))
    print(f"{len(rows) - bad} of {len(rows)} tasks identical to the reference, bit for bit "
          f"({wall:.0f} s)")
    return 0 if bad == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
