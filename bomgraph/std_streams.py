"""``-`` as stdin and stdout, and the standard streams of the command (moved from
:mod:`bomgraph.stdio`, h86): an input read from stdin (or a FIFO) is spooled to a temporary
file, an output to stdout is written to one and copied there. A stream closed by the shell
(``<&-``, ``>&-``: Python has none) is refused in one line; a text stream a caller in this
process set (``io.StringIO``, a notebook's) is read or written as text. ``STDIO``,
:func:`~bomgraph.stdio.standard_output` and :func:`~bomgraph.stdio.check_output_path` are
:mod:`bomgraph.stdio`'s, here too for the CLI."""

from __future__ import annotations

import contextlib
import os
import shutil
import stat
import sys
import tempfile
from typing import IO, Callable, Iterator

from .errors import ConfigError, shown_path
from .stdio import CHUNK_BYTES, STDIO, check_output_path, copy_bounded, standard_output

#: temp paths standing for stdin, so messages can name ``<stdin>`` instead.
_SPOOLED: dict[str, str] = {}


def display_path(message: str) -> str:
    """``message`` with every spooled temp path replaced by ``<stdin>``."""
    for tmp, name in _SPOOLED.items():
        message = message.replace(tmp, name)
    return message


@contextlib.contextmanager
def input_path(path: str) -> Iterator[str]:
    """``path`` itself, or for ``-`` and a FIFO (``/dev/stdin`` on a pipe, a named pipe) a
    temporary file holding all of it (removed after; bounded as every input is): a command
    may read its input more than once (``run`` counts its lines for the progress bar), and a
    pipe gives its bytes only once."""
    if path != STDIO:
        try:
            fifo = stat.S_ISFIFO(os.stat(path).st_mode)
        except (OSError, ValueError):  # missing, unreadable, ...: the reader says so
            fifo = False
        if not fifo:
            yield path
            return
    else:
        source = standard_input()  # closed: refused before a temporary folder is made
    with tempfile.TemporaryDirectory(prefix="bomgraph-stdin-") as tmp:
        spooled = os.path.join(tmp, "stdin")
        # kept: the message may be printed after the cleanup; a FIFO named as every message
        _SPOOLED[spooled] = "<stdin>" if path == STDIO else shown_path(path)  # names a file
        with open(spooled, "wb") as fh:
            if path == STDIO:
                copy_bounded(source, fh, spooled)
            else:
                with open(path, "rb") as src:
                    copy_bounded(src, fh, spooled)
        yield spooled


def standard_input() -> IO[bytes]:
    """The bytes of ``sys.stdin`` for ``-`` (of a text stream a caller in this process set,
    UTF-8); refused when closed (``<&-``: a traceback before, h86)."""
    if sys.stdin is None:
        raise ConfigError("-: the standard input is closed; give a file name")
    if hasattr(sys.stdin, "buffer"):
        return sys.stdin.buffer
    return _Encoded(sys.stdin)


class _Encoded:
    """A text stream read as UTF-8 bytes (``read(n)``: at most ``n`` characters)."""

    def __init__(self, text: IO[str]) -> None:
        self._text = text

    def read(self, n: int = -1) -> bytes:
        return self._text.read(n).encode("utf-8")


def write_output(path: str, write: Callable[[str], None]) -> None:
    """``write(path)``, or for ``-`` write to a temporary file and copy it to stdout (or to the
    text stream a caller in this process set as ``sys.stdout``: ``io.StringIO``, a notebook's)."""
    if path != STDIO:
        write(path)
        return
    stdout = standard_output()
    binary = hasattr(stdout, "buffer")
    with tempfile.TemporaryDirectory(prefix="bomgraph-stdout-") as tmp:
        out = os.path.join(tmp, "out")
        write(out)
        with open(out, "rb") if binary else open(out, encoding="utf-8", newline="") as fh:
            shutil.copyfileobj(fh, stdout.buffer if binary else stdout, CHUNK_BYTES)
        stdout.flush()


def is_stdout(path: str) -> bool:
    """Whether writing ``path`` reaches this process's standard output (``-``,
    ``/dev/stdout``, or the file stdout is redirected to): result lines then go to stderr."""
    if path == STDIO:
        return True
    try:
        return os.path.samestat(os.stat(path), os.fstat(sys.stdout.fileno()))
    except (OSError, ValueError, AttributeError):
        return False


@contextlib.contextmanager
def closed_streams_as_none() -> Iterator[None]:
    """A ``sys.stdout`` or ``sys.stderr`` that a caller in this process closed
    (``sys.stdout.close()``) taken for None while a command runs, as the shell's ``>&-``
    leaves it: its lines dropped, ``--out -`` refused as closed; put back after. Before (h92)
    :func:`bomgraph.cli.main` wrote its output, then raised ValueError (I/O operation on
    closed file) at the first line it printed. A closed ``sys.stdin`` is the shell's ``<&-``:
    ``-`` refused as closed, where ValueError came out of main() (h93)."""
    closed = {name: stream for name in ("stdin", "stdout", "stderr")
              if getattr(stream := getattr(sys, name), "closed", False) is True}
    for name in closed:
        setattr(sys, name, None)
    try:
        yield
    finally:
        for name, stream in closed.items():
            if getattr(sys, name) is None:
                setattr(sys, name, stream)


#: with :mod:`bomgraph.stdio`'s ``STDIO``, ``standard_output`` and ``check_output_path``: what
#: a command needs of its standard streams and ``--out``, from one module
__all__ = ["STDIO", "display_path", "input_path", "standard_input", "standard_output",
           "write_output", "is_stdout", "check_output_path", "closed_streams_as_none"]
