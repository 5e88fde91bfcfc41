"""The paper's experiments on the paper setup (25 runs each), every arm side by side.

    python scripts/paper_experiments.py exp1 [--quick] [--out results/exp1] [--jobs N]
    python scripts/paper_experiments.py exp2|exp3|all ...

Exp. 1 is mapping without localisation, Exp. 2 SLAM, Exp. 3 mapping with 10 % of the pairs
known as priors (paper section IV); ``all`` is every method side by side. A thin call into the
library, the same as ``bomgraph compare --experiments NAME``
(:func:`bomgraph.report.compare` over :func:`bomgraph.experiments.paper_experiments`): prints
the table, writes JSON, CSV and PNG figures to ``results/NAME`` unless ``--out`` says otherwise.
"""

from __future__ import annotations

import sys

from bomgraph.cli import main

NAMES = ("exp1", "exp2", "exp3", "all")

if __name__ == "__main__":
    args = sys.argv[1:]
    if not args or args[0] not in NAMES:
        print(f"usage: python scripts/paper_experiments.py {{{','.join(NAMES)}}} "
              f"[bomgraph compare options]", file=sys.stderr)
        sys.exit(2)
    name, rest = args[0], args[1:]
    if "--out" not in rest:
        rest += ["--out", f"results/{name}"]
    sys.exit(main(["compare", "--experiments", name, *rest]))
