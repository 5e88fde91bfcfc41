"""The ``bomgraph`` command: argument parsing and printing only.

Every command is one library call plus printing. A user error (a BomgraphError) prints one
line to stderr and exits with status 2, without a traceback.
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any, Callable, Sequence

import numpy as np

from .errors import BomgraphError, ConfigError


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


def _positive_int(text: str) -> int:
    v = int(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {v}")
    return v


# --------------------------------------------------------------------------------------------
# Commands
# --------------------------------------------------------------------------------------------

def cmd_simulate(args: argparse.Namespace) -> int:
    from .sim import SimConfig, make_priors, simulate, with_priors
    from .stream_file import write_stream

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
    from .bench import run_file
    from .jsonio import parse_options
    from .estimate_file import write_estimate

    result = run_file(args.stream, args.method, parse_options(args.option),
                      checkpoint_every=args.checkpoint_every, allow_truth=args.allow_truth)
    write_estimate(result, args.out)
    print(f"{args.method}: {len(result.final)} landmarks mapped at t = "
          f"{result.checkpoints[-1].t} in {result.total_s:.3f} s; wrote {args.out}")
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    from .report import evaluate_files, format_evaluation

    ev = evaluate_files(args.estimate, args.stream, with_scale=args.similarity,
                        align_on=args.align, delta=args.delta, reference_path=args.reference)
    print(format_evaluation(ev, "json" if args.json else args.format))
    return 0


def cmd_plot(args: argparse.Namespace) -> int:
    from .figures import plot_results, plot_run

    if args.results:
        if args.estimate or args.stream:
            raise ConfigError("plot --results DIR takes no estimate or stream")
        path = plot_results(args.results, args.out, kind=args.kind,
                            experiments=args.experiments.split(",") if args.experiments else ())
    else:
        if not (args.estimate and args.stream):
            raise ConfigError("plot needs EST STREAM, or --results DIR")
        path = plot_run(args.estimate, args.stream, args.out, t=args.t, align_on=args.align)
    print(f"wrote {path}")
    return 0


def cmd_methods(args: argparse.Namespace) -> int:
    from .mapper import available_methods

    for info in available_methods():
        flag = "  (benchmark only: reads the truth)" if info.needs_truth else ""
        print(f"{info.name:18s} {info.description}{flag}")
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    from .bench import Executor
    from .experiments import paper_experiments, real_experiments, select
    from .report import compare, final_by_run, format_by_run, format_summary

    exps = (real_experiments(args.real) if args.real
            else paper_experiments(quick=args.quick, seed=args.seed))
    chosen = select(exps, args.experiments.split(",") if args.experiments else ())
    executor = Executor.choose(args.jobs, args.scheduler, args.dask_local)
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
        result = compare(chosen, args.out, executor=executor, use_cache=not args.no_cache,
                         figures=not args.no_figures, progress=progress)
    finally:
        if bar is not None:
            bar.close()
    print(format_summary(result.summary))
    if args.real:
        print(format_by_run(final_by_run(result.results)))
    print(f"\n{len(result.results)} runs in {result.wall_s:.1f} s; wrote "
          f"{', '.join(result.files)}")
    return 0


def _report_import(stream: Any, out: str) -> int:
    from .stream_file import write_stream

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
    e.add_argument("--align", choices=("landmarks", "trajectory", "both"), default="landmarks",
                   help="fit the alignment on the common landmarks (default), the robot "
                        "positions (as evo), or both together")
    e.add_argument("--delta", type=_positive_int, default=1, metavar="N",
                   help="steps between the two poses of a relative pose error (default 1)")
    e.add_argument("--reference", default=None, metavar="EST",
                   help="score against this estimate file instead of the stream's truth")
    e.add_argument("--format", choices=("text", "json", "csv", "markdown", "latex"),
                   default="text", help="output format (default text; --json = json)")
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

    pl = sub.add_parser("plot", help="draw one run over its truth, or a compare folder")
    pl.add_argument("estimate", nargs="?", help="an estimate file (bomgraph run)")
    pl.add_argument("stream", nargs="?", help="its stream file")
    pl.add_argument("--out", required=True, help="FILE.png, FILE.pdf or FILE.svg")
    pl.add_argument("--t", type=_nonneg_int, default=None,
                    help="draw the checkpoint at this step (default: the final map)")
    pl.add_argument("--align", choices=("landmarks", "trajectory", "both"), default="landmarks",
                    help="as for evaluate (default landmarks)")
    pl.add_argument("--results", default=None, metavar="DIR",
                    help="a `bomgraph compare` output folder: final MPE across runs and "
                         "error against time")
    pl.add_argument("--kind", choices=("box", "violin"), default="box",
                    help="with --results: box or violin plots (default box)")
    pl.add_argument("--experiments", default="",
                    help="with --results: comma-separated experiments (default: all)")
    pl.set_defaults(func=cmd_plot)

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
