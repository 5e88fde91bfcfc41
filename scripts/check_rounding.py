"""How much of a method's final map is decided by rounding: each stream as it is, and again
with every bearing moved by ``--eps`` radians (Gaussian, default 1e-12: rounding level, ten
orders of magnitude under the noise), ``--draws`` times with seeds 1, 2, ...

A method whose choices are well-posed gives the same map to about ``eps`` divided by its
conditioning. A stream whose final MPE moves by more than ``--tol`` (relative, default 1 %)
has a decision (an outlier test, a gate, an iteration count) that rounding takes. The
sixteenth session found four such streams of thirty for ``stmds-smacof@real`` on the
generality streams (``docs/measurements.md``, "Faster long BOM-STMDS windows, tried and
reverted"). Streams need ground truth landmarks (the MPE is against them).

Usage::

    python scripts/check_rounding.py STREAM.jsonl ... [--method stmds-smacof@real]
        [--eps 1e-12] [--draws 2] [--jobs 2] [--tol 0.01] [--out FILE.json]

Prints one line per stream (MPE as is, then per draw, and the largest relative change) and
the count above ``--tol``; exits 0 either way (a measurement, not a test).
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any, Sequence  # noqa: E402

import numpy as np  # noqa: E402

from bomgraph.evaluate import score_estimate  # noqa: E402
from bomgraph.mapper import create_mapper, run  # noqa: E402
from bomgraph.stream import Step  # noqa: E402
from bomgraph.stream_file import read_stream  # noqa: E402


def perturbed(steps: Sequence[Step], eps: float, seed: int) -> list[Step]:
    """``steps`` with every bearing moved by ``eps`` times a standard normal draw (seeded)."""
    rng = np.random.default_rng(seed)
    return [dataclasses.replace(st, bearings_rad=st.bearings_rad
                                + eps * rng.standard_normal(st.bearings_rad.shape))
            for st in steps]


def final_mpe_cm(path: str, method: str, eps: float, seed: int) -> dict[str, Any]:
    """One run: the final map's landmark MPE (cm) and size, bearings moved by ``eps`` (0: as
    is)."""
    name, _, preset = method.partition("@")
    stream = read_stream(path)
    steps = perturbed(stream.steps, eps, seed) if eps else stream.steps
    options = {"preset": preset} if preset else {}
    est = run(create_mapper(name, stream.header, **options), steps).final
    return {"stream": Path(path).name, "seed": seed, "eps": eps, "n_mapped": len(est),
            "mpe_cm": 100 * score_estimate(est, stream.truth).mpe_m}


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("streams", nargs="+", help="stream files with landmark truth")
    ap.add_argument("--method", default="stmds-smacof@real", help="NAME or NAME@PRESET")
    ap.add_argument("--eps", type=float, default=1e-12, help="bearing perturbation, rad")
    ap.add_argument("--draws", type=int, default=2, help="perturbed runs per stream")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--tol", type=float, default=0.01, help="relative MPE change reported")
    ap.add_argument("--out", default=None, help="also save the rows as JSON")
    a = ap.parse_args(argv)
    if a.eps <= 0 or a.draws < 1:
        ap.error("--eps must be > 0 and --draws >= 1")
    from joblib import Parallel, delayed

    jobs = [(p, a.method, e, s) for p in a.streams
            for e, s in [(0.0, 0)] + [(a.eps, d) for d in range(1, a.draws + 1)]]
    rows = Parallel(n_jobs=a.jobs)(delayed(final_mpe_cm)(*j) for j in jobs)
    per = 1 + a.draws
    moved = 0
    print(f"{a.method}: final MPE (cm) as is, then with the bearings moved by {a.eps:g} rad")
    for i in range(0, len(rows), per):
        base, draws = rows[i], rows[i + 1:i + per]
        rel = max(abs(r["mpe_cm"] / base["mpe_cm"] - 1) for r in draws)
        moved += rel > a.tol
        cells = " ".join(f"{r['mpe_cm']:7.2f}" for r in draws)
        print(f"{base['stream']:28s} {base['mpe_cm']:7.2f} | {cells}   largest change {rel:.3f}")
    print(f"{moved} of {len(rows) // per} streams moved by more than {a.tol:.0%}")
    if a.out:
        Path(a.out).write_text(json.dumps({"method": a.method, "eps": a.eps, "rows": rows},
                                          indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
