"""The ``bomgraph`` command: its commands, printing and exit statuses only (the argument
parser is :mod:`bomgraph.cli_parser`; the signal handlers :mod:`bomgraph.cli_signals`).

Every command is one library call plus printing. A user error (a BomgraphError) prints one
line to stderr and exits with status 2, without a traceback. ``-v``/``-q`` set the level of
the root ``logging`` handler (the library logs through ``logging.getLogger(__name__)``);
a closed pipe ends the command quietly; Ctrl-C exits with status 130 and SIGTERM with 143,
never with a traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import json
import math
import os
import signal
import sys
from typing import Any, Callable, Iterator, Sequence

from .cli_parser import PROGRESS_MIN_STEPS, build_parser
from .cli_signals import (Terminated, forget_unhandled_interrupt, own_signals, stdout_closed,
                          stop_status, stopped)
from .errors import (BomgraphError, ConfigError, exception_line, message_line, one_line,
                     shown_path)


def _say(text: str, *, to_stderr: bool = False) -> None:
    """Print a result line (to stderr when stdout carries data, e.g. ``--out -``). An error
    writing stdout (a full disk, ``> /dev/full``) names the standard output: it was
    reported as "--out FILE: No space left on device", of a FILE written whole (h126)."""
    if to_stderr:
        print(text, file=sys.stderr)
        return
    with _naming_stdout():
        print(text)


@contextlib.contextmanager
def _naming_stdout() -> Iterator[None]:
    """Errors writing ``sys.stdout`` (other than a closed pipe) as one naming it."""
    try:
        yield
    except BrokenPipeError:
        raise
    except OSError as exc:
        from .stdio import OutputPathError  # not at import: it loads numpy

        raise OutputPathError(f"the standard output: {exc.strerror or exc}") from None


# --------------------------------------------------------------------------------------------
# Commands
# --------------------------------------------------------------------------------------------

def cmd_simulate(args: argparse.Namespace) -> int:
    import numpy as np

    from .sim import SimConfig, make_priors, simulate, with_priors
    from .std_streams import check_output_path, is_stdout, write_output
    from .stream_file import write_stream

    check_output_path(args.out)
    config = SimConfig(n_landmarks=args.landmarks, n_steps=args.steps,
                       sensor_range_m=args.sensor_range, noise_scale=args.noise_scale,
                       fov_rad=math.radians(args.fov_deg),
                       wrong_association_rate=args.wrong_association_rate)
    if not 0 <= args.prior_fraction <= 1:
        raise ConfigError(f"--prior-fraction must be in [0, 1] (0: no priors; Exp. 3 uses "
                          f"0.1), got {args.prior_fraction:g}")
    rng = np.random.default_rng(args.seed)
    stream = simulate(config, rng, meta={"seed": args.seed})
    if args.prior_fraction > 0:
        stream = with_priors(stream, make_priors(stream.truth, args.prior_fraction,
                                                 args.prior_sigma, rng))
    write_output(args.out, lambda p: write_stream(stream, p))  # `-`: stdout, not a file
    from .tables import counted

    _say(f"wrote {shown_path(args.out)}: {counted(len(stream.steps), 'step')}, "
         f"{counted(config.n_landmarks, 'landmark')}, "
         f"{counted(len(stream.header.priors), 'prior')}", to_stderr=is_stdout(args.out))
    return 0


def _step_bar(stream_path: str, method: str, force: bool | None) -> Any:
    """A tqdm bar over the stream's steps: always with ``--progress``, never with
    ``--no-progress``, else when stderr is a terminal and the stream is long."""
    if force is False or (force is None and not sys.stderr.isatty()):
        return None
    from .bench import count_steps

    total = count_steps(stream_path)
    if not force and total < PROGRESS_MIN_STEPS:
        return None
    from tqdm import tqdm

    return tqdm(total=total, unit="step", desc=method, file=sys.stderr)


def cmd_run(args: argparse.Namespace) -> int:
    from .bench import run_file
    from .jsonio import parse_options
    from .mapper import checkpoint_times
    from .std_streams import check_output_path, input_path, is_stdout, write_output

    from .command_line_sweep import run_method

    label, method, options = run_method(args.method, parse_options(args.option))
    check_output_path(args.out, inputs=(args.stream,))
    to_stderr = is_stdout(args.out)  # `--out -`, `--out /dev/stdout > f`: not over the estimate
    with input_path(args.stream) as stream_path:
        bar = _step_bar(stream_path, label, args.progress)
        progress = None if bar is None else (lambda t: bar.update(t + 1 - bar.n))
        done: list = []

        def compute(out_path: str) -> None:  # the estimate is written as the run goes
            done.append(run_file(stream_path, method, options,
                                 checkpoint_every=args.checkpoint_every,
                                 allow_truth=args.allow_truth, progress=progress,
                                 out=out_path))
        try:
            write_output(args.out, compute)
        finally:
            if bar is not None:
                bar.close()
    result = done[0]
    if args.json:  # the result keeps only the last checkpoint; the file has all of them
        written = len(checkpoint_times(result.checkpoints[-1].t + 1, args.checkpoint_every))
        _say(json.dumps({"method": label, "stream": args.stream, "out": args.out,
                         "landmarks": len(result.final), "t": result.checkpoints[-1].t,
                         "checkpoints": written,
                         "total_s": round(result.total_s, 6)}), to_stderr=to_stderr)
    else:
        from .tables import counted

        _say(f"{label}: {counted(len(result.final), 'landmark')} mapped at t = "
             f"{result.checkpoints[-1].t} in {result.total_s:.3f} s; wrote {args.out}",
             to_stderr=to_stderr)
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    from .file_evaluation import evaluate_files, format_evaluation
    from .std_streams import STDIO, input_path

    if args.estimate == STDIO and args.stream == STDIO:
        raise BomgraphError("only one of ESTIMATE and STREAM can be '-' (stdin)")
    with input_path(args.estimate) as estimate, input_path(args.stream) as stream:
        ev = evaluate_files(estimate, stream, with_scale=args.similarity, align_on=args.align,
                            delta=args.delta, reference_path=args.reference)
    _say(format_evaluation(ev, "json" if args.json else args.format))
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
    _say(f"wrote {shown_path(path)}")
    return 0


def _note_g2o_unmapped(src: Any, stream: Any) -> None:
    """Say which observed landmarks a g2o export has no vertex for: g2o's loader drops
    their bearing edges without a word."""
    from .export import unmapped_landmarks
    from .tables import counted

    unmapped, n_bearings = unmapped_landmarks(src, stream)
    if unmapped:
        one = len(unmapped) == 1
        ids = " ".join(map(str, unmapped[:10])) + (" ..." if len(unmapped) > 10 else "")
        print(f"bomgraph: note: {counted(len(unmapped), 'observed landmark')} without an "
              f"estimate {'has' if one else 'have'} no VERTEX_XY (id{'' if one else 's'} "
              f"{ids}): g2o drops {'its' if one else 'their'} "
              f"{counted(n_bearings, 'bearing edge')} when it loads the file", file=sys.stderr)


def cmd_export(args: argparse.Namespace) -> int:
    from .estimate_file import read_estimate
    from .errors import ExportError
    from .export import export_text, truth_estimate, write_text_atomic
    from .file_evaluation import check_stream_identity
    from .std_streams import STDIO, check_output_path, input_path, is_stdout, standard_output
    from .stream_file import read_stream

    if (args.estimate is None) == (args.truth is None):
        raise ExportError("give an estimate file EST, or --truth STREAM (not both)")
    if args.truth is not None and args.stream is not None:
        raise ExportError("--truth STREAM is the stream already; drop --stream")
    stream_path = args.truth if args.truth is not None else args.stream
    if args.estimate == STDIO and stream_path == STDIO:
        raise ExportError("only one of EST and the stream can be '-' (stdin)")
    with input_path(stream_path) if stream_path else contextlib.nullcontext() as sp:
        stream = None if sp is None else read_stream(sp)
    if args.truth is not None:
        if stream is not None and stream.truth is None:
            raise ExportError(f"{shown_path(args.truth)}, line 1: no 'truth' in the header: "
                              f"the stream has no ground truth to export")
        src = truth_estimate(stream)  # type: ignore[arg-type]
    else:
        with input_path(args.estimate) as ep:
            est = read_estimate(ep)
        if stream is not None:  # as evaluate: an estimate of another stream is refused
            check_stream_identity(est, stream.steps, args.estimate, stream_path,
                                  error=ExportError)
        src = est.final
    text = export_text(src, args.format, stream, name=args.truth or args.estimate,
                       stream_name=stream_path)
    to_stderr = is_stdout(args.out)  # `--out /dev/stdout > f`: the line would overwrite f
    inputs = [p for p in (args.estimate, stream_path) if p and p != STDIO]
    if args.out == "-":
        check_output_path(STDIO, inputs)  # `--out - >> EST`: refused as /dev/stdout is (h86)
        standard_output().write(text)
    else:
        write_text_atomic(text, args.out, inputs)
    if args.format == "tum" and stream is None and not getattr(args, "quiet", False):
        print("bomgraph: note: the TUM time stamps are step indices; give --stream FILE to "
              "use the stream's time_s (as export --truth does), so that evo can pair them",
              file=sys.stderr)
    if args.format == "g2o" and not getattr(args, "quiet", False):
        _note_g2o_unmapped(src, stream)  # type: ignore[arg-type]
    if args.out == "-":
        return 0
    from .tables import counted

    held = [counted(0 if src.poses is None else len(src.poses), "pose")]
    if args.format in ("csv", "g2o"):  # TUM and KITTI hold poses only
        held.append(counted(len(src.landmark_ids), "landmark"))
    _say(f"wrote {shown_path(args.out)} ({args.format}): {', '.join(held)}", to_stderr=to_stderr)
    return 0


def cmd_methods(args: argparse.Namespace) -> int:
    from .jsonio import jsonable, options_to_json
    from .mapper import available_methods, factory_options, method_config_class, method_info
    from .method_list import (format_method_list, method_listing, no_presets_line,
                              options_heading, preset_summary, takes_any_option)

    if args.name is None:
        rows = [method_listing(i) for i in available_methods()]
        if args.json:
            _say(json.dumps(jsonable(options_to_json(rows))))  # presets' infinities kept
            return 0
        _say(format_method_list(rows))
        return 0
    from .config import describe_options

    r = method_listing(method_info(args.name))
    cls = method_config_class(args.name)
    options = describe_options(cls) if cls is not None else factory_options(args.name)
    if args.json:
        _say(json.dumps(jsonable(options_to_json({  # an infinite default as "Infinity"
            **r, "config": cls.__name__ if cls else None,
            "options": [o._asdict() for o in options],
            "any_option": takes_any_option(args.name)}))))  # its **options (h154)
        return 0
    _say(f"{r['name']}: {r['description']}")
    if r["origin"] == "plugin":
        _say(f"  plugin {method_info(args.name).target} from {r['distribution']} {r['version']}")
    _say("\n" + options_heading(args.name, cls.__name__ if cls is not None else None,
                                 len(options)))
    width = max(len(o.name) for o in options) if options else 0
    for o in options:
        _say(f"  {o.name:{width}s}  {o.type}, default {o.default!r}"
             + (f": {o.doc}" if o.doc else ""))
    if not r["presets"]:
        _say(f"\n{no_presets_line(args.name)}")
        return 0
    _say("\npresets (NAME@PRESET, or --option preset=PRESET):")
    for name, overrides in r["presets"].items():
        _say(f"  {name}: {preset_summary(overrides, 1000)}")
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    seen = {"done": 0}
    try:
        return _compare(args, seen)
    except (KeyboardInterrupt, Terminated) as exc:  # anywhere: imports, runs, writes, printing
        from .tables import counted

        cached = ("" if args.no_cache else
                  f"; {counted(seen['done'], 'run')} cached, rerun to resume")
        print(f"bomgraph: {stopped(exc)}{cached}", file=sys.stderr)
        return stop_status(exc)


def _compare(args: argparse.Namespace, seen: dict[str, int]) -> int:
    from .bench import Executor
    from .experiments import compare_experiments
    from .paired import format_paired, references_for
    from .report import compare, final_by_run, format_by_run, format_summary, plan_compare

    chosen, settings = compare_experiments(
        config=args.config, streams=args.streams, methods=args.methods, options=args.option,
        reference=args.reference, checkpoint_every=args.checkpoint_every, real=args.real,
        quick=args.quick, seed=args.seed,
        names=args.experiments.split(",") if args.experiments else ())
    executor = Executor.choose(args.jobs, args.scheduler, args.dask_local, defaults=settings)
    if args.dry_run:
        references_for(chosen, args.paired_reference)    # a wrong arm: refused here too
        return _print_plan(plan_compare(chosen, args.out, use_cache=not args.no_cache,
                                        estimates=args.estimates, executor=executor,
                                        figures=not args.no_figures), args.out)
    if executor.backend == "dask" and args.jobs is not None and not getattr(args, "quiet", False):
        print(f"bomgraph: note: --jobs {args.jobs} is not used: the Dask cluster's workers run "
              f"the tasks (--dask-local N workers, or those started for --scheduler)",
              file=sys.stderr)
    if executor.backend == "dask" and not getattr(args, "verbose", 0):
        from .cluster import quiet_dask_logging
        from .log_setup import restore_after

        # a cluster's failure is the failed runs' line, Dask's with -v; main(): undone after
        restore_after(quiet_dask_logging())
    show = sys.stderr.isatty() if args.progress is None else args.progress
    bar = None

    def progress(done: int, total: int) -> None:  # the bar starts when the total is known
        nonlocal bar
        seen["done"] = done
        if show and bar is None:
            from tqdm import tqdm

            bar = tqdm(total=total, initial=done, unit="run", desc="compare", file=sys.stderr)
        elif bar is not None:
            bar.total = total
            bar.n = done
            bar.refresh()

    try:
        result = compare(chosen, args.out, executor=executor, use_cache=not args.no_cache,
                         figures=not args.no_figures, progress=progress,
                         estimates=args.estimates, paired_reference=args.paired_reference)
    finally:
        if bar is not None:
            bar.close()
    _say(format_summary(result.summary))
    if result.paired and not getattr(args, "quiet", False):
        _say(format_paired(result.paired))
    recorded = {e.name for e in chosen if not e.designed}
    if recorded:
        _say(format_by_run(final_by_run([r for r in result.results
                                         if r["experiment"] in recorded])))
    from .tables import counted

    est = [f for f in result.files if f.endswith(".est")]
    streams = [f for f in result.files if f.endswith(".jsonl")]
    wrote = [f for f in result.files if not f.endswith((".est", ".jsonl"))]
    if est:
        wrote.append(f"{counted(len(est), 'estimate file')} under "
                     f"{os.path.join(args.out, 'estimates')}")
    if streams:
        wrote.append(f"{counted(len(streams), 'stream file')} under "
                     f"{os.path.join(args.out, 'streams')}")
    cache = f" ({result.n_cached} from the cache)" if result.n_cached else ""
    _say(f"\n{counted(len(result.results), 'run')} in {result.wall_s:.1f} s{cache}; wrote "
          f"{', '.join(wrote)}")
    bad = [r["error"] for r in result.results if not r.get("ok") and str(
        r.get("error", "")).startswith(("StreamFormatError: ", "DatasetError: "))]
    if bad:  # a malformed input is the user's to fix, not a method's failure
        print(one_line(f"bomgraph: error: {counted(len(bad), 'run')} stopped on an input file "
                       f"that cannot be read: {bad[0].partition(': ')[2]}"), file=sys.stderr)
        return 2
    failed = [r for r in result.results if not r.get("ok")]
    if failed:  # a method (or a reference) raised, or a worker was stale: status 1
        f = failed[0]
        print(one_line(f"bomgraph: error: {len(failed)} of "
                       f"{counted(len(result.results), 'run')} failed "
                       f"(first: {f['arm']} on {f['experiment']} {f['run']}: "
                       f"{f.get('error')}); the tables mark them FAILED and "
                       f"{shown_path(os.path.join(args.out, 'results.json'))} holds each "
                       f"error"), file=sys.stderr)
        return 1
    return 0


def _print_plan(rows: list[dict[str, Any]], out: str) -> int:
    """``compare --dry-run``: the runs per experiment and arm, and how many are cached."""
    from .tables import counted, plural

    groups: dict[tuple[str, str], list[bool]] = {}
    for r in rows:
        groups.setdefault((r["experiment"], r["arm"]), []).append(r["cached"])
    width = max([len(a) for _, a in groups] + [3])
    for (exp, arm), cached in groups.items():
        runs = plural(len(cached), "run") + ","
        _say(f"{exp:12s} {arm:{width}s} {len(cached):6d} {runs:5s} {sum(cached):6d} cached")
    done = sum(r["cached"] for r in rows)
    _say(f"\n{counted(len(rows), 'run')}: {len(rows) - done} to run, {done} in "
          f"{os.path.join(out, 'cache')}; nothing was run or written (--dry-run)")
    return 0


def _import(args: argparse.Namespace, make: Callable[[], Any], *inputs: str | None) -> int:
    """Check ``--out`` (not one of the ``inputs``) before ``make()`` imports, then write."""
    from .datasets.summary import import_summary
    from .std_streams import check_output_path, is_stdout, write_output
    from .stream_file import write_stream

    check_output_path(args.out, inputs)
    stream = make()
    write_output(args.out, lambda p: write_stream(stream, p, inputs=inputs))
    _say(f"wrote {shown_path(args.out)}: {import_summary(stream)}", to_stderr=is_stdout(args.out))
    return 0


def cmd_import_mrclam(args: argparse.Namespace) -> int:
    from .datasets.mrclam import KeyframeConfig, import_mrclam

    given = {"min_distance_m": args.min_distance, "min_turn_rad": args.min_turn,
             "attach_window_s": args.attach_window}
    keyframe = KeyframeConfig(**{k: v for k, v in given.items() if v is not None})
    return _import(args, lambda: import_mrclam(args.dir, args.robot, keyframe=keyframe,
                                               keep_ranges=args.keep_ranges,
                                               calibrate=not args.no_calibrate,
                                               landmark_check=not args.no_landmark_check,
                                               odometry_scale=args.odometry_scale),
                   args.dir)


def cmd_import_g2o(args: argparse.Namespace) -> int:
    from .datasets.g2o import import_g2o

    return _import(args, lambda: import_g2o(args.file, truth_path=args.truth,
                                            bearing_sigma_rad=args.bearing_sigma),
                   args.file, args.truth)


def cmd_import_victoria(args: argparse.Namespace) -> int:
    from .datasets.victoria import import_victoria

    return _import(args, lambda: import_victoria(args.file, bearing_sigma_rad=args.bearing_sigma),
                   args.file)


# --------------------------------------------------------------------------------------------
# Parser
# --------------------------------------------------------------------------------------------

#: errors of a write (a full disk, a quota, a file size limit): the OSError names no file.
_WRITE_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG}

#: the handler of each subcommand, by the name :func:`build_parser` gives it.
_COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    f.__name__: f for f in (cmd_simulate, cmd_run, cmd_evaluate, cmd_plot, cmd_export,
                            cmd_methods, cmd_compare, cmd_import_mrclam, cmd_import_g2o,
                            cmd_import_victoria)}


def main(argv: Sequence[str] | None = None) -> int:
    """The ``bomgraph`` command with ``argv`` (default: ``sys.argv[1:]``), for a caller in
    the same process (a test, a notebook, a script); returns the exit status. SIGINT and
    SIGTERM are handled from the start (:func:`bomgraph.cli_signals._on_signal`), and the
    handlers and ``sys.unraisablehook`` in place before are restored at the end, so the
    caller's Ctrl-C works as before. The installed command is :func:`program`."""
    return _run(argv, program=False)


def program() -> int:
    """The ``bomgraph`` command as a program (the console script and ``python -m
    bomgraph``): :func:`main` on ``sys.argv[1:]``, closed descriptors 0-2 held first
    (:func:`~bomgraph.stdio.hold_standard_descriptors`), SIGINT and SIGTERM left ignored at
    the end: a signal during the interpreter's exit would be a traceback or a death by it."""
    from .stdio import hold_standard_descriptors
    hold_standard_descriptors()
    return _run(None, program=True)


def _run(argv: Sequence[str] | None, program: bool) -> int:
    hook = sys.unraisablehook
    from .log_setup import logging_restored
    from .std_streams import closed_streams_as_none

    kept = contextlib.ExitStack()
    kept.enter_context(closed_streams_as_none())  # put back after logging_restored's undos
    if not program:  # the caller's logging and warnings, which the command replaces
        kept.enter_context(logging_restored())
    owned = own_signals(hook)
    try:
        try:
            status = _main(argv)
        except (KeyboardInterrupt, Terminated) as exc:  # before a command ran, or after
            command = next((a for a in (sys.argv[1:] if argv is None else argv)
                            if not a.startswith("-")), "")
            print(f"bomgraph: {stopped(exc)}" + ("; rerun to resume" if command == "compare"
                                                 else ""), file=sys.stderr)
            status = stop_status(exc)
        finally:
            for s in owned:
                signal.signal(s, signal.SIG_IGN)
        if status in (130, 143):
            forget_unhandled_interrupt()
        return status
    finally:
        if not program:
            for s, previous in owned.items():
                signal.signal(s, previous)
            sys.unraisablehook = hook
            kept.close()


def _main(argv: Sequence[str] | None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except BrokenPipeError:  # `bomgraph --help | head -1`
        return stdout_closed()
    except OSError as exc:  # `bomgraph --help > /dev/full`: as a command's output error
        print(f"bomgraph: error: the standard output: {exc.strerror or exc}", file=sys.stderr)
        return 2
    from .checks import command_line
    from .log_setup import configure_logging

    configure_logging(getattr(args, "verbose", 0), getattr(args, "quiet", False))
    func: Callable[[argparse.Namespace], int] = _COMMANDS[args.func]
    try:
        with command_line():   # refusals name the options (--out), not the library's names
            status = func(args)
        if sys.stdout is not None:  # None: closed by the shell (>&-)
            with _naming_stdout():
                sys.stdout.flush()
        return status
    except BrokenPipeError:
        return stdout_closed()
    except Exception as exc:
        from .mapper import method_failure_note

        note = method_failure_note(exc)
        if isinstance(exc, BomgraphError) or (isinstance(exc, OSError) and note is None):
            # a refusal, with what to fix (also one a method made, then with where): exit 2
            from .std_streams import display_path

            # a method's, as compare shows it: its lines joined (exception_line)
            message = str(exc) if note is None else message_line(str(exc))
            if isinstance(exc, OSError) and exc.filename is None \
                    and exc.errno in _WRITE_ERRNOS and getattr(args, "out", None):
                message = f"--out {args.out}: {exc.strerror}"  # a write error names no file
            print(one_line(f"bomgraph: error: {display_path(message)}"
                           + (f" ({note})" if note else "")), file=sys.stderr)
            return 2
        if note is None and isinstance(exc, MemoryError):  # no traceback helps here (h91)
            print(f"bomgraph: error: out of memory{f' ({exc})' if str(exc) else ''}; give a "
                  f"smaller input or fewer --jobs, or run it with more memory", file=sys.stderr)
            return 1
        if note is None:   # not a method's own code: bomgraph's bug, whose traceback helps
            raise
        return _method_failed(args, exc, note)


def _method_failed(args: argparse.Namespace, exc: BaseException, note: str) -> int:
    """A method (a plugin's, say) raised what is no refusal: one line saying where, the
    traceback with ``-v``; exit status 1."""
    import traceback

    verbose = getattr(args, "verbose", 0)
    print(one_line(f"bomgraph: error: method {getattr(args, 'method', '?')} failed: "
                   f"{exception_line(exc)} ({note})"
                   + ("" if verbose else "; -v shows the traceback")), file=sys.stderr)
    if verbose:
        traceback.print_exception(exc, file=sys.stderr)
    return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
