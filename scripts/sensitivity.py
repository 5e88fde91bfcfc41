"""Where do the paper's figures fall? BOM-STMDS MPE at t = 300 against noise scale and step
length (paper setup otherwise, 25 runs each).

    python scripts/sensitivity.py [--quick] [--methods stmds-cs,stmds-smacof] [--jobs 2]

Prints a table (rows: setting; columns: method) next to the paper's 4.78 / 2.87 cm and saves
results/sensitivity.json.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

from bomgraph.bench import Executor, execute
from bomgraph.experiments import Arm, Experiment
from bomgraph.report import summarise
from bomgraph.sim import SimConfig
from bomgraph.jsonio import jsonable

PAPER = {"stmds-cs": 0.0478, "stmds-smacof": 0.0287}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="5 runs per setting")
    ap.add_argument("--methods", default="stmds-cs,stmds-smacof")
    ap.add_argument("--jobs", type=int, default=-1)
    ap.add_argument("--out", default="results/sensitivity.json")
    args = ap.parse_args()
    methods = args.methods.split(",")
    base = SimConfig()
    settings = [("paper", base)]
    settings += [(f"noise x{k}", replace(base, noise_scale=k)) for k in (0.25, 0.5, 2.0)]
    settings += [(f"step {a}-{b} m", replace(base, step_min_m=a, step_max_m=b,
                                             lookahead_m=max(0.3, b)))
                 for a, b in ((0.05, 0.1), (0.2, 0.3), (0.3, 0.4))]
    size = dict(n_layouts=5, n_starts=1) if args.quick else {}
    table = []
    for name, sim in settings:
        exp = Experiment("sens", name, tuple(Arm(m, m) for m in methods), sim, **size)
        rows = {r["arm"]: r for r in summarise(execute(exp.tasks(), Executor(n_jobs=args.jobs)))}
        entry = {"setting": name}
        for m in methods:
            entry[m] = rows[m].get(f"mpe_mean_m@{sim.n_steps}", float("nan"))
        table.append(entry)
        print(f"{name:16s} " + "  ".join(f"{m}: {100 * entry[m]:6.2f} cm" for m in methods),
              flush=True)
    print("paper            " + "  ".join(f"{m}: {100 * PAPER[m]:6.2f} cm" for m in methods
                                          if m in PAPER))
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(jsonable({"table": table, "paper": PAPER}), indent=1))


if __name__ == "__main__":
    main()
