"""The paper's Exp. 2 on the paper setup (25 runs), every arm side by side.

    python scripts/exp2_slam.py [--quick] [--out results/exp2] [--jobs N]

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
        args += ["--out", "results/exp2"]
    sys.exit(main(["compare", "--experiments", "exp2", *args]))
