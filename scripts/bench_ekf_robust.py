"""The EKF baselines' robust (Huber) bearing update (``robust_update="huber"``) against the
plain update, on the MRCLAM streams of the generality table.

Each stream of ``DIR`` (``bench_generality.py``'s imports: m6, m6dense, m6sigx0.5, m6sigx2,
m1, m1dense, ``_r1`` .. ``_r5``) is run by ``ekf`` and ``ekf-invdepth`` with the ``real``
preset (:func:`bomgraph.bench.run_file`), the final map scored against the stream's truth
(:func:`bomgraph.evaluate.score_estimate`; MRCLAM1: landmark truth only). The threshold
``robust_k`` is chosen per method on the selection family only (``--select``, default m6: the
smallest sum of final-map MPE over its five streams among ``--ks``); the other families are
then run with the option off and at that ``k`` unchanged. The oracle's MPE is read from
README.md's generality table.

Usage::

    python scripts/bench_ekf_robust.py DIR [--jobs 2] [--ks 1.5,2,3] [--select m6]
        [--out /tmp/bench_ekf_robust.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any, Sequence

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _ekf_options import (FAMILIES, METHODS, oracle_table, scored_run,  # noqa: E402
                          stream_path)


def one(path: str, method: str, k: float | None) -> dict[str, Any]:
    """One run: ``k`` None is the option off (the preset as it is)."""
    opts: dict[str, Any] = {"preset": "real"}
    if k is not None:
        opts.update(robust_update="huber", robust_k=k)
    r = scored_run(path, method, opts)
    info = r.pop("info")
    return {**r, "method": method, "k": k, "downweighted": info.get("robust_downweighted"),
            "gated": info.get("gated_bearings")}


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", type=Path)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--ks", default="1.5,2,3")
    ap.add_argument("--select", default="m6")
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--out", type=Path, default=Path("/tmp/bench_ekf_robust.json"))
    a = ap.parse_args(argv)
    ks = [float(v) for v in a.ks.split(",")]
    families = [f for f in a.families.split(",") if f != a.select]
    from joblib import Parallel, delayed

    t0 = time.perf_counter()
    # 1. selection: every k (and off) on the selection family only
    tasks = [(stream_path(a.dir, a.select, r), m, k) for r in range(1, 6) for m in METHODS
             for k in [None, *ks]]
    rows = Parallel(n_jobs=a.jobs)(delayed(one)(*t) for t in tasks)
    by = {(r["stream"], r["method"], r["k"]): r for r in rows}

    def total(fam: str, m: str, k: float | None) -> float:
        return sum(by[f"{fam}_r{r}", m, k]["mpe_cm"] for r in range(1, 6))

    print(f"selection on {a.select} (sum of final-map MPE over r1..r5, cm):")
    print("| method | off | " + " | ".join(f"k = {k:g}" for k in ks) + " |")
    print("|---|---|" + "---|" * len(ks))
    chosen = {}
    for m in METHODS:
        sums = [total(a.select, m, k) for k in ks]
        chosen[m] = ks[min(range(len(ks)), key=sums.__getitem__)]
        print(f"| {m} | {total(a.select, m, None):.1f} | "
              + " | ".join(f"{s:.1f}" for s in sums) + " |")
    print("chosen k: " + ", ".join(f"{m} {k:g}" for m, k in chosen.items()) + "\n")
    # 2. the chosen k, unchanged, on the other families
    tasks = [(stream_path(a.dir, f, r), m, k) for f in families for r in range(1, 6) for m in METHODS
             for k in (None, chosen[m])]
    more = Parallel(n_jobs=a.jobs)(delayed(one)(*t) for t in tasks)
    rows += more
    by.update({(r["stream"], r["method"], r["k"]): r for r in more})
    wall = time.perf_counter() - t0
    oracle = oracle_table(Path(__file__).resolve().parents[1] / "README.md")
    print("MPE cm (mapped; on: bearings down-weighted), ratio to the oracle off -> on:")
    print("| stream | ekf off | ekf on | ekf-invdepth off | ekf-invdepth on | oracle "
          "| ekf / oracle | invdepth / oracle |")
    print("|---|---|---|---|---|---|---|---|")
    for fam in [a.select, *families]:
        for r in range(1, 6):
            s = f"{fam}_r{r}"
            cells, ratios = [], []
            orc = oracle.get(s)
            for m in METHODS:
                off, on = by[s, m, None], by[s, m, chosen[m]]
                cells += [f"{off['mpe_cm']:.1f} ({off['mapped']})",
                          f"{on['mpe_cm']:.1f} ({on['mapped']}; {on['downweighted']})"]
                ratios.append(f"{off['mpe_cm'] / orc:.2f} -> {on['mpe_cm'] / orc:.2f}"
                              if orc else "-")
            print(f"| {s} | {' | '.join(cells)} | {orc if orc else 'no truth'} | "
                  f"{' | '.join(ratios)} |")
    for fam in [a.select, *families]:
        for m in METHODS:
            off, on = total(fam, m, None), total(fam, m, chosen[m])
            print(f"{fam:10s} {m:13s} k {chosen[m]:g}  sum off {off:6.1f}  on {on:6.1f}"
                  f"  ({on / off:.3f})")
    print(f"\n{len(rows)} runs in {wall:.0f} s; wrote {a.out}")
    a.out.write_text(json.dumps({"chosen": chosen, "rows": rows}, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
