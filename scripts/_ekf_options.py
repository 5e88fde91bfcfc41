"""What the EKF option benchmarks share (``bench_ekf_robust.py``, ``bench_ekf_range.py``,
``bench_variance_scale.py``): single-threaded BLAS, the issue-15 families and the two EKFs, one
scored run of a stream, and the oracle column of README.md's generality table.

Import it before numpy (it sets the BLAS thread variables a benchmark runs with).
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import re  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

#: The families of issue 15's validation table, as ``bench_generality.py --work`` writes them
#: (``DIR/{family}_r{1..5}.jsonl``).
FAMILIES = ("m6", "m6dense", "m6sigx0.5", "m6sigx2", "m1", "m1dense")
#: The filters these benchmarks compare.
METHODS = ("ekf", "ekf-invdepth")


def stream_path(folder: Path, family: str, robot: int) -> str:
    """``folder/{family}_r{robot}.jsonl`` as a string (the joblib tasks' argument)."""
    return str(folder / f"{family}_r{robot}.jsonl")


def scored_run(path: str, method: str, options: dict[str, Any],
               header_changes: dict[str, Any] | None = None) -> dict[str, Any]:
    """One run of ``method`` on the stream at ``path`` (checkpoint every 10 steps, as ``bomgraph
    run``), its final map scored against the stream's truth.

    ``options`` go to the method (``preset`` among them); ``header_changes`` replace fields of
    the stream's header first. Returns ``stream`` (the file's stem), ``mpe_cm`` (nan when fewer
    than 3 landmarks were mapped), ``mapped``, ``info`` (the final estimate's) and ``cpu_s``.
    """
    import dataclasses

    from bomgraph.errors import TooFewLandmarksError
    from bomgraph.evaluate import score_estimate
    from bomgraph.mapper import create_mapper, run
    from bomgraph.stream_file import read_stream

    t0 = time.process_time()
    s = read_stream(path)
    header = dataclasses.replace(s.header, **(header_changes or {}))
    est = run(create_mapper(method, header, **options), s.steps, checkpoint_every=10).final
    try:
        mpe = 100 * score_estimate(est, s.truth).mpe_m
    except TooFewLandmarksError:
        mpe = float("nan")
    return {"stream": Path(path).stem, "mpe_cm": mpe, "mapped": len(est), "info": est.info,
            "cpu_s": time.process_time() - t0}


def oracle_table(readme: Path) -> dict[str, float]:
    """Stream -> the oracle's MPE (cm) in README.md's generality table."""
    out = {}
    for line in readme.read_text().splitlines():
        m = re.match(r"\| (m[0-9a-z.]+_r\d) \|.*\| ([0-9.]+) \(\d+\) \|$", line)
        if m:
            out[m.group(1)] = float(m.group(2))
    return out
