"""The paper's Exp. 1 on the paper setup (25 runs), every arm side by side.

    python scripts/exp1_mapping.py [--quick] [--out results/exp1] [--jobs N]

A thin call into the library (`bomgraph compare`): `bomgraph.report.compare` with the
experiment of `bomgraph.experiments.paper_experiments`; prints the table, writes JSON, CSV and
PNG figures.
"""

from __future__ import annotations

import sys

from bomgraph.cli import main

if __name__ == "__main__":
    args = sys.argv[1:]
    if "--out" not in args:
        args += ["--out", "results/exp1"]
    sys.exit(main(["compare", "--experiments", "exp1", *args]))
