"""Every method's covariances against a Monte Carlo, in the frame fixed by the first pose.

    python scripts/bench_consistency.py [--methods ekf,gtsam-batch,...] [--seeds 0:150]
        [--steps 100] [--landmarks 50] [--option KEY=JSON ...] [--out FILE.json]

Each run is the paper's simulated world (``SimConfig`` with ``n_steps`` and ``n_landmarks``;
seed ``5000 + k``), mapped with the estimate asked for only at the end; GTSAM methods with
``covariances=True``, the oracle given the truth. The final estimate is carried into the
truth's frame by the rigid transform that takes its first pose onto the true first pose (the
anchor of the filters and graphs), so no alignment absorbs any error, and the script prints
per method the mean over runs of the final pose's NEES (3 dof; its position and heading parts)
and of each run's mean landmark NEES (2 dof), with the 95 % band of a mean of that many
independent chi-square draws (for the landmarks a lower bound on the width: a run's landmarks
are correlated), beside the evaluator's NEES after its Procrustes alignment on the landmarks
(which absorbs part of the error). Runs without covariances, or without one for the final
pose, are counted and left out; landmarks without one (an all-NaN block: not defined) are
left out of their run's mean.

The twenty-first session's table (150 runs of 100 steps) is in docs/measurements.md,
"Covariances against an anchored Monte Carlo".
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

import numpy as np
from scipy.stats import chi2

from bomgraph import create_mapper, run
from bomgraph.angles import angle_residual
from bomgraph.evaluate import mean_landmark_nees, pose_nees, score_estimate
from bomgraph.geometry import rotation
from bomgraph.map_estimate import MapEstimate
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream import Truth

METHODS = "ekf,ekf-invdepth,gtsam-batch,gtsam-isam2,hybrid,hybrid-isam2,oracle"
SEED_BASE = 5000


def anchored_nees(est: MapEstimate, truth: Truth) -> dict[str, Any]:
    """The final pose's NEES (whole, position, heading) and the landmarks' NEES, with the
    estimate carried into the truth's frame by the rigid transform taking its first pose onto
    the true one (covariances turned with it)."""
    p0, q0 = est.poses[0], truth.poses[est.pose_t[0]]
    turn = q0[2] - p0[2]
    rot = rotation(np.array([turn]))[0]
    shift = q0[:2] - rot @ p0[:2]
    jac = np.eye(3)
    jac[:2, :2] = rot
    p, q = est.poses[-1], truth.poses[est.pose_t[-1]]
    err = np.r_[rot @ p[:2] + shift - q[:2], angle_residual(p[2] + turn, q[2])]
    cov = jac @ est.pose_cov[-1] @ jac.T
    _, ie, it = np.intersect1d(est.landmark_ids, truth.landmark_ids, return_indices=True)
    defined = ~np.isnan(est.landmark_cov[ie]).all(axis=(1, 2))   # all NaN: no covariance
    ie, it = ie[defined], it[defined]
    lm_err = est.landmarks_xy[ie] @ rot.T + shift - truth.landmarks_xy[it]
    lm_cov = rot @ est.landmark_cov[ie] @ rot.T
    lm = np.einsum("ni,nij,nj->n", lm_err, np.linalg.inv(lm_cov), lm_err)
    return {"pose": float(err @ np.linalg.solve(cov, err)),
            "pose_xy": float(err[:2] @ np.linalg.solve(cov[:2, :2], err[:2])),
            "pose_heading": float(err[2] ** 2 / cov[2, 2]),
            "landmarks": float(lm.mean()), "n_landmarks": int(lm.size)}


def one_run(method: str, seed: int, steps: int, landmarks: int,
            options: dict[str, Any]) -> dict[str, Any] | None:
    """One simulated run of ``method``: its anchored NEES and the evaluator's, or None when
    the estimate has no covariances or fewer than 3 landmarks."""
    stream = simulate(SimConfig(n_steps=steps, n_landmarks=landmarks),
                      np.random.default_rng(SEED_BASE + seed))
    kw = dict(options)
    if not method.startswith("ekf"):
        kw["covariances"] = True
    if method == "oracle":
        kw["truth"] = stream.truth
    est = run(create_mapper(method, stream.header, **kw), stream.steps,
              checkpoint_every=10 ** 6).final
    if (est.pose_cov is None or est.landmark_cov is None or len(est.landmark_ids) < 3
            or np.isnan(est.pose_cov[-1]).all()):
        return None
    out = {"seed": seed, **anchored_nees(est, stream.truth)}
    score = score_estimate(est, stream.truth)
    out["evaluator_landmarks"] = mean_landmark_nees(est, stream.truth, score.alignment)
    out["evaluator_pose"] = pose_nees(est, stream.truth, score.alignment)
    out["covariances_from"] = est.info.get("covariances_from", "")
    return out


def summary_line(method: str, rows: list[dict[str, Any] | None], steps: int) -> str:
    ok = [r for r in rows if r is not None]
    k = len(ok)
    if not k:
        return f"{method:14s} no run with covariances ({len(rows)} runs)"
    mean = {key: float(np.mean([r[key] for r in ok])) for key in ok[0]
            if key not in ("seed", "covariances_from")}
    pb = chi2.ppf([0.025, 0.975], 3 * k) / k
    lb = chi2.ppf([0.025, 0.975], 2 * k) / k
    return (f"{method:14s} runs {k:3d}/{len(rows)}, {steps} steps | pose NEES "
            f"{mean['pose']:6.2f} (band {pb[0]:.2f}-{pb[1]:.2f}; position {mean['pose_xy']:.2f}, "
            f"heading {mean['pose_heading']:.2f}) | landmark NEES {mean['landmarks']:6.2f} "
            f"(band {lb[0]:.2f}-{lb[1]:.2f}) | after the landmark alignment: pose "
            f"{mean['evaluator_pose']:.2f}, landmarks {mean['evaluator_landmarks']:.2f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--methods", default=METHODS)
    ap.add_argument("--seeds", default="0:150", help="FIRST:END, run k uses seed 5000 + k")
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--landmarks", type=int, default=50)
    ap.add_argument("--option", action="append", default=[], metavar="KEY=JSON",
                    help="a method option for every method, e.g. preset='\"real\"'")
    ap.add_argument("--out", help="write the per-run values as JSON")
    a = ap.parse_args(argv)
    first, end = (int(x) for x in a.seeds.split(":"))
    options = {k: json.loads(v) for k, v in (kv.split("=", 1) for kv in a.option)}
    results = {}
    for method in a.methods.split(","):
        rows = [one_run(method, k, a.steps, a.landmarks, options) for k in range(first, end)]
        results[method] = rows
        print(summary_line(method, rows, a.steps), flush=True)
    if a.out:
        with open(a.out, "w") as fh:
            json.dump(results, fh)
    return 0


if __name__ == "__main__":
    sys.exit(main())
