"""The EKF baselines' inverse-depth prior against the stream's stated sensor range:
``rho_prior="range"`` (the presets) against ``"empirical"`` (:mod:`baselines.ekf.range_prior`).

1. On the selection family (``--select``, default m6; ``DIR/{fam}_r{1..5}.jsonl``) each stream
   is run by ``ekf`` and ``ekf-invdepth`` (preset ``real``), option off and on, with the
   header's ``sensor_range_m`` as stated, None, x2 and x0.5: final-map MPE (cm) and landmarks
   mapped, and per robot the worst ratio of MPE between the range variants.
2. The other families at the stated range, off and on, with the sums of MPE per family.

Usage::

    python scripts/bench_ekf_range.py DIR [--jobs 2] [--out /tmp/bench_ekf_range.json]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any, Sequence

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _ekf_options import FAMILIES, METHODS, scored_run, stream_path  # noqa: E402
PRIORS = ("range", "empirical")
VARIANTS = ("as is", "None", "x2", "x0.5")


def one(path: str, method: str, prior: str, variant: str) -> dict[str, Any]:
    """One run with the header's range replaced as ``variant`` says."""
    from bomgraph.stream_file import StreamReader

    with StreamReader(path, warn=False) as reader:
        rng = reader.header.sensor_range_m
    new = {"as is": rng, "None": None, "x2": None if rng is None else 2 * rng,
           "x0.5": None if rng is None else 0.5 * rng}[variant]
    r = scored_run(path, method, {"preset": "real", "rho_prior": prior},
                   {"sensor_range_m": new})
    return {"stream": r["stream"], "method": method, "prior": prior, "variant": variant,
            "mpe_cm": r["mpe_cm"], "mapped": r["mapped"]}


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", type=Path)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--select", default="m6")
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--out", type=Path, default=Path("/tmp/bench_ekf_range.json"))
    a = ap.parse_args(argv)
    from joblib import Parallel, delayed

    others = [f for f in a.families.split(",") if f != a.select]
    tasks = [(stream_path(a.dir, a.select, r), m, p, v) for r in range(1, 6)
             for m in METHODS for p in PRIORS for v in VARIANTS]
    tasks += [(stream_path(a.dir, f, r), m, p, "as is") for f in others
              for r in range(1, 6) for m in METHODS for p in PRIORS]
    rows = Parallel(n_jobs=a.jobs)(delayed(one)(*t) for t in tasks)
    by = {(r["stream"], r["method"], r["prior"], r["variant"]): r for r in rows}
    print(f"{a.select}: final MPE cm (landmarks mapped) per header range; worst = the largest "
          f"ratio of MPE between the variants")
    for m in METHODS:
        for p in PRIORS:
            print(f"\n{m} rho_prior={p}")
            print(f"{'robot':6s}" + "".join(f"{v:>13s}" for v in VARIANTS) + f"{'worst':>8s}")
            sums = dict.fromkeys(VARIANTS, 0.0)
            for r in range(1, 6):
                cells = [by[(f"{a.select}_r{r}", m, p, v)] for v in VARIANTS]
                mpes = [c["mpe_cm"] for c in cells]
                for v, e in zip(VARIANTS, mpes):
                    sums[v] += e
                print(f"r{r:<5d}" + "".join(f"{c['mpe_cm']:8.1f} ({c['mapped']:2d})"
                                          for c in cells) + f"{max(mpes) / min(mpes):8.2f}")
            print(f"{'sum':6s}" + "".join(f"{sums[v]:13.1f}" for v in VARIANTS))
    print("\nstated range: sum of final MPE cm over r1-r5 (landmarks mapped), range -> empirical")
    for f in [a.select, *others]:
        cells = []
        for m in METHODS:
            s = {p: [by[(f"{f}_r{r}", m, p, "as is")] for r in range(1, 6)] for p in PRIORS}
            cells.append(f"{m} " + " -> ".join(
                f"{sum(c['mpe_cm'] for c in s[p]):.1f} ({sum(c['mapped'] for c in s[p])})"
                for p in PRIORS))
            cells.append("[" + ", ".join(f"{c['mpe_cm']:.1f}/{d['mpe_cm']:.1f}"
                                         for c, d in zip(s["range"], s["empirical"])) + "]")
        print(f"{f:10s} " + "  ".join(cells))
    a.out.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
