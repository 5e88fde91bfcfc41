"""One method over one stream file, read step by step (``bomgraph run``), and one method on one
simulated run of an experiment (the comparison's example map).

:func:`run_file` reads the stream once: with ``out`` it hashes the steps as they are read for
the estimate file's header (:class:`bomgraph.stream_identity.StreamHasher`) and writes the
estimate checkpoint by checkpoint, so memory stays bounded by one map.
"""

from __future__ import annotations

import contextlib
import logging
import os
from typing import Any, Callable, Iterable, Iterator, Mapping

import numpy as np

from .checks import option_named, out_named
from .errors import ConfigError, StreamFormatError, StreamValueError, shown_path
from .experiments import Experiment, SimSource
from .mapper import (MapEstimate, RunResult, checkpoint_times, create_mapper, method_info,
                     run)
from .stream import Step, Stream
from .stdio import check_output_path
from .stream_file import StreamReader, located
from .tables import counted

_log = logging.getLogger(__name__)


def run_file(stream_path: str | os.PathLike[str], method: str,
             options: Mapping[str, Any] | None = None, *, checkpoint_every: int = 10,
             allow_truth: bool = False,
             progress: Callable[[int], None] | None = None,
             out: str | os.PathLike[str] | None = None) -> RunResult:
    """Run ``method`` with ``options`` over a stream file, read step by step (single-threaded
    BLAS, as :func:`run_task`). ``progress(t)`` is called after each step is read.

    With ``out``, the estimate file is written there checkpoint by checkpoint (atomically,
    with the stream's identity and the options; :class:`bomgraph.estimate_file.EstimateWriter`)
    and the result keeps only the final checkpoint, so memory stays bounded by one map.

    Raises
    ------
    ConfigError
        The method reads the ground truth (a benchmark bound) and ``allow_truth`` is False.
    """
    if options is not None and not isinstance(options, Mapping):
        raise ConfigError(f"run_file(): options must be a mapping of option names to values "
                          f"(or None), got {type(options).__name__}")
    if method_info(method).needs_truth and not allow_truth:
        raise ConfigError(f"method {method!r} reads the ground truth; it is a benchmark "
                          f"bound, not a mapper (pass "
                          f"{option_named('--allow-truth', 'allow_truth=True')} to run it "
                          f"anyway)")
    if out is not None and os.path.exists(out) and os.path.samefile(out, stream_path):
        raise ConfigError(f"{out_named('out', out)} is the input stream; choose another "
                          f"file for the estimate")
    if out is not None:  # before the stream is read, and naming the parameter ``out`` (h103:
        check_output_path(out, name="out")  # EstimateWriter's refusal said path='x')
    try:
        result = _run_read(stream_path, method, options, checkpoint_every, progress, out)
    except StreamValueError as exc:  # the method's refusal, naming the file and the line
        raise located(exc, stream_path, method) from None
    _log.info("%s: %d checkpoints, %d landmarks at t = %d, %.3f s", method,
              len(checkpoint_times(result.checkpoints[-1].t + 1, checkpoint_every)),
              len(result.final), result.checkpoints[-1].t, result.total_s)
    if len(result.final) == 0:
        _log.warning("%s mapped no landmark by t = %d (too few steps or too little parallax?)",
                     method, result.checkpoints[-1].t)
    failures = result.final.info.get("update_failures")
    if failures:
        _log.warning("%s: %s recovered from (last: %s); see the estimate's "
                     "info", method, counted(failures, "solver failure"),
                     result.final.info.get("last_failure", "?"))
    converged = result.final.info.get("converged")  # a numpy bool_ too (np.all(...))
    if isinstance(converged, (bool, np.bool_)) and not converged:
        _log.warning("%s: the final solve did not converge (%s)", method,
                     result.final.info.get("stop", "see the estimate's info"))
    return result


def _run_read(stream_path: str | os.PathLike[str], method: str,
              options: Mapping[str, Any] | None, checkpoint_every: int,
              progress: Callable[[int], None] | None,
              out: str | os.PathLike[str] | None) -> RunResult:
    """:func:`run_file`'s reading and running, its arguments checked."""
    from threadpoolctl import threadpool_limits

    with contextlib.ExitStack() as stack:
        reader = stack.enter_context(StreamReader(stream_path))
        stack.enter_context(threadpool_limits(limits=1))
        if reader.truth is None and method_info(method).needs_truth:
            raise ConfigError(f"{shown_path(stream_path)}: method {method!r} reads the ground "
                              f"truth, and this stream has none (no 'truth' in its header)")
        mapper = create_mapper(method, reader.header, truth=reader.truth, **dict(options or {}))
        _log.info("running %s on %s", method, stream_path)
        if out is None:
            steps: Iterable[Step] = reader if progress is None else _reporting(reader, progress)
            result = run(mapper, steps, checkpoint_every=checkpoint_every, method=method)
        else:  # the stream read once, its identity (the header's) hashed as it is read
            from .estimate_file import EstimateWriter
            from .stream_identity import StreamHasher

            hasher = StreamHasher()
            refused: list[StreamFormatError] = []  # the reader's own error, if it gave one
            lines = _remembering(reader, refused)  # kept: the rest is checked if the run fails
            steps = hasher.through(lines)
            try:
                writer = stack.enter_context(EstimateWriter(
                    out, method, stream=hasher, options=options,
                    checkpoint_every=checkpoint_every))
                result = run(mapper, steps if progress is None else _reporting(steps, progress),
                             checkpoint_every=checkpoint_every, method=method,
                             on_checkpoint=writer.add, keep_checkpoints=False)
                writer.finish(result)
            except Exception as exc:  # a bad step anywhere in the stream is refused first,
                if not isinstance(exc, StreamFormatError):  # as when it was read for its
                    _refuse_a_bad_rest(lines, refused)     # identity before the run
                raise
    return result


def _remembering(steps: Iterable[Step], refused: list[StreamFormatError]) -> Iterator[Step]:
    """The steps; a :class:`StreamFormatError` they raise is kept in ``refused`` too: the run
    takes a due checkpoint when the line after it is bad, and if the method fails there, the
    exception raised is the method's, with the stream's error only as its context."""
    try:
        yield from steps
    except StreamFormatError as exc:
        refused.append(exc)
        raise


def _refuse_a_bad_rest(lines: Iterator[Step], refused: list[StreamFormatError]) -> None:
    """Read the steps the run had not read yet (the same reader, from where it stopped; none
    once it has read them all): a bad line after the point of a method's (or the output's)
    failure is the error reported, as when the stream was checked before the run; so is a
    bad line the reader already refused (``refused``) before the method failed. The file
    is not opened again: the steps already read were checked, and a file replaced or removed
    since is not what the run read."""
    try:
        for _ in lines:
            pass
    except StreamFormatError as exc:
        raise exc from None
    if refused:
        raise refused[0] from None


def _reporting(steps: Iterable[Step], progress: Callable[[int], None]) -> Iterator[Step]:
    for st in steps:
        yield st
        progress(st.t)


def run_example(method: str, experiment: Experiment, *, run_index: int = 0,
                t: int | None = None) -> tuple[Stream, MapEstimate]:
    """``method`` (default options) on run ``run_index`` of a simulated experiment, without
    priors: the stream and the estimate at checkpoint ``t`` (the last one by default). For the
    example map of the comparison (paper fig. 3 and 5)."""
    stream = SimSource(experiment.runs()[run_index], experiment.sim).stream()
    needs_truth = method_info(method).needs_truth
    mapper = create_mapper(method, stream.header, truth=stream.truth if needs_truth else None)
    res = run(mapper, stream.steps, checkpoint_every=experiment.checkpoint_every)
    return stream, (res.final if t is None else res.at(t))


__all__ = ["run_file", "run_example"]
