"""Each method's recording setting on recordings it was not tuned on (issue 15, item 6).

    python scripts/bench_generality.py [--data ../shared/data] [--work results/generality]
                                       [--methods a,b,...] [--robots 1,2,3,4,5] [--jobs N]
                                       [--families m6,m6dense,...]
                                       [--cadence [FAMILIES]]

The ``real`` presets were chosen on MRCLAM6 as ``bomgraph import mrclam`` keyframes it
(0.3 m / 0.3 rad, sigmas calibrated against the robot truth). This script reports them,
unchanged, on streams nobody tuned on, made with the user's own commands:

* ``m6``       MRCLAM6, the default import (the tuning data, for reference);
* ``m6dense``  MRCLAM6 re-imported with ``--min-distance 0.1 --min-turn 0.1745``;
* ``m6sigx0.5`` / ``m6sigx2``  the ``m6`` streams with the header's bearing sigma halved /
  doubled (a MAD-style small calibration, a generous one);
* ``m1`` / ``m1dense``  MRCLAM1 (landmark truth only, imported ``--no-calibrate``) at both
  keyframings;
* ``m1cal`` / ``m1densecal``  the same with each robot's odometry length calibrated on
  MRCLAM6 (``--odometry-scale``, the robot's ``odometry_length_ratio`` against the MRCLAM6
  truth: the same five robots; not a family of the issue, shown beside it).

For every stream and method it prints the final map's landmark MPE (cm) and the number of
landmarks mapped, then the issue's target ratios: each method against ``oracle`` on the same
stream (on MRCLAM1, which has no robot truth for the oracle, against the best method on that
stream), beside it the same ratio with both maps scored on the landmarks both mapped (each
aligned on that common set alone: the whole-map ratio compares different landmark sets where
the two map different landmarks), dense against default keyframing, sigma x0.5 / x2 against
the calibrated sigma. With
``--cadence [FAMILIES]`` it also runs each method on the streams of those families (``m6``
if none are named) with a single checkpoint at the end and reports the worst ratio to the
default cadence (every 10 steps) on the same stream.

A method without a ``real`` preset runs its defaults and is marked ``*``. Everything is
written as JSON to ``WORK/generality.json``; the streams are imported once into
``WORK/streams`` (never into the repository).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from bomgraph.bench import run_file
from bomgraph.cli import main as bomgraph_main
from bomgraph.datasets.calibration import odometry_length_ratio
from bomgraph.errors import BomgraphError
from bomgraph.evaluate import score_estimate
from bomgraph.jsonio import jsonable
from bomgraph.mapper import MapEstimate, available_methods, method_config_class, method_info
from bomgraph.stream_file import StreamReader

FAMILIES = ("m6", "m6dense", "m6sigx0.5", "m6sigx2", "m1", "m1dense", "m1cal", "m1densecal")
#: MRCLAM1 with each robot's odometry length calibrated on MRCLAM6 (the same robots): the
#: factor ``--odometry-scale`` is the robot's ``odometry_length_ratio`` against the MRCLAM6
#: truth (default import). Not a family of issue 15; shown beside ``m1`` / ``m1dense``.
CALIBRATED = ("m1cal", "m1densecal")
DENSE = ("--min-distance", "0.1", "--min-turn", "0.1745")
SIGMA_SCALE = {"m6sigx0.5": 0.5, "m6sigx2": 2.0}


def length_ratio_of(path: Path) -> float:
    """A stream's odometry length ratio against its truth poses
    (:func:`bomgraph.datasets.calibration.odometry_length_ratio`)."""
    with StreamReader(path) as reader:
        steps = list(reader)
        truth = reader.truth
    odoms = np.array([s.odom for s in steps[1:]], dtype=float).reshape(-1, 3)
    ratio = odometry_length_ratio(odoms, truth.poses)
    if ratio is None:
        raise SystemExit(f"{path}: no step moved; no odometry length ratio")
    return ratio


def make_streams(data: Path, work: Path, robots: list[int]) -> dict[str, dict[int, Path]]:
    """Import (once) every stream of the table; return ``{family: {robot: path}}``."""
    out: dict[str, dict[int, Path]] = {f: {} for f in FAMILIES}
    work.mkdir(parents=True, exist_ok=True)
    for r in robots:
        for fam, src, extra in (("m6", "mrclam6", ()), ("m6dense", "mrclam6", DENSE),
                                ("m1", "mrclam1", ("--no-calibrate",)),
                                ("m1dense", "mrclam1", ("--no-calibrate", *DENSE))):
            path = work / f"{fam}_r{r}.jsonl"
            if not path.exists():
                rc = bomgraph_main(["import", "mrclam", str(data / src), "--robot", str(r),
                                    "--out", str(path), "-q", *extra])
                if rc:
                    raise SystemExit(f"import of {src} robot {r} failed (exit {rc})")
            out[fam][r] = path
        for fam, scale in SIGMA_SCALE.items():
            path = work / f"{fam}_r{r}.jsonl"
            if not path.exists():
                lines = out["m6"][r].read_text().splitlines(keepends=True)
                header = json.loads(lines[0])
                header["bearing_sigma_rad"] = header["bearing_sigma_rad"] * scale
                tmp = path.with_suffix(".tmp")
                tmp.write_text(json.dumps(header) + "\n" + "".join(lines[1:]))
                tmp.replace(path)
            out[fam][r] = path
        scale = f"{length_ratio_of(out['m6'][r]):.4f}"
        for fam in CALIBRATED:
            path = work / f"{fam}_r{r}.jsonl"
            if not path.exists():
                extra = ("--no-calibrate", *(DENSE if "dense" in fam else ()))
                rc = bomgraph_main(["import", "mrclam", str(data / "mrclam1"), "--robot",
                                    str(r), "--out", str(path), "-q", "--odometry-scale",
                                    scale, *extra])
                if rc:
                    raise SystemExit(f"import of mrclam1 robot {r} failed (exit {rc})")
            out[fam][r] = path
    return out


def has_real(method: str) -> bool:
    cls = method_config_class(method)
    return cls is not None and "real" in getattr(cls, "PRESETS", {})


def one_run(stream: Path, method: str, checkpoint_every: int) -> dict[str, Any]:
    """The final map of ``method`` (preset ``real`` where it has one) scored on ``stream``."""
    options = {"preset": "real"} if has_real(method) else {}
    row: dict[str, Any] = {"stream": stream.stem, "method": method,
                           "preset": options.get("preset", "default"),
                           "checkpoint_every": checkpoint_every}
    t0 = time.process_time()
    if method_info(method).needs_truth:
        with StreamReader(stream) as reader:
            truth = reader.truth
        if truth is None or truth.poses is None:  # not run, not a failure: printed "no truth"
            row.update(mpe_m=math.nan, n_mapped=0, no_truth=True, cpu_s=0.0)
            return row
    try:
        result = run_file(stream, method, options, checkpoint_every=checkpoint_every,
                          allow_truth=True)
        with StreamReader(stream) as reader:
            truth = reader.truth
        score = score_estimate(result.final, truth)
        similar = score_estimate(result.final, truth, with_scale=True)
        row.update(mpe_m=score.mpe_m, n_mapped=score.n_mapped, n_truth=score.n_truth,
                   mpe_similarity_m=similar.mpe_m, similarity_scale=similar.alignment.scale,
                   converged=result.final.info.get("converged"),
                   landmark_ids=result.final.landmark_ids.tolist(),
                   landmarks_xy=result.final.landmarks_xy.tolist())
    except BomgraphError as exc:
        row.update(mpe_m=math.nan, n_mapped=0, error=f"{type(exc).__name__}: {exc}")
    row["cpu_s"] = time.process_time() - t0
    return row


def _ratio(a: float, b: float) -> float:
    return a / b if (math.isfinite(a) and math.isfinite(b) and b > 0) else math.nan


def common_set_mpe(a: dict[str, Any], b: dict[str, Any], truth: Any) -> tuple[float, float, int]:
    """MPE (m) of the final maps of rows ``a`` and ``b`` on the landmarks both mapped, each
    aligned on that common set alone, and the size of the set (NaN below 3 landmarks).

    "vs bound" compares each method's whole map with the bound's whole map; where the two map
    different landmarks (the oracle leaves out landmarks whose rays on the true poses do not
    pass its parallax test, MRCLAM6 robot 4), this is the like-for-like figure beside it."""
    if not (a.get("landmark_ids") and b.get("landmark_ids")):
        return math.nan, math.nan, 0
    ids = np.intersect1d(a["landmark_ids"], b["landmark_ids"])
    if ids.size < 3:
        return math.nan, math.nan, int(ids.size)
    out = []
    for r in (a, b):
        lid = np.asarray(r["landmark_ids"], dtype=np.int64)
        keep = np.isin(lid, ids)
        est = MapEstimate(lid[keep], np.asarray(r["landmarks_xy"], dtype=float)[keep])
        out.append(score_estimate(est, truth).mpe_m)
    return out[0], out[1], int(ids.size)


def common_set_ratios(rows: list[dict[str, Any]], truths: dict[str, Any]) -> dict[str, dict]:
    """Per stream and method: the method's MPE over the bound's on the landmarks both mapped
    (:func:`common_set_mpe`); the bound as in :func:`summarise` (the oracle; on MRCLAM1 the
    best method by whole-map MPE), which scores 1 against itself as in "vs bound"."""
    by = {(r["stream"], r["method"]): r for r in rows
          if r["checkpoint_every"] == 10 and math.isfinite(r["mpe_m"])}
    out: dict[str, dict] = {}
    for s in sorted({k[0] for k in by}):
        if s.startswith("m1"):
            cands = [r for (ss, m), r in by.items() if ss == s and m != "oracle"]
            bound = min(cands, key=lambda r: r["mpe_m"]) if cands else None
        else:
            bound = by.get((s, "oracle"))
        if bound is None or s not in truths:
            continue
        for (ss, m), r in by.items():
            if ss != s:
                continue
            # the bound against itself: the same map twice, ratio 1 (as in "vs bound")
            mine, theirs, n = common_set_mpe(r, bound, truths[s])
            out.setdefault(m, {})[s] = {"ratio": _ratio(mine, theirs), "n_common": n,
                                        "mpe_m": mine, "bound_mpe_m": theirs,
                                        "bound": bound["method"]}
    return out


def summarise(rows: list[dict[str, Any]], methods: list[str], robots: list[int],
              families: tuple[str, ...] = FAMILIES, key: str = "mpe_m") -> dict:
    """The issue's target ratios, per method, as worst case over the robots, of the rows'
    ``key`` (``"mpe_m"``, the issue's rigid alignment; ``"mpe_similarity_m"``, the map's shape
    after a similarity fit, which leaves out the scale that bearings cannot observe and the
    odometry sets)."""
    mpe = {(r["stream"], r["method"], r["checkpoint_every"]): r.get(key, math.nan)
           for r in rows}
    no_truth = {(r["stream"], r["method"]) for r in rows if r.get("no_truth")}

    def bound_of(s: str) -> float:  # the oracle; on MRCLAM1 (no robot truth) the best method
        if s.startswith("m1"):
            finite = [v for (ss, mm, ce), v in mpe.items()
                      if ss == s and ce == 10 and mm != "oracle" and math.isfinite(v)]
            return min(finite) if finite else math.nan
        return mpe.get((s, "oracle", 10), math.nan)

    def rel(s: str, m: str) -> float:  # the method against the bound on the same stream
        return _ratio(mpe.get((s, m, 10), math.nan), bound_of(s))

    summary: dict[str, dict[str, float]] = {}
    for m in methods:
        vs_bound, dense, sig_lo, sig_hi, cadence = [], [], [], [], []
        dense_rel, sig_lo_rel, sig_hi_rel = [], [], []
        for r in robots:
            for fam in families:
                vs_bound.append(rel(f"{fam}_r{r}", m))
            base = mpe.get((f"m6_r{r}", m, 10), math.nan)
            dense.append(_ratio(mpe.get((f"m6dense_r{r}", m, 10), math.nan), base))
            for lo, hi in (("m1", "m1dense"), ("m1cal", "m1densecal")):
                dense.append(_ratio(mpe.get((f"{hi}_r{r}", m, 10), math.nan),
                                    mpe.get((f"{lo}_r{r}", m, 10), math.nan)))
            sig_lo.append(_ratio(mpe.get((f"m6sigx0.5_r{r}", m, 10), math.nan), base))
            sig_hi.append(_ratio(mpe.get((f"m6sigx2_r{r}", m, 10), math.nan), base))
            for fam in FAMILIES:
                cadence.append(_ratio(mpe.get((f"{fam}_r{r}", m, 100000), math.nan),
                                      mpe.get((f"{fam}_r{r}", m, 10), math.nan)))
            # the same ratios with each stream's bound divided out: a denser keyframing
            # carries more bearings and moves the bound itself (robot 2: 25 -> 10 cm)
            if m != "oracle":
                dense_rel.append(_ratio(rel(f"m6dense_r{r}", m), rel(f"m6_r{r}", m)))
                dense_rel.append(_ratio(rel(f"m1dense_r{r}", m), rel(f"m1_r{r}", m)))
                dense_rel.append(_ratio(rel(f"m1densecal_r{r}", m), rel(f"m1cal_r{r}", m)))
                sig_lo_rel.append(_ratio(rel(f"m6sigx0.5_r{r}", m), rel(f"m6_r{r}", m)))
                sig_hi_rel.append(_ratio(rel(f"m6sigx2_r{r}", m), rel(f"m6_r{r}", m)))

        def worst(v: list[float], two_sided: bool = True) -> float:
            v = [x for x in v if not math.isnan(x)]
            if not v:
                return math.nan
            return max(max(x, 1 / x) for x in v) if two_sided else max(v)

        summary[m] = {"max_vs_bound": worst(vs_bound, two_sided=False),
                      "keyframing": worst(dense), "sigma_x0.5": worst(sig_lo),
                      "sigma_x2": worst(sig_hi), "cadence": worst(cadence),
                      "keyframing_vs_bound": worst(dense_rel),
                      "sigma_x0.5_vs_bound": worst(sig_lo_rel),
                      "sigma_x2_vs_bound": worst(sig_hi_rel),
                      # the method's own runs printed "fail" (not a stream whose bound
                      # failed, where the ratio is NaN too)
                      "failed_runs": sum(1 for r in robots for fam in families if not
                                         math.isfinite(mpe.get((f"{fam}_r{r}", m, 10),
                                                               math.nan))
                                         and (f"{fam}_r{r}", m) not in no_truth)}
    return summary


def worst_common(common: dict[str, dict], methods: list[str]) -> dict[str, float]:
    """Per method, the largest ratio of :func:`common_set_ratios` over the streams (NaN where
    no stream has 3 landmarks in common with its bound): "vs bound" on the common set."""
    out = {}
    for m in methods:
        v = [c["ratio"] for c in common.get(m, {}).values() if math.isfinite(c["ratio"])]
        out[m] = max(v) if v else math.nan
    return out


def width_of(methods: list[str]) -> int:
    """The method column's width in the printed tables."""
    return max(12, *(len(m) + 1 for m in methods))


def print_tables(rows: list[dict[str, Any]], methods: list[str], robots: list[int],
                 summary: dict, families: tuple[str, ...] = FAMILIES) -> None:
    by = {(r["stream"], r["method"]): r for r in rows if r["checkpoint_every"] == 10}
    width = width_of(methods)
    print("Final-map landmark MPE, cm (landmarks mapped); * = no `real` preset, defaults")
    print("stream".ljust(14) + "".join(
        (m + ("" if has_real(m) else "*")).rjust(width + 5) for m in methods))
    for fam in families:
        for r in robots:
            s = f"{fam}_r{r}"
            cells = []
            for m in methods:
                row = by.get((s, m))
                if row is not None and row.get("no_truth"):  # a bound without the truth
                    cells.append("no truth".rjust(width + 5))
                elif row is None or not math.isfinite(row["mpe_m"]):
                    cells.append("fail".rjust(width + 5))
                else:
                    cells.append(f"{100 * row['mpe_m']:.1f} ({row['n_mapped']})"
                                 .rjust(width + 5))
            print(s.ljust(14) + "".join(cells))
    print()
    print("Worst ratio over the robots (targets: vs bound <= 2, GTSAM methods <= 1.1; "
          "keyframing and sigma <= 1.25; cadence <= 1.05)")
    keys = ("max_vs_bound", "max_vs_bound_common", "keyframing", "sigma_x0.5", "sigma_x2",
            "cadence", "failed_runs")
    labels = ("vs_bound", "vs_bound_common", *keys[2:])
    print("method".ljust(width) + "".join(k.rjust(17) for k in labels))
    for m in methods:
        print(m.ljust(width) + "".join(
            (str(summary[m][k]) if k == "failed_runs" else
             f"{summary[m].get(k, math.nan):.2f}").rjust(17) for k in keys))
    print("vs_bound compares the whole maps (the target measure); vs_bound_common scores "
          "both maps on the landmarks both mapped, each aligned on that set alone.")
    print()
    print("The same, each stream's MPE divided by its bound first (a denser keyframing or "
          "another sigma moves the bound too)")
    keys = ("keyframing_vs_bound", "sigma_x0.5_vs_bound", "sigma_x2_vs_bound")
    print("method".ljust(width) + "".join(k.rjust(22) for k in keys))
    for m in methods:
        print(m.ljust(width) + "".join(f"{summary[m][k]:.2f}".rjust(22) for k in keys))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default_data = os.environ.get("BOMGRAPH_DATA",
                                  str(Path(__file__).resolve().parents[2] / "shared" / "data"))
    ap.add_argument("--data", default=default_data)
    ap.add_argument("--work", default="results/generality")
    ap.add_argument("--methods", default=None,
                    help="comma-separated (default: every registered method but triangulate)")
    ap.add_argument("--robots", default="1,2,3,4,5")
    ap.add_argument("--families", default=",".join(FAMILIES),
                    help=f"comma-separated subset of {', '.join(FAMILIES)}")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--cadence", nargs="?", const="m6", default=None, metavar="FAMILIES",
                    help="also run each method with one final checkpoint on the streams of "
                         "these families (comma-separated; m6 if none given)")
    args = ap.parse_args(argv)

    robots = [int(r) for r in args.robots.split(",")]
    methods = (args.methods.split(",") if args.methods else
               [m.name for m in available_methods() if m.name != "triangulate"])
    if "oracle" not in methods:
        methods.append("oracle")
    work = Path(args.work)
    streams = make_streams(Path(args.data), work / "streams", robots)
    families = [f for f in args.families.split(",") if f]
    unknown = sorted(set(families) - set(FAMILIES))
    if unknown:
        ap.error(f"unknown stream families {unknown}; choose from {', '.join(FAMILIES)}")
    jobs = [(streams[f][r], m, 10) for f in families for r in robots for m in methods]
    if args.cadence:
        cad = [f for f in args.cadence.split(",") if f]
        unknown = sorted(set(cad) - set(FAMILIES))
        if unknown:
            ap.error(f"unknown --cadence families {unknown}; choose from {', '.join(FAMILIES)}")
        jobs += [(streams[f][r], m, 100000) for f in cad for r in robots for m in methods]
    t0 = time.perf_counter()
    if args.jobs > 1:
        from joblib import Parallel, delayed
        rows = Parallel(n_jobs=args.jobs)(delayed(one_run)(*j) for j in jobs)
    else:
        rows = [one_run(*j) for j in jobs]
    summary = summarise(rows, methods, robots, tuple(families))
    truths = {}
    for f in families:
        for r in robots:
            with StreamReader(streams[f][r]) as reader:
                truths[f"{f}_r{r}"] = reader.truth
    common = common_set_ratios(rows, truths)
    for m, v in worst_common(common, methods).items():
        summary[m]["max_vs_bound_common"] = v
    print_tables(rows, methods, robots, summary, tuple(families))
    shape = summarise(rows, methods, robots, tuple(families), key="mpe_similarity_m")
    for m in methods:
        summary.setdefault(m, {})["max_vs_bound_similarity"] = shape[m]["max_vs_bound"]
    print()
    print("vs bound after a similarity fit (the map's shape; bearings do not observe scale, the "
          "odometry sets it): worst stream per method")
    for m in methods:
        print(f"{m.ljust(width_of(methods))}{shape[m]['max_vs_bound']:8.2f}")
    print()
    print("vs bound on the landmarks both mapped (each map aligned on that set alone): worst "
          "stream per method")
    for m in methods:
        cells = common.get(m, {})
        if not cells:
            continue
        s_worst = max(cells, key=lambda k: (math.isfinite(cells[k]["ratio"]),
                                            cells[k]["ratio"]))
        c = cells[s_worst]
        print(f"{m.ljust(width_of(methods))}{summary[m]['max_vs_bound_common']:8.2f}  "
              f"({s_worst}: {100 * c['mpe_m']:.1f} vs {c['bound']} {100 * c['bound_mpe_m']:.1f} "
              f"cm on {c['n_common']})")
    out = work / "generality.json"
    tmp = out.with_suffix(".tmp")
    tmp.write_text(json.dumps(jsonable({"rows": rows, "summary": summary, "common": common,
                                        "wall_s": time.perf_counter() - t0}), indent=1))
    tmp.replace(out)
    print(f"\n{len(rows)} runs in {time.perf_counter() - t0:.0f} s; wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
