"""Names of the process's own descriptors (``/dev/stdout``, ``/dev/fd/N``,
``/proc/self/fd/N``, through symbolic links too) and the standard descriptors 0-2 the program
found closed at its start, held on /dev/null (:func:`hold_standard_descriptors`) and refused
when named as an input (:func:`open_input`) or an output
(:func:`bomgraph.stdio.check_output_path`). Split out of :mod:`bomgraph.stdio`, which uses it.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
from typing import IO

#: names that stand for an already open descriptor: written directly, never renamed over.
_FD_NAME = re.compile(r"^/(dev/(stdout|stderr|stdin|fd/(\d+))"
                      r"|proc/(self|thread-self|\d+)(?:/task/\d+)?/fd/(\d+))$")
_STANDARD = {"stdin": 0, "stdout": 1, "stderr": 2}


#: the standard descriptors that :func:`hold_standard_descriptors` found closed
CLOSED_AT_START: set[int] = set()


def hold_standard_descriptors() -> None:
    """/dev/null on each of descriptors 0, 1 and 2 that is closed (``<&-``, ``>&-``,
    ``2>&-``), for the program (:func:`bomgraph.cli.program`) before it opens anything: else
    the first file it opened took that number, and whatever wrote to the descriptor after (a
    method's C library, a worker process, which inherits it) wrote into that file (h92: text
    a method wrote to descriptor 1 landed in ``compare``'s ``.bomgraph.lock``). Python's
    ``sys.stdin``/``sys.stdout``/``sys.stderr`` stay None: ``-`` is still refused as closed,
    and so is ``--out /dev/stdout`` (:func:`check_output_path`)."""
    for fd in (0, 1, 2):
        try:
            os.fstat(fd)
            continue
        except OSError:
            pass
        with contextlib.suppress(OSError):  # no /dev/null to open: left closed, as before
            null = os.open(os.devnull, os.O_RDWR)  # the lowest free number: fd itself
            if null != fd:
                os.dup2(null, fd)
                os.close(null)
            os.set_inheritable(fd, True)  # as the shell's would be: worker processes get it
            CLOSED_AT_START.add(fd)


def open_input(path: str | os.PathLike[str]) -> IO[bytes]:
    """``open(path, "rb")``, but the name of a descriptor that :func:`hold_standard_descriptors`
    found closed (``/dev/stdin`` under ``<&-``) raises OSError: reading it read the /dev/null
    held on it, an empty input refused for what it lacked (h93)."""
    if CLOSED_AT_START and (fd := own_descriptor(os.fspath(path))) in CLOSED_AT_START:
        raise OSError(errno.EBADF, f"descriptor {fd} was closed when bomgraph started")
    return open(path, "rb")


def fd_name(path: str) -> re.Match[str] | None:
    """The name of a descriptor that ``path`` is, or that its symbolic links lead to (``out
    -> /dev/stdout``: the file behind it was replaced, ``>> f`` lost f too), else None."""
    for _ in range(40):  # the kernel's limit of links followed
        path = os.path.abspath(path)
        path = path[1:] if path.startswith("//") else path  # //dev/fd/1: abspath keeps it
        m = _FD_NAME.match(path)
        if m is not None or not os.path.islink(path):
            return m
        try:
            path = os.path.join(os.path.dirname(path), os.readlink(path))
        except OSError:  # gone meanwhile: the write says so
            return None
    return None


def own_descriptor(path: str) -> int | None:
    """The descriptor of this process that ``path`` names (``/dev/stdout``: 1, ``/dev/fd/N``,
    ``/proc/self/fd/N``: N; through links too), else None (another process's, or none)."""
    m = fd_name(path)
    if m is None or (m[4] not in (None, "self", "thread-self") and int(m[4]) != os.getpid()):
        return None
    return _STANDARD[m[2]] if m[2] in _STANDARD else int(m[3] or m[5])


__all__ = ["hold_standard_descriptors", "open_input", "fd_name", "own_descriptor",
           "CLOSED_AT_START"]
