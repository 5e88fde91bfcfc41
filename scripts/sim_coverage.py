"""When has every landmark been seen? The paper says by t = 50 in all 25 runs.

Prints, for the paper's 25-run design, the first step at which all landmarks have been
observed, and saves the numbers to results/sim_coverage.json.

    python scripts/sim_coverage.py [--seed 0]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from bomgraph.sim import SimConfig, paper_design, simulate_run
from bomgraph.jsonio import jsonable


def first_all_seen(seed: int, config: SimConfig) -> list[int | None]:
    out: list[int | None] = []
    for spec in paper_design(seed):
        s = simulate_run(spec, config)
        seen = np.zeros(config.n_landmarks, bool)
        first = None
        for st in s.steps:
            seen[st.landmark_ids] = True
            if seen.all():
                first = st.t
                break
        out.append(first)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    firsts = first_all_seen(args.seed, SimConfig())
    t = np.array([np.inf if f is None else f for f in firsts])
    summary = {"seed": args.seed, "first_all_seen": firsts,
               "runs_all_seen_by_50": int(np.sum(t <= 50)), "median": float(np.median(t)),
               "worst": float(t.max())}
    print(f"runs with every landmark seen by t = 50: {summary['runs_all_seen_by_50']} of 25; "
          f"median first time {summary['median']:.0f}, worst {summary['worst']:.0f}")
    Path("results").mkdir(exist_ok=True)
    Path("results/sim_coverage.json").write_text(json.dumps(jsonable(summary), indent=1))


if __name__ == "__main__":
    main()
