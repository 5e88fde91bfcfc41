"""The CLI's logging: one handler on stderr at the level ``-v``/``-q`` ask for, Python
warnings logged on one line, and everything put back when a command run in its caller's
process (:func:`bomgraph.cli.main`) ends (moved from :mod:`bomgraph.stdio`, h79)."""

from __future__ import annotations

import contextlib
import contextvars
import logging
import os
import sys
import warnings
from typing import Callable, Iterator


def configure_logging(verbose: int = 0, quiet: bool = False) -> None:
    """The root handler on stderr: WARNING by default, INFO with -v, DEBUG with -vv, ERROR
    with -q (stderr closed by the shell: on /dev/null, :func:`_stderr_reopened`)."""
    _stderr_reopened()
    level = (logging.ERROR if quiet else logging.DEBUG if verbose >= 2
             else logging.INFO if verbose == 1 else logging.WARNING)
    root = logging.getLogger()
    for h in root.handlers[:]:  # set aside, not closed: main() puts them back
        # (:func:`logging_restored`)
        root.removeHandler(h)
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_OneLine("bomgraph: %(levelname)s: %(message)s"))
    root.addHandler(handler)
    root.setLevel(level)
    logging.captureWarnings(True)
    captured = logging.getLogger("py.warnings")
    if _first_line not in captured.filters:
        captured.addFilter(_first_line)
    if quiet:
        warnings.simplefilter("ignore")


def _stderr_reopened() -> None:
    """``sys.stderr`` writing to /dev/null when it is None, so that no line printed to it goes
    to stdout (into the data of ``--out -``) and no progress bar fails; put back when the
    command run in its caller's process ends (:func:`restore_after`). Descriptor 2 closed
    (``2>&-``) is put on /dev/null too; one open (the caller set ``sys.stderr`` to None, as
    ``pythonw`` does, or a file it opened took descriptor 2) is never written. Before (h83),
    ``run``'s progress bar raised AttributeError (exit 1, the traceback shown nowhere), and a
    line printed to ``sys.stderr`` = None went to stdout: ``simulate --out - > f 2>&-`` ended
    f with ``wrote -: ...``; in the caller's process (h86) too, and its ``sys.stderr`` and
    descriptor 2 were left changed."""
    if sys.stderr is not None:
        return
    try:
        os.fstat(2)
        closed = False
    except OSError:
        closed = True
    try:
        if not closed:
            stream = open(os.devnull, "w", encoding="utf-8")
        else:
            fd = os.open(os.devnull, os.O_WRONLY)
            if fd != 2:  # 0 or 1 closed too: the lowest number was free
                os.dup2(fd, 2)
                os.close(fd)
            stream = open(2, "w", encoding="utf-8", errors="backslashreplace", closefd=False)
    except OSError:
        return
    ours = os.fstat(stream.fileno())
    sys.stderr = stream

    def undo() -> None:
        if sys.stderr is stream:
            sys.stderr = None
        with contextlib.suppress(OSError, ValueError):
            stream.close()
            if closed and os.path.samestat(os.fstat(2), ours):
                os.close(2)  # closed as it was

    restore_after(undo)


class _OneLine(logging.Formatter):
    """A record's message on one line (:func:`bomgraph.errors.one_line`: a file name with a
    newline split a warning in two), a spooled stdin's temporary file named ``<stdin>``
    (:func:`bomgraph.std_streams.display_path`), as in the error line; a traceback logged
    with it (``exc_info``) follows on its own lines."""

    def formatMessage(self, record: logging.LogRecord) -> str:
        from .errors import one_line
        from .std_streams import display_path

        record.message = one_line(display_path(record.message))
        return super().formatMessage(record)


def _first_line(record: logging.LogRecord) -> bool:
    """A Python warning as :func:`logging.captureWarnings` logs it, cut to its first line
    (``FILE:LINE: Category: text``): the source line below it made one warning three lines."""
    lines = record.getMessage().strip().splitlines()
    record.msg, record.args = (lines[0] if lines else ""), ()
    return True


#: The undos :func:`restore_after` was given in the :func:`logging_restored` block running.
_UNDOS: contextvars.ContextVar[list[Callable[[], None]] | None] = contextvars.ContextVar(
    "bomgraph_logging_undos", default=None)


def restore_after(undo: Callable[[], None]) -> None:
    """Have ``undo`` (what puts back a change to logging, such as Dask's loggers quieted by
    :func:`bomgraph.cluster.quiet_dask_logging`) called when the :func:`logging_restored`
    block running ends: the command run in its caller's process. Outside one (the program,
    whose process ends with the command) the change stays."""
    undos = _UNDOS.get()
    if undos is not None:
        undos.append(undo)


@contextlib.contextmanager
def logging_restored() -> Iterator[None]:
    """The root logger's level and handlers and the warnings' filters and ``showwarning`` as
    they were before, when the block ends, and the changes given to :func:`restore_after`
    undone: for the command run in its caller's process (:func:`bomgraph.cli.main`), whose
    ``-q`` left the caller's root logger at ERROR, its handlers removed, and every warning
    ignored, and whose Dask cluster left Dask's loggers at CRITICAL (h63)."""
    root = logging.getLogger()
    level, handlers = root.level, root.handlers[:]
    undos: list[Callable[[], None]] = []
    token = _UNDOS.set(undos)
    # logging.captureWarnings keeps the showwarning it replaced, and installs its own only
    # when it holds none: catch_warnings puts showwarning back, so that is put back too (else
    # the caller's captureWarnings(True) afterwards, and the next main()'s, did nothing)
    captured = getattr(logging, "_warnings_showwarning", None)
    try:
        with warnings.catch_warnings():
            yield
    finally:
        _UNDOS.reset(token)
        for undo in reversed(undos):
            undo()
        if hasattr(logging, "_warnings_showwarning"):
            logging._warnings_showwarning = captured
        for h in root.handlers[:]:  # the block's handlers go, the caller's come back
            if h not in handlers:
                root.removeHandler(h)
                h.close()
        for h in handlers:
            if h not in root.handlers:
                root.addHandler(h)
        root.setLevel(level)


__all__ = ["configure_logging", "logging_restored", "restore_after"]
