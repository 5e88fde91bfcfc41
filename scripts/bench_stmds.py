"""Accuracy of BOM-STMDS on the paper's simulation (Exp. 1-3), printed and saved as JSON.

The paper's 25 runs (``paper_design(0)``: 5 layouts x 5 starts, 300 steps, maps every 10
steps). For Method 1 (``stmds-cs``) and Method 2 (``stmds-smacof``) it reports the landmark MPE
at t = 300 next to the paper's 4.78 / 2.87 cm, for

* ``literal``: the paper read literally (eq. 3-4 with ``fusion="paper"``);
* ``default``: the paper's method with the corrected fusion rule (the mapper's defaults);
* ``improved``: the best variant measured (preset ``"improved"``: 4-step triangulation
  baseline, ``"relative"`` fusion, inverse-variance SMACOF weights, a 1.3 x range gate);

then every fusion rule for Method 2 at the paper's triangulation and at the improved settings,
the localising variants (robot position error next to the paper's 10 / 6 cm bounds), and
Exp. 3 (10 % prior pairs) against no priors. ``--sensitivity`` adds runs with the noise scaled
and with longer steps, to show where the paper's figures fall.

Usage: ``python scripts/bench_stmds.py [--runs 25] [--jobs 2] [--sensitivity] [--quick]``.
Results go to ``results/bench_stmds.json`` (and ``results/bench_stmds_sensitivity.json``).
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from joblib import Parallel, delayed

from bomgraph.evaluate import error_table
from bomgraph.jsonio import jsonable
from bomgraph.mapper import create_mapper, run
from bomgraph.sim import SimConfig, paper_design, simulate_run
from bomgraph.stmds.distances import FUSION_RULES

RESULTS = Path(__file__).resolve().parents[1] / "results"
PAPER = {"stmds-cs": 4.78, "stmds-smacof": 2.87}
PAPER_ROBOT_BOUND = {"stmds-cs-loc": 10.0, "stmds-smacof-loc": 6.0}

VARIANTS = {
    "literal": {"fusion": "paper"},
    "default": {},
    "improved": {"preset": "improved"},
}


def one_run(spec, method: str, options: dict, sim: SimConfig, prior_fraction: float) -> dict:
    stream = simulate_run(spec, sim, prior_fraction=prior_fraction)
    mapper = create_mapper(method, stream.header, **options)
    res = run(mapper, stream.steps, checkpoint_every=10, method=method)
    table = error_table(res, stream.truth)
    return {"t": table["t"].tolist(), "mpe_m": table["mpe_m"].tolist(),
            "robot_last_m": table["robot_last_m"].tolist(),
            "n_mapped": table["n_mapped"].tolist(), "total_s": res.total_s}


def experiment(name: str, method: str, options: dict, specs: list, jobs: int,
               sim: SimConfig = SimConfig(), prior_fraction: float = 0.0) -> dict:
    t0 = time.perf_counter()
    runs = Parallel(n_jobs=jobs)(delayed(one_run)(s, method, options, sim, prior_fraction)
                                 for s in specs)
    mpe = np.array([r["mpe_m"] for r in runs])
    robot = np.array([r["robot_last_m"] for r in runs])
    t = runs[0]["t"]
    out = {"name": name, "method": method, "options": jsonable(options),
           "n_runs": len(runs), "t": t,
           "mpe_cm_mean_curve": (100 * np.nanmean(mpe, axis=0)).round(3).tolist(),
           "mpe_cm_t300_mean": float(100 * np.nanmean(mpe[:, -1])),
           "mpe_cm_t300_median": float(100 * np.nanmedian(mpe[:, -1])),
           "mpe_cm_t300_std": float(100 * np.nanstd(mpe[:, -1])),
           "mpe_cm_t300_max": float(100 * np.nanmax(mpe[:, -1])),
           "seconds": time.perf_counter() - t0}
    if np.isfinite(robot).any():
        curve = 100 * np.nanmean(robot, axis=0)
        out.update(robot_cm_mean_curve=curve.round(3).tolist(),
                   robot_cm_t300_mean=float(curve[-1]),
                   robot_cm_mean_over_t=float(np.nanmean(curve)),
                   robot_cm_max_over_t_from_50=float(np.nanmax(curve[4:])))
    return out


def line(res: dict, ref: float | None = None) -> str:
    txt = (f"{res['name']:<44s} MPE(t=300) {res['mpe_cm_t300_mean']:6.2f} cm "
           f"(median {res['mpe_cm_t300_median']:5.2f}, max {res['mpe_cm_t300_max']:6.2f})")
    if ref is not None:
        txt += f"   paper {ref:.2f} cm"
    if "robot_cm_t300_mean" in res:
        txt += (f" | robot: t=300 {res['robot_cm_t300_mean']:5.2f} cm, mean over t "
                f"{res['robot_cm_mean_over_t']:5.2f}, max over t>=50 "
                f"{res['robot_cm_max_over_t_from_50']:5.2f}")
    return txt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=25, help="runs of paper_design(0) to use")
    ap.add_argument("--jobs", type=int, default=2, help="joblib processes")
    ap.add_argument("--sensitivity", action="store_true",
                    help="also vary the noise scale and the step length")
    ap.add_argument("--quick", action="store_true", help="main table only")
    args = ap.parse_args()
    specs = paper_design(0)[:args.runs]
    results: list[dict] = []

    def show(res: dict, ref: float | None = None) -> None:
        results.append(res)
        print(line(res, ref), flush=True)

    print(f"== Exp. 1: landmark MPE at t = 300, {len(specs)} runs ==")
    for method in ("stmds-cs", "stmds-smacof"):
        for variant, opts in VARIANTS.items():
            show(experiment(f"{method} {variant}", method, opts, specs, args.jobs),
                 PAPER[method])
    if not args.quick:
        print("== Method 2, every fusion rule ==")
        for base_name, base in (("paper triangulation", {}),
                                ("improved", {"preset": "improved"})):
            for rule in FUSION_RULES:
                show(experiment(f"stmds-smacof {base_name}, fusion={rule}", "stmds-smacof",
                                {**base, "fusion": rule}, specs, args.jobs))
        print("== Exp. 2: localisation (p = 6) ==")
        for method in ("stmds-cs-loc", "stmds-smacof-loc"):
            for variant in ("default", "improved"):
                res = experiment(f"{method} {variant}", method, VARIANTS[variant], specs,
                                 args.jobs)
                res["paper_robot_bound_cm"] = PAPER_ROBOT_BOUND[method]
                show(res)
        print("== Exp. 3: 10 % prior pairs (sigma 3 cm in x and y) ==")
        for variant in ("default", "improved"):
            for pf in (0.0, 0.1):
                res = experiment(f"stmds-smacof {variant}, priors {pf:.0%}", "stmds-smacof",
                                 VARIANTS[variant], specs, args.jobs, prior_fraction=pf)
                show(res)
                print("    MPE curve (cm) t=10..300 every 10: "
                      + " ".join(f"{v:.1f}" for v in res["mpe_cm_mean_curve"]))
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / "bench_stmds.json"
    path.write_text(json.dumps(jsonable({"paper": PAPER, "paper_robot_bound_cm": PAPER_ROBOT_BOUND,
                                         "results": results}), indent=1))
    print(f"saved {path}")

    if args.sensitivity:
        sens: list[dict] = []
        print("== Sensitivity: noise scale and step length ==")
        cases = [("noise x0.5", replace(SimConfig(), noise_scale=0.5)),
                 ("noise x1 (paper)", SimConfig()),
                 ("noise x1.5", replace(SimConfig(), noise_scale=1.5)),
                 ("steps 0.2-0.3 m", replace(SimConfig(), step_min_m=0.2, step_max_m=0.3,
                                             lookahead_m=0.4)),
                 ("steps 0.05-0.1 m", replace(SimConfig(), step_min_m=0.05, step_max_m=0.1))]
        for label, sim in cases:
            for method in ("stmds-cs", "stmds-smacof"):
                for variant in ("default", "improved"):
                    res = experiment(f"{label}: {method} {variant}", method, VARIANTS[variant],
                                     specs, args.jobs, sim=sim)
                    sens.append(res)
                    print(line(res, PAPER[method]), flush=True)
        spath = RESULTS / "bench_stmds_sensitivity.json"
        spath.write_text(json.dumps(jsonable({"paper": PAPER, "results": sens}), indent=1))
        print(f"saved {spath}")


if __name__ == "__main__":
    main()
