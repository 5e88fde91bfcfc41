"""Standard streams and output paths for the command line: ``-`` as stdin/stdout, and the
checks an output path gets before any computation (issue 13, item 22).

The core never prints; these helpers move bytes between files and the process's standard
streams for :mod:`bomgraph.cli` and raise :class:`~bomgraph.errors.BomgraphError` on a path
that cannot be written.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Callable, Iterator

from .errors import BomgraphError

STDIO = "-"
#: temp paths standing for stdin, so messages can name ``<stdin>`` instead.
_SPOOLED: dict[str, str] = {}


class OutputPathError(BomgraphError):
    """An ``--out`` that cannot or must not be written."""


def display_path(message: str) -> str:
    """``message`` with every spooled temp path replaced by ``<stdin>``."""
    for tmp, name in _SPOOLED.items():
        message = message.replace(tmp, name)
    return message


@contextlib.contextmanager
def input_path(path: str) -> Iterator[str]:
    """``path`` itself, or for ``-`` a temporary file holding all of stdin (removed after)."""
    if path != STDIO:
        yield path
        return
    with tempfile.TemporaryDirectory(prefix="bomgraph-stdin-") as tmp:
        spooled = os.path.join(tmp, "stdin")
        with open(spooled, "wb") as fh:
            shutil.copyfileobj(sys.stdin.buffer, fh)
        _SPOOLED[spooled] = "<stdin>"  # kept: the message may be printed after the cleanup
        yield spooled


def write_output(path: str, write: Callable[[str], None]) -> None:
    """``write(path)``, or for ``-`` write to a temporary file and copy it to stdout."""
    if path != STDIO:
        write(path)
        return
    with tempfile.TemporaryDirectory(prefix="bomgraph-stdout-") as tmp:
        out = os.path.join(tmp, "out")
        write(out)
        with open(out, "rb") as fh:
            shutil.copyfileobj(fh, sys.stdout.buffer)
        sys.stdout.buffer.flush()


def check_output_path(path: str, inputs: tuple[str, ...] = ()) -> None:
    """Refuse an output path before anything is computed.

    Refused: a directory, one of ``inputs`` (the same file, through links too), a file whose
    folder does not exist or is not writable, an existing file that is not writable. ``-``
    (stdout) always passes.

    Raises
    ------
    OutputPathError
    """
    if path == STDIO:
        return
    p = Path(path)
    if p.is_dir():
        raise OutputPathError(f"--out {path}: is a directory; give a file name")
    for inp in inputs:
        if inp != STDIO and os.path.exists(inp) and p.exists() and os.path.samefile(p, inp):
            raise OutputPathError(f"--out {path}: is the input {inp}; writing it would "
                                  f"destroy the input, choose another name")
    folder = p.resolve().parent
    if not folder.is_dir():
        raise OutputPathError(f"--out {path}: the folder {folder} does not exist")
    if p.exists() and not os.access(p, os.W_OK):
        raise OutputPathError(f"--out {path}: the file is not writable")
    if not p.exists() and not os.access(folder, os.W_OK | os.X_OK):
        raise OutputPathError(f"--out {path}: the folder {folder} is not writable")


__all__ = ["STDIO", "OutputPathError", "display_path", "input_path", "write_output",
           "check_output_path"]
