"""BOM-STMDS recording settings on streams nobody tuned them on (issue 15 items 2, 3, 6).

    python scripts/bench_stmds_generality.py STREAM_DIR [--methods stmds-smacof,...]
        [--presets real,real-keyframes] [--reference oracle:robust] [--out results/x.json]

Runs every ``method:preset`` and the reference (LM from the truth, ``oracle`` with its
``robust`` preset) on every ``*.jsonl`` stream of ``STREAM_DIR`` (e.g. MRCLAM6 and MRCLAM1
imported with the default keyframing, with ``--min-distance 0.1 --min-turn 0.1745``, and with
the header's bearing sigma scaled), the final map only, and prints the landmark MPE (cm) of
each with its ratio to the reference. A stream without robot truth cannot run the oracle; its
ratio is to the best method in the table. Results are saved as JSON.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

from bomgraph.errors import BomgraphError
from bomgraph.evaluate import score_estimate
from bomgraph.mapper import create_mapper, run
from bomgraph.stream_file import read_stream


def _limit_blas() -> None:
    from threadpoolctl import threadpool_limits
    threadpool_limits(limits=1)


def run_one(path: Path, spec: str) -> dict:
    """Final map of ``method[:preset]`` on one stream: MPE (m), landmarks, CPU seconds."""
    method, _, preset = spec.partition(":")
    stream = read_stream(path)
    opts = {"preset": preset} if preset else {}
    t0 = time.process_time()
    try:
        mapper = create_mapper(method, stream.header, truth=stream.truth, **opts)
        est = run(mapper, stream.steps, checkpoint_every=10).final
        mpe = float(score_estimate(est, stream.truth).mpe_m)
        n = len(est)
    except BomgraphError as exc:              # no truth for the oracle, or no map
        return {"mpe_m": math.nan, "n_mapped": 0, "error": str(exc)}
    return {"mpe_m": mpe, "n_mapped": n, "cpu_s": time.process_time() - t0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("streams", type=Path)
    ap.add_argument("--methods", default="stmds-cs,stmds-smacof,stmds-cs-loc,stmds-smacof-loc")
    ap.add_argument("--presets", default="real,real-keyframes")
    ap.add_argument("--reference", default="oracle:robust")
    ap.add_argument("--out", type=Path, default=Path("results/bench_stmds_generality.json"))
    args = ap.parse_args()
    _limit_blas()
    specs = [f"{m}:{p}" for m in args.methods.split(",") for p in args.presets.split(",")]
    paths = sorted(args.streams.glob("*.jsonl"))
    table: dict[str, dict[str, dict]] = {}
    for path in paths:
        row = table.setdefault(path.stem, {})
        for spec in [args.reference, *specs]:
            row[spec] = run_one(path, spec)
    print("| stream | " + " | ".join([args.reference, *specs]) + " |")
    print("|---" * (len(specs) + 2) + "|")
    for name, row in table.items():
        ref = row[args.reference]["mpe_m"]
        if not math.isfinite(ref):           # no robot truth: the best method instead
            ref = min((r["mpe_m"] for r in row.values() if math.isfinite(r["mpe_m"])),
                      default=math.nan)
        cells = []
        for spec in [args.reference, *specs]:
            mpe = row[spec]["mpe_m"]
            cells.append("-" if not math.isfinite(mpe) else
                         f"{100 * mpe:.1f} ({mpe / ref:.2f}x)" if spec != args.reference
                         else f"{100 * mpe:.1f}")
        print(f"| {name} | " + " | ".join(cells) + " |")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(table, indent=1))
    print(f"saved {args.out}")


if __name__ == "__main__":
    main()
