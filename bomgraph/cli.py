"""The ``bomgraph`` command: argument parsing and printing only.

Every command is one library call plus printing. A user error (a BomgraphError) prints one
line to stderr and exits with status 2, without a traceback.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any, Callable, Sequence

import numpy as np

from .errors import BomgraphError


def _nonneg_int(text: str) -> int:
    v = int(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {v}")
    return v


def _jobs(text: str) -> int:
    v = int(text)
    if v == 0:
        raise argparse.ArgumentTypeError("must be a number of processes >= 1, or -1 for one "
                                         "per core")
    return v


def _finite_json(v: Any) -> Any:
    """NaN and infinities as JSON null (strict JSON has no NaN)."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {k: _finite_json(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_finite_json(x) for x in v]
    return v


def _positive_int(text: str) -> int:
    v = int(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {v}")
    return v


def _parse_options(pairs: Sequence[str]) -> dict[str, Any]:
    """``key=value`` pairs for a method's options; values parsed as JSON when they can be."""
    out: dict[str, Any] = {}
    for p in pairs:
        if "=" not in p:
            raise BomgraphError(f"--option takes key=value, got {p!r}")
        k, v = p.split("=", 1)
        if not k:
            raise BomgraphError(f"--option needs a name before '=', got {p!r}")
        try:
            out[k] = json.loads(v)
        except json.JSONDecodeError:
            out[k] = v
    return out


# --------------------------------------------------------------------------------------------
# Commands
# --------------------------------------------------------------------------------------------

def cmd_simulate(args: argparse.Namespace) -> int:
    from .sim import SimConfig, make_priors, simulate, with_priors
    from .stream import write_stream

    config = SimConfig(n_landmarks=args.landmarks, n_steps=args.steps,
                       sensor_range_m=args.sensor_range, noise_scale=args.noise_scale,
                       fov_rad=math.radians(args.fov_deg),
                       wrong_association_rate=args.wrong_association_rate)
    rng = np.random.default_rng(args.seed)
    stream = simulate(config, rng, meta={"seed": args.seed})
    if args.prior_fraction > 0:
        stream = with_priors(stream, make_priors(stream.truth, args.prior_fraction,
                                                 args.prior_sigma, rng))
    write_stream(stream, args.out)
    print(f"wrote {args.out}: {len(stream.steps)} steps, {config.n_landmarks} landmarks, "
          f"{len(stream.header.priors)} priors")
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    from .mapper import create_mapper, method_info, run, write_estimate
    from .stream import StreamReader

    options = _parse_options(args.option)
    if method_info(args.method).needs_truth and not args.allow_truth:
        raise BomgraphError(f"method {args.method!r} reads the ground truth; it is a benchmark "
                            f"bound, not a mapper (pass --allow-truth to run it anyway)")
    from threadpoolctl import threadpool_limits

    with StreamReader(args.stream) as reader, threadpool_limits(limits=1):
        mapper = create_mapper(args.method, reader.header, truth=reader.truth, **options)
        result = run(mapper, reader, checkpoint_every=args.checkpoint_every,
                     method=args.method)
    write_estimate(result, args.out)
    est = result.final
    print(f"{args.method}: {len(est)} landmarks mapped at t = {result.checkpoints[-1].t} "
          f"in {result.total_s:.3f} s; wrote {args.out}")
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    from .evaluate import error_table, score_estimate
    from .mapper import read_estimate
    from .stream import read_stream

    est = read_estimate(args.estimate)
    stream = read_stream(args.stream)
    if stream.truth is None:
        raise BomgraphError(f"{args.stream}: the stream has no ground truth to evaluate "
                            f"against")
    score = score_estimate(est.final, stream.truth, with_scale=args.similarity)
    table = error_table(est.checkpoints, stream.truth) if est.checkpoints else None
    if args.json:
        out = {"method": est.method, **score.as_dict()}
        if table is not None:
            out["checkpoints"] = {k: v.tolist() for k, v in table.items()}
        print(json.dumps(_finite_json(out), allow_nan=False))
        return 0
    print(f"method {est.method}: {score.n_common} of {score.n_truth} landmarks mapped "
          f"({score.n_mapped} in the estimate)")
    print(f"  landmark MPE {100 * score.mpe_m:.2f} cm, RMSE {100 * score.rmse_m:.2f} cm, "
          f"median {100 * score.median_m:.2f} cm, max {100 * score.max_m:.2f} cm")
    if score.n_poses:
        print(f"  robot position error: last {100 * score.robot_last_m:.2f} cm, mean over "
              f"{score.n_poses} poses {100 * score.robot_mean_m:.2f} cm")
    if table is not None and len(table["t"]) > 1:
        print("  t      MPE [cm]  mapped")
        for t, m, n in zip(table["t"], table["mpe_m"], table["n_mapped"]):
            print(f"  {t:<6d} {100 * m:8.2f}  {n:6d}")
    return 0


def cmd_methods(args: argparse.Namespace) -> int:
    from .mapper import available_methods

    for info in available_methods():
        flag = "  (benchmark only: reads the truth)" if info.needs_truth else ""
        print(f"{info.name:18s} {info.description}{flag}")
    return 0


def _cm(v: float) -> str:
    return "   -  " if v is None or not math.isfinite(v) else f"{100 * v:6.2f}"


def format_summary(summary: Sequence[dict]) -> str:
    """The comparison table as text: one block per experiment, one row per arm."""
    lines = []
    by_exp: dict[str, list[dict]] = {}
    for row in summary:
        by_exp.setdefault(row["experiment"], []).append(row)
    for exp, rows in by_exp.items():
        times = sorted({int(k.split("@")[1]) for r in rows for k in r if k.startswith("mpe_mean_m@")})
        lines.append(f"\n== {exp} ==  landmark MPE [cm] mean/median±std at t; robot: error "
                     f"[cm] of the latest pose at the end; conv: converged runs; NEES: robot "
                     f"pose; wall time per run; [k/n]: only k of n runs had a map")
        head = f"{'arm':30s} {'runs':>4s} " + " ".join(f"{'t=' + str(t):>17s}" for t in times)
        head += f" {'robot':>7s} {'conv':>5s} {'NEES':>6s} {'wall s':>7s}  paper"
        lines.append(head)
        for r in rows:
            cells = []
            for t in times:
                m, md, sd = (r.get(f"mpe_mean_m@{t}"), r.get(f"mpe_median_m@{t}"),
                             r.get(f"mpe_std_m@{t}"))
                cell = f"{_cm(m).strip()}/{_cm(md).strip()}±{_cm(sd).strip()}"
                scored, ran = r.get(f"n_scored@{t}", 0), r["runs"] - r["failed"]
                if scored < ran:  # runs without a map yet are not averaged in: say so
                    cell += f"[{scored}/{ran}]"
                cells.append(cell)
            conv = r.get("converged_rate")
            conv_s = "  -  " if conv is None or not math.isfinite(conv) else f"{100 * conv:4.0f}%"
            nees = r.get("nees_pose_mean")
            nees_s = "   -  " if nees is None or not math.isfinite(nees) else f"{nees:6.2f}"
            fail = f"  FAILED {r['failed']}: {'; '.join(r['errors'])[:120]}" if r["failed"] else ""
            lines.append(f"{r['arm'][:30]:30s} {r['runs']:4d} " + " ".join(f"{c:>17s}" for c in cells)
                         + f" {_cm(r.get('robot_last_mean_m')):>7s} {conv_s:>5s} {nees_s:>6s}"
                         f" {r.get('wall_s_mean', float('nan')):7.3f}  {r.get('paper', '')}{fail}")
    return "\n".join(lines)


def format_by_run(rows: Sequence[dict]) -> str:
    """Final landmark MPE [cm] (landmarks mapped) per arm and run, one block per experiment."""
    lines = []
    by_exp: dict[str, list[dict]] = {}
    for row in rows:
        by_exp.setdefault(row["experiment"], []).append(row)
    for exp, rs in by_exp.items():
        runs = list(dict.fromkeys(r["run"] for r in rs))
        arms = list(dict.fromkeys(r["arm"] for r in rs))
        cell = {(r["arm"], r["run"]): r for r in rs}
        lines.append(f"\n== {exp}, final map per run ==  landmark MPE [cm] (landmarks mapped); "
                     f"'no map': fewer than 3 landmarks; FAILED: the run raised")
        lines.append(f"{'arm':30s} " + " ".join(f"{r[-14:]:>14s}" for r in runs))
        for arm in arms:
            cells = []
            for run_name in runs:
                r = cell.get((arm, run_name))
                if r is None:
                    cells.append("")
                elif not r["ok"]:
                    cells.append("FAILED")
                elif not math.isfinite(r["mpe_m"]):
                    cells.append(f"no map ({r['n_mapped']})")
                else:
                    cells.append(f"{100 * r['mpe_m']:.1f} ({r['n_mapped']})")
            lines.append(f"{arm[:30]:30s} " + " ".join(f"{c:>14s}" for c in cells))
    return "\n".join(lines)


def cmd_compare(args: argparse.Namespace) -> int:
    from .bench import Executor, compare, paper_experiments

    if args.real:
        from .bench import real_experiments

        exps = real_experiments(args.real)
    else:
        exps = paper_experiments(quick=args.quick, seed=args.seed)
    names = args.experiments.split(",") if args.experiments else list(exps)
    unknown = [n for n in names if n not in exps]
    if unknown:
        raise BomgraphError(f"unknown experiment(s) {unknown}; choose from {list(exps)}")
    if args.scheduler or args.dask_local:
        executor = Executor("dask", scheduler=args.scheduler, dask_local=args.dask_local or 0)
    elif args.jobs == 1:
        executor = Executor("serial")
    else:
        executor = Executor("processes", n_jobs=args.jobs)
    bar = None
    if not args.no_progress:
        from tqdm import tqdm

        bar = tqdm(total=0, unit="run", desc="compare", file=sys.stderr)

    def progress(done: int, total: int) -> None:
        if bar is not None:
            bar.total = total
            bar.n = done
            bar.refresh()

    try:
        result = compare([exps[n] for n in names], args.out, executor=executor,
                         use_cache=not args.no_cache, figures=not args.no_figures,
                         progress=progress)
    finally:
        if bar is not None:
            bar.close()
    print(format_summary(result.summary))
    if args.real:
        from .bench import final_by_run

        print(format_by_run(final_by_run(result.results)))
    print(f"\n{len(result.results)} runs in {result.wall_s:.1f} s; wrote "
          f"{', '.join(result.files)}")
    return 0


def _report_import(stream: Any, out: str) -> int:
    from .stream import write_stream

    write_stream(stream, out)
    n_brg = sum(len(st.landmark_ids) for st in stream.steps)
    truth = "no truth" if stream.truth is None else (
        "truth: landmarks only" if stream.truth.poses is None else "truth: poses + landmarks")
    print(f"wrote {out}: {len(stream.steps)} steps, {n_brg} bearings, "
          f"{len(stream.landmark_ids())} landmarks; bearing sigma "
          f"{stream.header.bearing_sigma_rad:.4f} rad, odometry sigma "
          f"{', '.join(f'{v:.4f}' for v in stream.header.odometry_sigma)}; {truth}")
    return 0


def cmd_import_mrclam(args: argparse.Namespace) -> int:
    from .datasets.mrclam import KeyframeConfig, import_mrclam

    given = {"min_distance_m": args.min_distance, "min_turn_rad": args.min_turn,
             "attach_window_s": args.attach_window}
    keyframe = KeyframeConfig(**{k: v for k, v in given.items() if v is not None})
    return _report_import(import_mrclam(args.dir, args.robot, keyframe=keyframe,
                                        keep_ranges=args.keep_ranges,
                                        calibrate=not args.no_calibrate), args.out)


def cmd_import_g2o(args: argparse.Namespace) -> int:
    from .datasets.g2o import import_g2o

    return _report_import(import_g2o(args.file, truth_path=args.truth,
                                     bearing_sigma_rad=args.bearing_sigma), args.out)


def cmd_import_victoria(args: argparse.Namespace) -> int:
    from .datasets.victoria import import_victoria

    return _report_import(import_victoria(args.file, bearing_sigma_rad=args.bearing_sigma),
                          args.out)


# --------------------------------------------------------------------------------------------
# Parser
# --------------------------------------------------------------------------------------------

def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bomgraph", description="Bearing-only mapping toolkit: "
                                "BOM-STMDS and SLAM baselines side by side.")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("simulate", help="simulate a run of the paper's world into a stream file")
    s.add_argument("--seed", type=_nonneg_int, default=0)
    s.add_argument("--landmarks", type=_positive_int, default=50)
    s.add_argument("--steps", type=int, default=300, help="number of moves (default 300)")
    s.add_argument("--sensor-range", type=float, default=1.0, help="metres (default 1.0)")
    s.add_argument("--fov-deg", type=float, default=360.0, help="field of view (default 360)")
    s.add_argument("--noise-scale", type=float, default=1.0,
                   help="multiplies the paper's noise; 0 gives noise-free data")
    s.add_argument("--wrong-association-rate", type=float, default=0.0)
    s.add_argument("--prior-fraction", type=float, default=0.0,
                   help="fraction of landmark pairs with a known distance (Exp. 3: 0.1)")
    s.add_argument("--prior-sigma", type=float, default=0.03, help="metres per axis")
    s.add_argument("--out", required=True)
    s.set_defaults(func=cmd_simulate)

    r = sub.add_parser("run", help="run a method on a stream file and write its estimate")
    r.add_argument("stream")
    r.add_argument("--method", required=True, help="see `bomgraph methods`")
    r.add_argument("--out", required=True)
    r.add_argument("--checkpoint-every", type=_positive_int, default=10)
    r.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="a method option (repeatable)")
    r.add_argument("--allow-truth", action="store_true", help=argparse.SUPPRESS)
    r.set_defaults(func=cmd_run)

    e = sub.add_parser("evaluate", help="score an estimate file against a stream's truth")
    e.add_argument("estimate")
    e.add_argument("stream")
    e.add_argument("--json", action="store_true", help="print one JSON object")
    e.add_argument("--similarity", action="store_true", help="also fit a scale")
    e.set_defaults(func=cmd_evaluate)

    c = sub.add_parser("compare", help="the paper's experiments, every method side by side")
    c.add_argument("--quick", action="store_true",
                   help="2 runs of 150 steps per arm (a demo), instead of 25 runs of 300")
    c.add_argument("--experiments", default="",
                   help="comma-separated subset of exp1,exp2,exp3,all (default: all four); "
                        "with --real: mrclam6,g2o")
    c.add_argument("--real", default=None, metavar="DATA_DIR",
                   help="every method on the recorded datasets under DATA_DIR (e.g. "
                        "../shared/data) instead of the simulation")
    c.add_argument("--out", default="compare-results", help="output folder")
    c.add_argument("--seed", type=_nonneg_int, default=0)
    c.add_argument("--jobs", type=_jobs, default=-1, help="local processes (-1: one per core)")
    c.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run on an existing Dask distributed scheduler, e.g. tcp://host:8786")
    c.add_argument("--dask-local", type=int, default=0, metavar="N",
                   help="start a local Dask cluster of N worker processes")
    c.add_argument("--no-cache", action="store_true", help="ignore and do not write the cache")
    c.add_argument("--no-figures", action="store_true")
    c.add_argument("--no-progress", action="store_true")
    c.set_defaults(func=cmd_compare)

    i = sub.add_parser("import", help="turn a real dataset into a stream file")
    isub = i.add_subparsers(dest="dataset", required=True)
    im = isub.add_parser("mrclam", help="one robot of a UTIAS MRCLAM folder, keyframed")
    im.add_argument("dir", help="the dataset folder (.dat or .dat.gz files)")
    im.add_argument("--robot", type=int, required=True, choices=range(1, 6), metavar="{1..5}")
    im.add_argument("--out", required=True)
    im.add_argument("--min-distance", type=float, help="keyframe distance, metres "
                    "(default: KeyframeConfig's, 0.3)")
    im.add_argument("--min-turn", type=float, help="keyframe turn, radians (default 0.3)")
    im.add_argument("--attach-window", type=float, help="seconds (default 0.6)")
    im.add_argument("--keep-ranges", action="store_true", help="keep ranges in the meta")
    im.add_argument("--no-calibrate", action="store_true",
                    help="use the default sigmas (needed without robot ground truth, mrclam1)")
    im.set_defaults(func=cmd_import_mrclam)
    ig = isub.add_parser("g2o", help="a bearing-only g2o file")
    ig.add_argument("file")
    ig.add_argument("--truth", default=None, help="a g2o file whose vertices are the truth")
    ig.add_argument("--bearing-sigma", type=float, default=None,
                    help="radians (default: from the bearing edges' information)")
    ig.add_argument("--out", required=True)
    ig.set_defaults(func=cmd_import_g2o)
    iv = isub.add_parser("victoria", help="GTSAM's victoria_park.txt")
    iv.add_argument("file")
    iv.add_argument("--bearing-sigma", type=float, default=None,
                    help="radians (default: median propagated point covariance)")
    iv.add_argument("--out", required=True)
    iv.set_defaults(func=cmd_import_victoria)

    m = sub.add_parser("methods", help="list the available methods")
    m.set_defaults(func=cmd_methods)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    func: Callable[[argparse.Namespace], int] = args.func
    try:
        return func(args)
    except BomgraphError as exc:
        print(f"bomgraph: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"bomgraph: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
