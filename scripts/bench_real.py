"""Every method on real data with ground truth: MRCLAM6 robots 1-5 and the bearing-only g2o set.

    python scripts/bench_real.py [--data ../shared/data] [--out results/real] [--jobs N]

(``BOMGRAPH_DATA`` sets the default data folder.)

A thin call into the library (`bomgraph compare --real`): prints the landmark MPE / robot error
table (failures reported with their reason), writes JSON, CSV and one map figure per dataset.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from bomgraph.cli import main

if __name__ == "__main__":
    args = sys.argv[1:]
    data = os.environ.get("BOMGRAPH_DATA",
                          str(Path(__file__).resolve().parents[2] / "shared" / "data"))
    if "--data" in args:
        k = args.index("--data")
        data = args[k + 1]
        del args[k:k + 2]
    if "--out" not in args:
        args += ["--out", "results/real"]
    sys.exit(main(["compare", "--real", data, *args]))
