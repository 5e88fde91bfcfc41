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

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import re  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any, Sequence  # noqa: E402

FAMILIES = ("m6", "m6dense", "m6sigx0.5", "m6sigx2", "m1", "m1dense")
METHODS = ("ekf", "ekf-invdepth")
MODES = ("fixed", "innovation")


def one(path: str, method: str, mode: str) -> dict[str, Any]:
    from bomgraph.bench import run_file
    from bomgraph.evaluate import score_estimate
    from bomgraph.stream_file import read_stream

    t0 = time.process_time()
    result = run_file(path, method, {"preset": "real", "bearing_variance_scale": mode})
    truth = read_stream(path).truth
    score = score_estimate(result.final, truth)
    return {"stream": Path(path).stem, "method": method, "mode": mode,
            "mpe_cm": 100 * score.mpe_m, "mapped": len(result.final),
            "scale": result.final.info.get("bearing_variance_scale"),
            "scale_max": result.final.info.get("bearing_variance_scale_max"),
            "cpu_s": time.process_time() - t0}


def oracle_table(readme: Path) -> dict[str, float]:
    """Stream -> the oracle's MPE (cm) in README.md's generality table."""
    out = {}
    for line in readme.read_text().splitlines():
        m = re.match(r"\| (m[0-9a-z.]+_r\d) \|.*\| ([0-9.]+) \(\d+\) \|$", line)
        if m:
            out[m.group(1)] = float(m.group(2))
    return out


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", type=Path)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--out", type=Path, default=Path("/tmp/bench_variance_scale.json"))
    a = ap.parse_args(argv)
    streams = [str(a.dir / f"{f}_r{r}.jsonl") for f in a.families.split(",") for r in range(1, 6)]
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
