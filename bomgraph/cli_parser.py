"""The ``bomgraph`` command's argument parser: every subcommand, its options and their types.

:func:`build_parser` names each subcommand's handler in ``func`` (the name of a ``cmd_*``
function of :mod:`bomgraph.cli`, which dispatches on it), so this module imports nothing of the
commands themselves.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from typing import IO, Any, Callable, NoReturn, Sequence

#: a run over this many steps shows a progress bar (when stderr is a terminal).
PROGRESS_MIN_STEPS = 1000
#: said on every --out that names a file: the documented policy (docs/FORMATS.md, "Output
#: paths"): a regular file there is replaced (written beside it, renamed into place); an input
#: file is refused; a link is followed, a device or FIFO written to.
REPLACES = "; an existing file of that name is replaced (never an input file)"


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line and exit 2 (bad input gets one
    line): ``bomgraph run: error: the following arguments are required: stream; see bomgraph
    run --help``, not the usage block first. Its subcommands' parsers are of this class too
    (argparse makes them of their parent's)."""

    def _print_message(self, message: str, file: IO[str] | None = None) -> None:
        # help and --version go to stdout (file: sys.stdout); closed (``>&-``: None) argparse
        # wrote them to stderr, where every command's own lines are dropped (h101). Errors
        # name sys.stderr.
        # An error writing them (``--help > /dev/full``) is the command's output error, as any
        # command's (one line, exit 2; a closed pipe: quiet), where argparse ignored it (exit
        # 0, nothing said; h107): written and flushed here, the error raised.
        if file is None or not message:
            return
        if file is sys.stderr:
            super()._print_message(message, file)
            return
        file.write(message)
        file.flush()

    def error(self, message: str) -> NoReturn:
        line = re.sub(r"\s*[\r\n]+\s*", " ", message).strip()  # the value as given: '1  2'
        self.exit(2, f"{self.prog}: error: {line}; see {self.prog} --help\n")

    def parse_known_args(self, args: Sequence[str] | None = None,  # type: ignore[override]
                         namespace: argparse.Namespace | None = None
                         ) -> tuple[argparse.Namespace, list[str]]:
        """As argparse's, but an argument left over is refused here, by the innermost
        (sub)command's parser, so the error names that command (argparse's top parser said
        ``bomgraph: error: unrecognized arguments``)."""
        ns, extras = super().parse_known_args(args, namespace)
        if extras:
            self.error(f"unrecognized arguments: {' '.join(extras)}")
        return ns, extras


def _named(name: str) -> Callable[[Callable[[str], Any]], Callable[[str], Any]]:
    """Give an argparse ``type`` the name its error messages show ("invalid NAME value")."""

    def wrap(func: Callable[[str], Any]) -> Callable[[str], Any]:
        func.__name__ = name
        return func

    return wrap


@_named("non-negative integer")
def _nonneg_int(text: str) -> int:
    v = int(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {v}")
    return v


@_named("number of processes")
def _jobs(text: str) -> int:
    v = int(text)
    if v == 0 or v < -1:
        raise argparse.ArgumentTypeError(f"must be a number of processes >= 1, or -1 for "
                                         f"one per core, got {v}")
    return v


@_named("number of workers")
def _dask_workers(text: str) -> int:
    """``--dask-local N``: a cluster of no workers is none (h101: 0 set a sweep file's
    ``[executor]`` aside and ran local processes, one per core, without a word)."""
    v = int(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1 (a local Dask cluster's workers), got "
                                         f"{v}; leave it out for local processes (--jobs) or "
                                         f"a sweep file's [executor]")
    return v


@_named("positive integer")
def _positive_int(text: str) -> int:
    v = int(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {v}")
    return v


@_named("integer")
def _int(text: str) -> int:
    return int(text)


@_named("number")
def _float(text: str) -> float:
    v = float(text)
    if math.isnan(v):
        raise argparse.ArgumentTypeError("must be a number, got NaN")
    return v



def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("bomgraph")
    except PackageNotFoundError:  # run from a source tree that is not installed
        return "unknown (not installed)"



def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="bomgraph", description="Bearing-only mapping toolkit: "
                                "BOM-STMDS and SLAM baselines side by side.")
    p.add_argument("--version", action="version", version=f"bomgraph {_version()}",
                   help="print the version and exit")
    _add_verbosity(p)
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    s = _command(sub, "simulate", "simulate a run of the paper's world into a stream file")
    s.add_argument("--seed", type=_nonneg_int, default=0, help="random seed (default 0)")
    s.add_argument("--landmarks", type=_positive_int, default=50,
                   help="number of landmarks (default 50)")
    s.add_argument("--steps", type=_int, default=300, help="number of moves (default 300)")
    s.add_argument("--sensor-range", type=_float, default=1.0, help="metres (default 1.0)")
    s.add_argument("--fov-deg", type=_float, default=360.0, help="field of view (default 360)")
    s.add_argument("--noise-scale", type=_float, default=1.0,
                   help="multiplies the paper's noise; 0 gives noise-free data")
    s.add_argument("--wrong-association-rate", type=_float, default=0.0,
                   help="fraction of bearings given a wrong landmark id (default 0)")
    s.add_argument("--prior-fraction", type=_float, default=0.0,
                   help="fraction of landmark pairs with a known distance (Exp. 3: 0.1)")
    s.add_argument("--prior-sigma", type=_float, default=0.03, help="metres per axis")
    s.add_argument("--out", required=True, help="the stream file to write" + REPLACES)
    s.set_defaults(func="cmd_simulate")

    r = _command(sub, "run", "run a method on a stream file and write its estimate")
    r.add_argument("stream", help="the stream file ('-': read it from stdin)")
    r.add_argument("--method", required=True, metavar="NAME[@PRESET]",
                   help="see `bomgraph methods`; NAME@PRESET is --option preset=PRESET")
    r.add_argument("--out", required=True,
                   help="the estimate file to write ('-': write it to stdout)" + REPLACES)
    r.add_argument("--checkpoint-every", type=_positive_int, default=10,
                   help="estimate the map every N steps (default 10) and at the last step")
    r.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="a method option (repeatable); `bomgraph methods NAME` lists them")
    r.add_argument("--json", action="store_true",
                   help="print the summary as one JSON line")
    bar = r.add_mutually_exclusive_group()
    bar.add_argument("--progress", action="store_true", default=None,
                     help=f"always show a progress bar (default: on a terminal, for streams "
                          f"of {PROGRESS_MIN_STEPS} steps or more)")
    bar.add_argument("--no-progress", action="store_false", dest="progress",
                     help="never show a progress bar")
    r.add_argument("--allow-truth", action="store_true",
                   help="let a method that reads the stream's ground truth run (oracle: a "
                        "benchmark bound, not a mapper)")
    r.set_defaults(func="cmd_run")

    e = _command(sub, "evaluate", "score an estimate file at every checkpoint: against the "
                 "stream's truth (or --reference), else truth-free measures (landmarks mapped, "
                 "bearing residuals)")
    e.add_argument("estimate", help="the estimate file ('-': stdin)")
    e.add_argument("stream", help="the stream file it was run on ('-': stdin; not both)")
    e.add_argument("--json", action="store_true", help="print one JSON object (--format json)")
    e.add_argument("--similarity", action="store_true",
                   help="align with a scale too (a similarity transform; default rigid, with "
                        "reflection)")
    e.add_argument("--align", choices=("landmarks", "trajectory", "both"), default="landmarks",
                   help="fit the alignment on the common landmarks (default), the robot "
                        "positions (as evo), or both together")
    e.add_argument("--delta", type=_positive_int, default=1, metavar="N",
                   help="steps between the two poses of a relative pose error (default 1)")
    e.add_argument("--reference", default=None, metavar="EST",
                   help="score against this estimate file instead of the stream's truth")
    e.add_argument("--format", choices=("text", "json", "csv", "markdown", "latex"),
                   default="text", help="output format (default text; --json = json)")
    e.set_defaults(func="cmd_evaluate")

    c = _command(sub, "compare", "methods side by side: the paper's experiments, your "
                 "streams and methods, or a sweep file")
    c.add_argument("--config", default=None, metavar="SWEEP",
                   help="a sweep file (TOML: streams, [[worlds]], [[methods]], [executor]; see "
                        "docs/USAGE.md, 'Sweep files') or a shipped one by name: paper (the "
                        "default)")
    c.add_argument("--streams", nargs="+", default=None, metavar="FILE",
                   help="stream files to run --methods on (any recording or simulation)")
    c.add_argument("--methods", default=None, metavar="NAME[@PRESET],...",
                   help="with --streams: comma-separated methods, each optionally with a "
                        "preset (stmds-smacof@real); plugins included (`bomgraph methods`); "
                        "with --real: names only, each with its recording variants")
    c.add_argument("--option", action="append", default=[], metavar="NAME:KEY=VALUE",
                   help="with --streams: an option of every arm of method NAME, or of "
                        "one arm with NAME@PRESET (repeatable; a key once per NAME)")
    c.add_argument("--reference", metavar="NAME[@PRESET]", help="with --streams: score "
                   "truth-free streams against this method's final map")
    c.add_argument("--paired-reference", metavar="ARM", default=None,
                   help="the arm every other arm is paired against, run by run, in paired.csv "
                        "(an arm's label as the tables show it; default: each experiment's "
                        "--reference arm if it is one of its arms, unless every run of it is "
                        "scored against its own map (no truth) and two other arms ran; else "
                        "its oracle-like bound, else its first arm)")
    c.add_argument("--checkpoint-every", type=_positive_int, metavar="N",
                   help="with --streams: map every N steps (default 10)")
    c.add_argument("--quick", action="store_true",
                   help="2 runs of 150 steps per arm (a demo), instead of 25 runs of 300")
    c.add_argument("--experiments", default="",
                   help="comma-separated subset of the experiments (paper: exp1,exp2,exp3,"
                        "all; with --real: mrclam6,g2o; a sweep file: its names)")
    c.add_argument("--real", default=None, metavar="DATA_DIR",
                   help="every method on the recorded datasets under DATA_DIR (e.g. "
                        "../shared/data) instead of the simulation")
    c.add_argument("--out", default="compare-results",
                   help="output folder; the files an earlier compare wrote in it (listed in "
                        "OUT/.bomgraph-compare-files) are replaced, and those this one does not "
                        "write and nobody changed since are removed; nothing else (the cache "
                        "is kept). Any other file at a name compare writes (results.csv, a "
                        "figure, estimates/index.csv; all of them in a folder from a bomgraph "
                        "without that list) is refused before anything runs: move it or "
                        "choose another folder")
    c.add_argument("--seed", type=_nonneg_int, help="the paper design's seed (default 0)")
    c.add_argument("--jobs", type=_jobs, help="local processes (-1, the default: one per core)")
    cluster = c.add_mutually_exclusive_group()
    cluster.add_argument("--scheduler", default=None, metavar="ADDRESS",
                         help="run on an existing Dask distributed scheduler, e.g. "
                              "tcp://host:8786")
    cluster.add_argument("--dask-local", type=_dask_workers, metavar="N",
                         help="start a local Dask cluster of N worker processes")
    c.add_argument("--no-cache", action="store_true", help="ignore and do not write the cache")
    c.add_argument("--dry-run", action="store_true",
                   help="list what would run (per experiment and arm: runs, and how many are "
                        "in --out's cache already) and stop; nothing runs or is written")
    c.add_argument("--no-figures", action="store_true", help="write no figures")
    c.add_argument("--estimates", action="store_true",
                   help="also write each run's final estimate file (map, trajectory, "
                        "covariances if any) to OUT/estimates/EXPERIMENT/ARM/RUN.est, for "
                        "`bomgraph evaluate`, `plot` and `export`")
    cbar = c.add_mutually_exclusive_group()
    cbar.add_argument("--progress", action="store_true", default=None,
                      help="always show a progress bar (default: when stderr is a terminal)")
    cbar.add_argument("--no-progress", action="store_false", dest="progress",
                      help="show no progress bar")
    c.set_defaults(func="cmd_compare")

    i = _command(sub, "import", "turn a real dataset into a stream file")
    isub = i.add_subparsers(dest="dataset", required=True, metavar="DATASET")
    im = _command(isub, "mrclam", "one robot of a UTIAS MRCLAM folder, keyframed")
    im.add_argument("dir", help="the dataset folder (.dat or .dat.gz files)")
    im.add_argument("--robot", type=_int, required=True, choices=range(1, 6), metavar="{1..5}",
                    help="the robot number")
    im.add_argument("--out", required=True, help="the stream file to write" + REPLACES)
    im.add_argument("--min-distance", type=_float, help="keyframe distance, metres "
                    "(default: KeyframeConfig's, 0.3)")
    im.add_argument("--min-turn", type=_float, help="keyframe turn, radians (default 0.3)")
    im.add_argument("--attach-window", type=_float, help="seconds (default 0.6)")
    im.add_argument("--keep-ranges", action="store_true", help="keep ranges in the meta")
    im.add_argument("--no-calibrate", action="store_true",
                    help="use the default sigmas (needed without robot ground truth, mrclam1)")
    im.add_argument("--odometry-scale", type=_float, default=1.0, metavar="K",
                    help="multiply the logged forward velocities by K (a robot's length "
                         "calibration: the meta's odometry_length_ratio of the same robot "
                         "imported with ground truth; default 1)")
    im.add_argument("--no-landmark-check", action="store_true",
                    help="take Landmark_Groundtruth.dat as read: no erratum corrected, no check "
                         "against the measured ranges")
    im.set_defaults(func="cmd_import_mrclam")
    ig = _command(isub, "g2o", "a bearing-only g2o file")
    ig.add_argument("file", help="the g2o file")
    ig.add_argument("--truth", default=None, help="a g2o file whose vertices are the truth")
    ig.add_argument("--bearing-sigma", type=_float, default=None,
                    help="radians (default: from the bearing edges' information)")
    ig.add_argument("--out", required=True, help="the stream file to write" + REPLACES)
    ig.set_defaults(func="cmd_import_g2o")
    iv = _command(isub, "victoria", "GTSAM's victoria_park.txt")
    iv.add_argument("file", help="the victoria_park.txt file")
    iv.add_argument("--bearing-sigma", type=_float, default=None,
                    help="radians (default: median propagated point covariance)")
    iv.add_argument("--out", required=True, help="the stream file to write" + REPLACES)
    iv.set_defaults(func="cmd_import_victoria")

    x = _command(sub, "export", "write an estimate (or a stream's truth) as TUM, KITTI, CSV "
                 "or g2o")
    x.add_argument("estimate", nargs="?", default=None,
                   help="an estimate file from `run` ('-': stdin)")
    x.add_argument("--stream", default=None, help="the estimate's stream: time stamps for "
                   "tum/csv, the measurements for g2o")
    x.add_argument("--truth", default=None, metavar="STREAM",
                   help="export this stream's ground truth instead of an estimate")
    x.add_argument("--format", required=True, choices=("tum", "kitti", "csv", "g2o"),
                   help="tum: t x y z qx qy qz qw; kitti: 3x4 rows; csv: one file with a kind "
                        "column; g2o: the problem with the estimate as values")
    x.add_argument("--out", required=True, help="output file, or - for stdout" + REPLACES)
    x.set_defaults(func="cmd_export")

    pl = _command(sub, "plot", "draw one run over its truth (without truth: in its own "
                  "frame), or a compare folder")
    pl.add_argument("estimate", nargs="?", help="an estimate file (bomgraph run)")
    pl.add_argument("stream", nargs="?", help="its stream file")
    pl.add_argument("--out", required=True, help="FILE.png, FILE.pdf or FILE.svg" + REPLACES)
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
    pl.set_defaults(func="cmd_plot")

    m = _command(sub, "methods", "list the methods, or one method's options and presets")
    m.add_argument("name", nargs="?", default=None, metavar="NAME",
                   help="a method: list its options (type, default, meaning) and presets")
    m.add_argument("--json", action="store_true", help="print JSON instead of text")
    m.set_defaults(func="cmd_methods")
    return p


def _add_verbosity(p: argparse.ArgumentParser) -> None:
    """``-v`` (INFO; ``-vv`` DEBUG) and ``-q`` (errors only), before or after the command."""
    g = p.add_mutually_exclusive_group()
    g.add_argument("-v", "--verbose", action="count", default=argparse.SUPPRESS,
                   help="log progress (INFO); twice for DEBUG")
    g.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                   help="log errors only (no warnings)")


def _command(sub: Any, name: str, help_text: str) -> argparse.ArgumentParser:
    cmd = sub.add_parser(name, help=help_text, description=help_text)
    _add_verbosity(cmd)
    return cmd
