"""CPU time and accuracy of ``gtsam-isam2`` beside a bare-GTSAM reference loop (issue 14 item 1).

Per paper run (``bomgraph.sim.paper_design(seed)``, 300 steps, N = 50, a map every 10 steps),
in the same process, single-threaded BLAS, CPU seconds (``time.process_time``):

* ``isam2``: :class:`baselines.isam2.Isam2Mapper` (``--option key=value`` overrides) through
  :func:`bomgraph.mapper.run`;
* ``loop``: the reference of issue 14, a bare warm-started Levenberg-Marquardt loop: the graph
  of :class:`baselines.bearing_graph.BearingGraph`, only the new factors added at each
  checkpoint, poses since the last solve dead-reckoned, LM (relative tolerance 1e-5, no Huber
  pass, no Gauss-Newton check) from the previous solution;
* ``oracle``: :class:`baselines.factor_graph.OracleMapper` at the final step only (the
  accuracy bound), not timed.

Prints one row per run (CPU s, ratio isam2 / loop, final MPE of the three, isam2 / oracle) and
the totals; ``--out`` saves them as JSON. ``--long T`` adds one simulated run of ``T`` steps at
the default cadence (isam2 vs ``gtsam-batch``, CPU s and MPE).

Usage::

    OMP_NUM_THREADS=1 PYTHONPATH=$PWD python scripts/bench_isam2.py [--runs 5] [--seed 0]
        [--option relinearize_skip=10 ...] [--long 3000] [--out results/bench_isam2.json]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import gtsam  # noqa: E402
import numpy as np  # noqa: E402

from baselines.bearing_graph import (BearingGraph, FactorGraphConfig,  # noqa: E402
                                     insert_pose, poses_from_values)
from baselines.factor_graph import BatchMapper, OracleMapper  # noqa: E402
from baselines.isam2 import Isam2Mapper  # noqa: E402
from bomgraph.evaluate import score_estimate  # noqa: E402
from bomgraph.jsonio import parse_options  # noqa: E402
from bomgraph.mapper import MapEstimate, run  # noqa: E402
from bomgraph.sim import SimConfig, paper_design, simulate_run  # noqa: E402
from bomgraph.stream import Stream  # noqa: E402
from bomgraph.stream_file import read_stream  # noqa: E402


def reference_loop(stream: Stream, every: int = 10) -> tuple[float, float]:
    """The bare warm LM loop; returns (CPU s, final MPE in m)."""
    t0 = time.process_time()
    config = FactorGraphConfig(huber_k=None)
    problem = BearingGraph(stream.header, config, np.zeros(3))
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-5)
    params.setlambdaUpperBound(1e16)
    params.setDiagonalDamping(True)
    last = len(stream.steps) - 1
    for st in stream.steps:
        problem.add_step(st)
        prev = poses_from_values(values, [st.t - 1])[0] if st.t > 0 else None
        insert_pose(values, st.t, problem.predict_pose(st.t, prev), prev)
        if (st.t > 0 and st.t % every == 0) or st.t == last:
            problem.admit(lambda ts: poses_from_values(values, ts))
            new = problem.take_new()
            graph.push_back(new.core)
            graph.push_back(new.landmark)
            values.insert(new.landmark_values)
            values = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
    cpu = time.process_time() - t0
    est = _estimate(problem, values)
    return cpu, score_estimate(est, stream.truth).mpe_m


def _estimate(problem: BearingGraph, values: gtsam.Values) -> MapEstimate:
    from baselines.factor_graph import estimate_from_values
    return estimate_from_values(problem, values, gtsam.NonlinearFactorGraph(), {}, False)


def timed_run(mapper: Any, stream: Stream, every: int) -> tuple[float, MapEstimate]:
    t0 = time.process_time()
    res = run(mapper, stream.steps, checkpoint_every=every, keep_checkpoints=False)
    return time.process_time() - t0, res.final


def oracle_mpe(stream: Stream) -> float:
    m = OracleMapper(stream.header, truth=stream.truth)
    for st in stream.steps:
        m.step(st)
    return score_estimate(m.estimate(), stream.truth).mpe_m


def _mpe(est: MapEstimate, stream: Stream) -> float:
    try:
        return score_estimate(est, stream.truth).mpe_m
    except Exception:  # noqa: BLE001 - a failed map is reported as NaN
        return math.nan


def recorded(paths: list[Path], preset: str | None, opts: dict[str, Any], every: int,
             out: Path | None) -> None:
    """isam2 (``preset`` + ``opts``) beside the oracle and gtsam-batch (``robust``) on
    recorded streams; the oracle needs robot truth (else the reference is batch)."""
    rows = []
    print(f"{'stream':18s} {'isam2 cm':>8s} {'oracle':>7s} {'batch':>7s} {'ratio':>6s} "
          f"{'isam2 s':>7s} mode")
    for path in paths:
        stream = read_stream(path)
        t0 = time.process_time()
        _, est = timed_run(Isam2Mapper(stream.header, preset=preset, **opts), stream, every)
        i_s = time.process_time() - t0
        mpe = _mpe(est, stream)
        o = math.nan
        if stream.truth is not None and stream.truth.poses is not None:
            om = OracleMapper(stream.header, truth=stream.truth,
                              preset="robust" if preset in ("robust", "real") else None)
            o = _mpe(run(om, stream.steps, checkpoint_every=10 ** 9).final, stream)
        _, best = timed_run(BatchMapper(stream.header, preset="robust"), stream, every)
        b = _mpe(best, stream)
        ref = o if math.isfinite(o) else b
        rows.append({"stream": path.stem, "isam2_mpe_m": mpe, "oracle_mpe_m": o,
                     "batch_mpe_m": b, "ratio": mpe / ref, "isam2_cpu_s": i_s,
                     "mode": est.info.get("mode"), "failures": est.info.get("update_failures"),
                     "converged": est.info.get("converged")})
        print(f"{path.stem:18s} {100 * mpe:8.2f} {100 * o:7.2f} {100 * b:7.2f} "
              f"{mpe / ref:6.3f} {i_s:7.2f} {est.info.get('mode')} "
              f"f={est.info.get('update_failures')} conv={est.info.get('converged')}",
              flush=True)
    if out:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps({"preset": preset, "options": opts, "rows": rows},
                                  indent=1))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--every", type=int, default=10)
    ap.add_argument("--option", action="append", default=[])
    ap.add_argument("--preset", default=None)
    ap.add_argument("--long", type=int, default=0)
    ap.add_argument("--no-oracle", action="store_true")
    ap.add_argument("--streams", nargs="*", type=Path, default=None,
                    help="recorded streams: isam2 vs oracle (same preset) and batch, final MPE")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args()
    opts = parse_options(a.option)
    if a.streams:
        return recorded(a.streams, a.preset, opts, a.every, a.out)
    rows = []
    print(f"{'run':12s} {'isam2 s':>8s} {'loop s':>7s} {'ratio':>6s} "
          f"{'mpe isam2':>9s} {'loop':>6s} {'oracle':>6s} {'/oracle':>7s} conv")
    for spec in paper_design(a.seed)[:a.runs]:
        stream = simulate_run(spec)
        loop_s, loop_mpe = reference_loop(stream, a.every)
        isam_s, est = timed_run(Isam2Mapper(stream.header, preset=a.preset, **opts), stream,
                                a.every)
        mpe = _mpe(est, stream)
        o = math.nan if a.no_oracle else oracle_mpe(stream)
        row = {"run": spec.name, "isam2_cpu_s": isam_s, "loop_cpu_s": loop_s,
               "ratio": isam_s / loop_s, "isam2_mpe_m": mpe, "loop_mpe_m": loop_mpe,
               "oracle_mpe_m": o, "vs_oracle": mpe / o,
               "converged": bool(est.info.get("converged")), "mode": est.info.get("mode"),
               "failures": est.info.get("update_failures")}
        rows.append(row)
        print(f"{spec.name:12s} {isam_s:8.2f} {loop_s:7.2f} {row['ratio']:6.2f} "
              f"{100 * mpe:9.3f} {100 * loop_mpe:6.3f} {100 * o:6.3f} {row['vs_oracle']:7.3f} "
              f"{row['converged']} {row['mode']} f={row['failures']}", flush=True)
    tot_i = sum(r["isam2_cpu_s"] for r in rows)
    tot_l = sum(r["loop_cpu_s"] for r in rows)
    summary: dict[str, Any] = {
        "options": opts, "preset": a.preset, "runs": len(rows), "isam2_cpu_s": tot_i,
        "loop_cpu_s": tot_l, "ratio": tot_i / tot_l,
        "mean_mpe_cm": 100 * float(np.nanmean([r["isam2_mpe_m"] for r in rows])),
        "max_vs_oracle": float(np.nanmax([r["vs_oracle"] for r in rows])),
        "rows": rows}
    print(f"total: isam2 {tot_i:.2f} s, loop {tot_l:.2f} s, ratio {tot_i / tot_l:.2f}; "
          f"mean MPE {summary['mean_mpe_cm']:.3f} cm; max isam2/oracle "
          f"{summary['max_vs_oracle']:.3f}")
    if a.long:
        stream = simulate_run(paper_design(a.seed)[0], SimConfig(n_steps=a.long))
        i_s, i_est = timed_run(Isam2Mapper(stream.header, preset=a.preset, **opts), stream,
                               a.every)
        b_s, b_est = timed_run(BatchMapper(stream.header), stream, a.every)
        summary["long"] = {"steps": a.long, "isam2_cpu_s": i_s, "batch_cpu_s": b_s,
                           "isam2_mpe_m": _mpe(i_est, stream), "batch_mpe_m": _mpe(b_est, stream)}
        print(f"long run, {a.long} steps: isam2 {i_s:.1f} s (MPE "
              f"{100 * summary['long']['isam2_mpe_m']:.2f} cm), batch {b_s:.1f} s (MPE "
              f"{100 * summary['long']['batch_mpe_m']:.2f} cm)")
    if a.out:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
