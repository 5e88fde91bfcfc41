"""The EKF baselines' online bearing variance scale (``bearing_variance_scale="innovation"``)
against the fixed header sigma, on the MRCLAM streams of the generality table.

Each stream of ``DIR`` (``bench_generality.py``'s imports: m6, m6dense, m6sigx0.5, m6sigx2,
m1, m1dense, ``_r1`` .. ``_r5``) is run by ``ekf`` and ``ekf-invdepth`` with the ``real``
preset, the option off and on (:func:`bomgraph.bench.run_file`), the final map scored against
the stream's truth (:func:`bomgraph.evaluate.score_estimate`; MRCLAM1: landmark truth only).
The oracle's MPE is read from README.md's generality table.

Usage::

    python scripts/bench_variance_scale.py DIR [--jobs 2] [--out /tmp/bench_variance_scale.json]
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
MODES = ("fixed", "innovation")


def one(path: str, method: str, mode: str) -> dict[str, Any]:
    r = scored_run(path, method, {"preset": "real", "bearing_variance_scale": mode})
    info = r.pop("info")
    return {**r, "method": method, "mode": mode,
            "scale": info.get("bearing_variance_scale"),
            "scale_max": info.get("bearing_variance_scale_max")}


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", type=Path)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--out", type=Path, default=Path("/tmp/bench_variance_scale.json"))
    a = ap.parse_args(argv)
    streams = [stream_path(a.dir, f, r) for f in a.families.split(",") for r in range(1, 6)]
    tasks = [(s, m, o) for s in streams for m in METHODS for o in MODES]
    from joblib import Parallel, delayed

    t0 = time.perf_counter()
    rows = Parallel(n_jobs=a.jobs)(delayed(one)(*t) for t in tasks)
    wall = time.perf_counter() - t0
    oracle = oracle_table(Path(__file__).resolve().parents[1] / "README.md")
    by = {(r["stream"], r["method"], r["mode"]): r for r in rows}
    print("| stream | ekf off | ekf on (lambda final, max) | ekf-invdepth off | ekf-invdepth on "
          "(lambda final, max) "
          "| oracle | ekf on/off | invdepth on/off |")
    print("|---|---|---|---|---|---|---|---|")
    for s in dict.fromkeys(r["stream"] for r in rows):
        cells = []
        for m in METHODS:
            off, on = by[s, m, "fixed"], by[s, m, "innovation"]
            cells += [f"{off['mpe_cm']:.1f} ({off['mapped']})",
                      f"{on['mpe_cm']:.1f} ({on['mapped']}; {on['scale']:.2f}, max "
                      f"{on['scale_max']:.2f})"]
        ratios = [by[s, m, "innovation"]["mpe_cm"] / by[s, m, "fixed"]["mpe_cm"] for m in METHODS]
        orc = oracle.get(s)
        print(f"| {s} | {' | '.join(cells)} | {orc if orc is not None else 'no truth'} | "
              f"{ratios[0]:.2f} | {ratios[1]:.2f} |")
    for fam in a.families.split(","):
        for m in METHODS:
            sums = [sum(by[f"{fam}_r{r}", m, o]["mpe_cm"] for r in range(1, 6)) for o in MODES]
            print(f"{fam:10s} {m:13s} sum off {sums[0]:6.1f}  on {sums[1]:6.1f}")
    print(f"\n{len(rows)} runs in {wall:.0f} s; wrote {a.out}")
    a.out.write_text(json.dumps({"rows": rows}, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
