"""Files in and out, one rule for every command: ``-`` as stdin/stdout, output paths checked
before any computation and written the one way, inputs read within bounds (issue 13, items 4,
5, 14, 22).

Writing (:func:`output_file`, used by every writer of bomgraph: streams, estimates, exports,
the compare results and cache, figures):

* a symbolic link is followed: the file it points to is written, the link stays a link;
* a character device or a FIFO (``/dev/null``, a named pipe) is written directly, the name of
  a descriptor (``/dev/stdout``, ``/dev/fd/N``, ``/proc/self/fd/N``, a link to one) too: of
  this process through a duplicate of it (a socket too; ``>> f`` appends, ``1<> f`` writes
  from where it stands: never truncated), of another opened to append;
* anything else that exists and is not a regular file (a directory, a block device) is refused;
* a regular file (or a new one) is written beside its target under a unique temporary name
  (``.NAME.XXXXXXXX.partial``, :data:`bomgraph.claims.TEMP_NAME`), flushed to disk and renamed
  into place, so a reader never sees half a file and an interrupted write leaves the old file
  and no stray file (but ``kill -9``: then the temporary file too, which the next writer of
  ``NAME`` removes, :func:`bomgraph.claims.remove_leftovers`; the sweep cache's, the next sweep);
* an output that is one of the command's inputs (the same file, through links or hard links
  too) is refused before anything is computed.

``-`` and the process's standard streams: :mod:`bomgraph.std_streams`.

Reading: :data:`MAX_LINE_BYTES` and :data:`MAX_INPUT_BYTES` bound every text file bomgraph
reads (streams, estimates, datasets, stdin), so an input without newlines (``/dev/zero``) is
refused in one line instead of being read until memory runs out.

The core never prints; these helpers move bytes between files and the process's standard
streams for :mod:`bomgraph.cli` and raise :class:`~bomgraph.errors.BomgraphError` subclasses
(the CLI's logging is set up in :mod:`bomgraph.log_setup`).
"""

from __future__ import annotations

import contextlib
import errno
import logging
import os
import re
import signal
import stat
import sys
import threading
from pathlib import Path
from typing import IO, Any, Callable, Iterator, Sequence

from .checks import file_name, items, out_named
from .claims import new_temp_file, release, remove_leftovers
from .descriptors import (CLOSED_AT_START, fd_name,  # noqa: F401
                          hold_standard_descriptors, open_input, own_descriptor)
from .errors import BomgraphError, shown_path

_log = logging.getLogger(__name__)

STDIO = "-"
#: the longest line any bomgraph text input may have (a stream header with the truth of a
#: 1,000,000-step run is about 60 MiB).
MAX_LINE_BYTES = 64 * 2**20
#: the largest text input bomgraph reads (a stream, an estimate, a dataset file, stdin).
MAX_INPUT_BYTES = 4 * 2**30
#: how much one read takes when a file or stream is copied or measured (1 MiB).
CHUNK_BYTES = 2**20


class OutputPathError(BomgraphError):
    """An ``--out`` that cannot or must not be written."""


class InputTooLargeError(BomgraphError):
    """An input file over :data:`MAX_INPUT_BYTES`, or with a line over :data:`MAX_LINE_BYTES`."""


def _mib(n: int) -> str:
    return f"{n / 2**20:g} MiB"


def line_too_long(path: str | os.PathLike[str], line: int,
                  limit: int = MAX_LINE_BYTES) -> InputTooLargeError:
    """The refusal of a line longer than ``limit`` (:data:`MAX_LINE_BYTES`, or a smaller cap
    on the whole file) with no newline in sight."""
    return InputTooLargeError(
        f"{shown_path(path)}, line {line}: longer than {_mib(limit)} without a "
        f"newline; not a bomgraph text file (is it binary data or a device like /dev/zero?)")


def input_too_large(path: str | os.PathLike[str]) -> InputTooLargeError:
    """The refusal of an input larger than :data:`MAX_INPUT_BYTES`."""
    return InputTooLargeError(f"{shown_path(path)}: larger than {_mib(MAX_INPUT_BYTES)}, the "
                              f"limit for one input file; split the run")


def bounded_lines(fh: IO[bytes], path: str | os.PathLike[str], *,
                  first_line: int = 1) -> Iterator[bytes]:
    """The lines of a binary file from where it stands (each with its newline, the last maybe
    without; numbered from ``first_line`` in messages), refusing a line over
    :data:`MAX_LINE_BYTES` or a file over :data:`MAX_INPUT_BYTES`."""
    total = fh.tell() if fh.seekable() else 0
    number = first_line - 1
    while True:
        raw = fh.readline(MAX_LINE_BYTES + 1)
        if not raw:
            return
        number += 1
        if len(raw) > MAX_LINE_BYTES:
            raise line_too_long(path, number)
        total += len(raw)
        if total > MAX_INPUT_BYTES:
            raise input_too_large(path)
        yield raw


def read_bounded(fh: IO[bytes], path: str | os.PathLike[str]) -> bytes:
    """All of a binary file, refusing it as :func:`bounded_lines` does."""
    return b"".join(bounded_lines(fh, path))


def read_regular_file(path: str | os.PathLike[str]) -> bytes:
    """All of the regular file ``path`` (a JSON file bomgraph wrote: results, cache, manifest),
    refusing anything else before reading: ``OSError`` for a directory, device or FIFO (a
    results.json linked to /dev/zero filled the memory), :class:`InputTooLargeError` for a file
    over :data:`MAX_INPUT_BYTES`. Opened without blocking: opening a FIFO for reading waits
    for a writer (``bomgraph plot --results`` on a results.json that is a FIFO hung)."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0))
    try:   # judged on the descriptor: open(fd) of a folder raises and leaves fd open
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise OSError(errno.EINVAL, "not a regular file")
        fh = open(fd, "rb")
    except BaseException:
        os.close(fd)
        raise
    with fh:
        if st.st_size > MAX_INPUT_BYTES:
            raise input_too_large(path)
        chunks, size = [], 0
        while chunk := fh.read(1 << 20):   # read(4 GiB) would reserve 4 GiB at once
            size += len(chunk)
            if size > MAX_INPUT_BYTES:       # it grew while read
                raise input_too_large(path)
            chunks.append(chunk)
    return b"".join(chunks)


def copy_bounded(src: IO[bytes], dst: IO[bytes], path: str) -> None:
    """Copy ``src`` to ``dst`` in chunks, refusing as :func:`bounded_lines` does (reading at
    most one line's limit beyond the last newline)."""
    total = 0
    since_newline = 0
    line = 1
    while True:
        chunk = src.read(CHUNK_BYTES)
        if not chunk:
            return
        total += len(chunk)
        if total > MAX_INPUT_BYTES:
            raise input_too_large(path)
        last = chunk.rfind(b"\n")
        if last < 0:
            since_newline += len(chunk)
        else:
            line += chunk.count(b"\n")
            since_newline = len(chunk) - last - 1
        if since_newline > MAX_LINE_BYTES:
            raise line_too_long(path, line)
        dst.write(chunk)


def standard_output(name: str = "path") -> IO[str]:
    """``sys.stdout`` for ``--out -``, refused when closed (``>&-``: a traceback before, h83)."""
    if sys.stdout is None:
        raise OutputPathError(f"{out_named(name, STDIO)}: the standard output is closed; give "
                              f"a file name")
    return sys.stdout


def _stdout_not_input(stdout: IO[str], inputs: Sequence[str | os.PathLike[str] | None],
                      name: str = "path") -> None:
    """Refuse ``--out -`` whose stdout is one of ``inputs`` or a file in an input folder (``>>
    INPUT``: read, then the output appended to it), as ``--out /dev/stdout`` is (h86)."""
    try:
        out = os.fstat(stdout.fileno())
    except (OSError, ValueError, AttributeError):  # a text stream of a caller in this process
        return
    for inp in inputs if stat.S_ISREG(out.st_mode) else ():
        if inp is None or os.fspath(inp) == STDIO:
            continue
        try:  # an input folder (mrclam's): any file in it, as for a file name
            st = os.stat(inp)
            same = os.path.samestat(out, st) or stat.S_ISDIR(st.st_mode) and any(
                os.path.samestat(out, os.stat(e.path)) for e in os.scandir(inp))
        except OSError:  # missing, unreadable: its reader says so
            same = False
        if same:
            raise OutputPathError(f"{out_named(name, STDIO)}: the standard output is the input "
                                  f"{shown_path(inp)}; refusing to overwrite an input: choose "
                                  f"another name")


def _stat(path: str, name: str = "path") -> os.stat_result | None:
    try:
        return os.stat(path)  # follows links: what a write would reach
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise OutputPathError(f"{out_named(name, path)}: {exc.strerror}") from None


def _direct(path: str, st: os.stat_result | None) -> bool:
    """Whether ``path`` is written in place: a character device, a FIFO, an open descriptor
    (a socket too, of this process: a service's stdout, h83)."""
    if st is None:
        return False
    if stat.S_ISCHR(st.st_mode) or stat.S_ISFIFO(st.st_mode):
        return True
    sock = stat.S_ISSOCK(st.st_mode) and own_descriptor(path) is not None
    return sock or stat.S_ISREG(st.st_mode) and fd_name(path) is not None


def _open_direct(path: str, st: os.stat_result) -> int:
    """A descriptor to write the device, FIFO or open descriptor ``path`` in place: for a
    descriptor of this process a duplicate of it, with its flags and its position (opening
    ``/dev/stdout`` by name reopens its file from the start, truncated: ``>> f`` lost f's
    content, h79); else ``path`` opened, never truncated (appended to, if a regular file)."""
    own = own_descriptor(path)
    if own is None:
        return os.open(path, os.O_WRONLY | (os.O_APPEND if stat.S_ISREG(st.st_mode) else 0))
    fd = os.dup(own)
    try:
        import fcntl
        readonly = fcntl.fcntl(fd, fcntl.F_GETFL) & os.O_ACCMODE == os.O_RDONLY
    except ImportError:
        readonly = False
    if readonly:
        os.close(fd)
        raise OSError(errno.EBADF, f"descriptor {own} is open for reading only")
    return fd


def check_output_path(path: str | os.PathLike[str],
                      inputs: Sequence[str | os.PathLike[str] | None] = (), *,
                      name: str = "path") -> None:
    """Refuse an output path before anything is computed.

    Refused: a path that is no file name (None, a number), ``inputs`` given as one path
    instead of a list of them, an empty name, a directory, a block device or socket, one of
    ``inputs`` (the same file, through symbolic or hard links too; an input that is a folder
    refuses every file in it), a file whose folder does not exist or is not writable, an
    existing file that is not writable.
    ``-`` (stdout), character devices, FIFOs and this process's descriptors (a socket too) pass.

    Raises
    ------
    OutputPathError
    """
    path = file_name(path, out_named(name), OutputPathError)
    inputs = items(inputs, (str, os.PathLike, type(None)), "inputs (the files read)",
                   OutputPathError, want="file names")
    if path == STDIO:
        _stdout_not_input(standard_output(name), inputs, name)  # closed: refused before
        return
    if not path:  # os.path.realpath("") is the working folder: the rename would aim at it
        raise OutputPathError(f"{out_named(name)} is empty; give a file name")
    st = _stat(path, name)
    if fd_name(path) is not None and (st is None or own_descriptor(path) in CLOSED_AT_START):
        # /dev/stdout under >&-: not a folder's file; /dev/null on it is no output either
        raise OutputPathError(f"{out_named(name, path)}: that descriptor is not open; give a "
                              f"file name")
    if st is not None and stat.S_ISDIR(st.st_mode):
        raise OutputPathError(f"{out_named(name, path)}: is a directory; give a file name")
    direct = _direct(path, st)
    if direct:
        if not os.access(path, os.W_OK):
            raise OutputPathError(f"{out_named(name, path)}: not writable")
        if not stat.S_ISREG(st.st_mode):
            return
    elif st is not None and not stat.S_ISREG(st.st_mode):
        raise OutputPathError(f"{out_named(name, path)}: exists and is neither a regular file, a "
                              f"character device nor a FIFO; choose another name")
    target = os.path.realpath(path)
    for inp in inputs:
        if inp is None or os.fspath(inp) == STDIO:
            continue
        inp = os.fspath(inp)
        same = os.path.realpath(inp) == target
        if not same and st is not None and os.path.exists(inp):
            with contextlib.suppress(OSError):
                same = os.path.samefile(path, inp)
        if not same and os.path.isdir(inp):
            same = os.path.dirname(target) == os.path.realpath(inp) and target in {
                os.path.realpath(os.path.join(inp, f)) for f in os.listdir(inp)}
        if same:
            raise OutputPathError(f"{out_named(name, path)}: is the input {shown_path(inp)}; "
                                  f"refusing to overwrite "
                                  f"an input: choose another name")
    if direct:  # a file open as a descriptor (``>> f``): written where it is
        return
    folder = Path(target).parent
    there = f"{out_named(name, path)}: the folder {shown_path(folder)}"
    if not folder.is_dir():
        raise OutputPathError(f"{there} does not exist")
    if st is not None and not os.access(target, os.W_OK):
        raise OutputPathError(f"{out_named(name, path)}: the file is not writable")
    if not os.access(folder, os.W_OK | os.X_OK):  # a file too: replaced from one made beside it
        raise OutputPathError(f"{there} is not writable")


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """Block SIGTERM and SIGINT for the block (main thread, POSIX); a signal that came
    meanwhile is delivered, and its handler run, when the block ends."""
    if (not hasattr(signal, "pthread_sigmask")
            or threading.current_thread() is not threading.main_thread()):
        yield
        return
    held = {signal.SIGTERM, signal.SIGINT}
    old = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


class AtomicOutput:
    """The one way bomgraph writes a file (see the module docstring): :meth:`open` gives the
    handle, :meth:`commit` puts the file in place, :meth:`abort` removes what was written
    beside it. :func:`output_file` wraps the three for a ``with`` block."""

    def __init__(self, path: str | os.PathLike[str], *, binary: bool = False,
                 inputs: Sequence[str | os.PathLike[str] | None] = (),
                 ready: Callable[[str], None] | None = None, leftovers: bool = True) -> None:
        check_output_path(path, inputs)
        self._leftovers = leftovers  # remove the name's leftovers (not: its caller does, h83)
        self._ready = ready  # called with the finished temporary file, before it replaces path
        self.given = os.fspath(path)
        st = _stat(self.given)
        self.direct = _direct(self.given, st)
        self._st = st
        self.path = self.given if self.direct else os.path.realpath(self.given)
        self._mode = 0o666 & ~_umask() if st is None else stat.S_IMODE(st.st_mode)
        self._binary = binary
        self._tmp: str | None = None
        self._claim: int | None = None  # its temporary file's lock (bomgraph.claims)
        self.fh: IO | None = None

    def open(self) -> IO:
        """The handle to write to; an :class:`OutputPathError` naming the path the user gave
        (never the temporary file) when it cannot be created."""
        try:
            return self._open()
        except OSError as exc:
            where = os.path.dirname(self.path) or "."
            what = ("cannot open it for writing" if self.direct
                    else f"cannot create a file in {shown_path(where)}")
            raise OutputPathError(f"{shown_path(self.given)}: {what} ({exc.strerror or exc}); "
                                  f"choose another {out_named('path')}") from None

    def _open(self) -> IO:
        kw = {} if self._binary else {"encoding": "utf-8", "newline": "\n"}
        mode = "wb" if self._binary else "w"
        if self.direct:
            fd = _open_direct(self.given, self._st)
            try:
                self.fh = open(fd, mode, **kw)
            except BaseException:
                os.close(fd)
                raise
            return self.fh
        d, name = os.path.split(self.path)
        # SIGTERM/SIGINT are held back from the temporary file's creation until the handle
        # owns it: a signal raising mid-way would leave a file nobody removes, or close the
        # descriptor twice (EBADF). Delivered at the unmask, the handle is in place for abort.
        with signals_held():
            fd, self._tmp, self._claim = new_temp_file(d, name)
            try:
                os.chmod(fd, self._mode)  # as open() would (or as the file was), not 0600
                self.fh = os.fdopen(fd, mode, **kw)
            except BaseException:
                with contextlib.suppress(OSError):
                    os.close(fd)
                self.abort()
                raise
        if self._claim is not None and self._leftovers:  # a killed claimer's is known
            removed = remove_leftovers(d, [name], keep=self._tmp)
            if removed:
                _log.info("removed %d temporary file(s) of %s that killed writers left",
                          removed, self.path)
        return self.fh

    def commit(self) -> None:
        if self.fh is None:
            raise RuntimeError("AtomicOutput.commit before open")
        try:
            self.fh.flush()
            if self._tmp is not None:
                os.fsync(self.fh.fileno())
        finally:
            self.fh.close()
            self.fh = None
        if self._tmp is not None:
            if self._ready is not None:  # e.g. compare's journal lists it before it is in place
                self._ready(self._tmp)
            os.replace(self._tmp, self.path)
            self._tmp = None
            release(self._claim)
            self._claim = None
            _fsync_dir(os.path.dirname(self.path))

    def abort(self) -> None:
        with signals_held():  # a second Ctrl-C must not stop the cleanup of the first
            if self.fh is not None:
                with contextlib.suppress(OSError):
                    self.fh.close()
                self.fh = None
            if self._tmp is not None:
                with contextlib.suppress(OSError):
                    os.unlink(self._tmp)
                self._tmp = None
            release(self._claim)
            self._claim = None


@contextlib.contextmanager
def output_file(path: str | os.PathLike[str], *, binary: bool = False,
                inputs: Sequence[str | os.PathLike[str] | None] = (),
                ready: Callable[[str], None] | None = None,
                leftovers: bool = True) -> Iterator[IO]:
    """A handle to write ``path`` the one way (module docstring); the file is in place when
    the block ends normally, and nothing is left beside it when it raises (SIGTERM too, under
    the CLI, which turns it into ``SystemExit``). ``ready`` is called with the finished file
    beside ``path`` just before it replaces ``path`` (not for a device or FIFO, written
    directly); if it raises, ``path`` is left as it was. ``leftovers=False``: the killed
    writers' temporary files of ``path``'s name are left to the caller (the sweep cache's
    folder is cleaned once a sweep, not listed again for each of its thousands of files)."""
    out = AtomicOutput(path, binary=binary, inputs=inputs, ready=ready, leftovers=leftovers)
    try:
        fh = out.open()
        yield fh
        out.commit()  # inside: an interrupt during its flush and fsync removes the file too
    except BaseException:
        out.abort()
        raise


def write_text(path: str | os.PathLike[str], text: str,
               inputs: Sequence[str | os.PathLike[str] | None] = (),
               ready: Callable[[str], None] | None = None) -> None:
    """``text`` into ``path`` through :func:`output_file`."""
    with output_file(path, inputs=inputs, ready=ready) as fh:
        fh.write(text)


def write_figure(fig: Any, path: str | os.PathLike[str], dpi: int,
                 ready: Callable[[str], None] | None = None) -> str:
    """A matplotlib figure into ``path`` through :func:`output_file` (its format by the
    suffix: .png, .pdf, .svg), so an interrupted save leaves the earlier figure, not half of
    one; returns the path."""
    with output_file(path, binary=True, ready=ready) as fh:
        fig.savefig(fh, format=os.fspath(path).rsplit(".", 1)[-1].lower(), dpi=dpi,
                    facecolor="white")
    return os.fspath(path)


class FolderBusyError(BomgraphError):
    """Another process holds the lock of an output folder."""


def check_folder(folder: str | os.PathLike[str]) -> None:
    """Refuse an output folder that is empty or is or lies under a file or a link to a missing
    folder, or that is (or would be made in) a folder this process cannot write
    (:class:`OutputPathError`, naming it, not ``[Errno 13]``/``[Errno 17]``/``[Errno 20]``);
    no mkdir."""
    if not os.fspath(folder):   # Path('') is '.'
        raise OutputPathError(f"{out_named('out_dir')} is empty; give a folder ('.' for this "
                              f"one)")
    path = Path(folder)
    for at in (path, *path.parents):   # the nearest one that exists must be a folder
        if os.path.isdir(at):
            if not os.access(at, os.W_OK | os.X_OK):  # not '[Errno 13] ...: OUT/.bomgraph.lock'
                name = "" if at == path else f"{shown_path(at)}, where it would be made, "
                raise OutputPathError(f"{out_named('out_dir', folder)}: {name}is not "
                                      f"writable; choose another folder")
            return
        if os.path.lexists(at):   # mkdir does not follow a link: [Errno 17] File exists
            what = (f"a link to {shown_path(os.readlink(at))}, which does not exist; create "
                    f"that folder, or give another" if not os.path.exists(at) else
                    "a file; give a folder (it is created if missing)")
            name = "" if at == path else f"{shown_path(at)} "
            raise OutputPathError(f"{out_named('out_dir', folder)}: {name}is {what}")


def make_folder(folder: str | os.PathLike[str]) -> None:
    """Create the output folder ``folder`` and its parents (:func:`check_folder` first)."""
    check_folder(folder)
    Path(folder).mkdir(parents=True, exist_ok=True)


#: the folder :func:`folder_lock` first said it could not lock (no flock), once a process
_NO_LOCK_SAID: list[str | os.PathLike[str]] = []


@contextlib.contextmanager
def folder_lock(folder: str | os.PathLike[str], what: str,
                shared: bool = False) -> Iterator[None]:
    """Hold an exclusive lock on ``folder`` (``fcntl.flock`` on ``folder/.bomgraph.lock``) for
    the block, so two sweeps never write one folder; a second one is refused at once.
    ``shared``: a shared lock (a compare writing below ``folder``, not into it), refused while
    an exclusive one is held and refusing one, not refusing another shared one; on a lock file
    that is there (none is made, nothing written: the folder may be another user's, or ``/``).
    Where there is no ``fcntl`` (Windows) no lock is taken, and a warning says so once.

    Raises
    ------
    FolderBusyError
        The folder is locked by another process (the message names its pid).
    OutputPathError
        ``.bomgraph.lock`` there holds something else than a pid (a user's file).
    """
    try:
        import fcntl
    except ImportError:  # no flock on this platform (Windows): no lock, said once (h107)
        if not _NO_LOCK_SAID:
            _NO_LOCK_SAID.append(folder)
            _log.warning("%s is not locked: this platform has no flock, so two compares into "
                         "one folder at once are not kept apart; run one at a time", folder)
        yield
        return
    lock = os.path.join(os.fspath(folder), ".bomgraph.lock")
    not_ours = (f"{shown_path(lock)}: is not a bomgraph lock (a process id); move it or "
                f"choose another {out_named('out_dir')}")
    try:  # without blocking: a FIFO there is refused, not waited on; a link too (h100)
        fd = os.open(lock, (os.O_RDONLY if shared else os.O_RDWR | os.O_CREAT)
                     | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOFOLLOW", 0),
                     0o666 & ~_umask())
    except OSError as exc:  # a link: ELOOP (its target was emptied, or made, h100)
        if isinstance(exc, IsADirectoryError) or exc.errno == errno.ELOOP:
            raise OutputPathError(not_ours) from None
        if not (shared and isinstance(exc, FileNotFoundError)):
            raise
        fd = -1  # shared, and no lock file: none is made in a folder above; nothing holds it
    if fd < 0:
        yield
        return
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):  # a FIFO: "[Errno 29] Illegal seek"
            raise OutputPathError(not_ours)
        try:
            fcntl.flock(fd, (fcntl.LOCK_SH if shared else fcntl.LOCK_EX) | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 64, 0).decode("ascii", "replace").strip() or "?"
            who, where = f" (pid {holder})", "into this folder"
            if not shared and _lock_is_shared(fd):  # held by compares writing below it only
                who, where = "", "below this folder, through a link or from a folder above"
            raise FolderBusyError(
                f"{shown_path(folder)}: another {what}{who} is writing {where}; wait for it to "
                f"finish or choose another {out_named('out_dir')}") from None
        if os.fstat(fd).st_size > 64 or not re.fullmatch(rb"\s*\d*\s*", os.pread(fd, 64, 0)):
            raise OutputPathError(not_ours)  # not a pid (judged whole): not ours to empty
        if not shared:  # shared holders would overwrite each other's: the last writer's stays
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode("ascii"), 0)
        yield
    finally:
        os.close(fd)  # releases the lock; the file stays (removing it would race)


def _lock_is_shared(fd: int) -> bool:
    """Whether the lock on ``fd`` that refused an exclusive one is held shared only."""
    import fcntl
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True  # released with fd, closed by the caller


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _fsync_dir(d: str) -> None:
    try:
        fd = os.open(d or ".", os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


__all__ = ["STDIO", "MAX_LINE_BYTES", "MAX_INPUT_BYTES", "OutputPathError", "InputTooLargeError",
           "line_too_long", "input_too_large", "bounded_lines", "read_bounded", "read_regular_file",
           "copy_bounded", "hold_standard_descriptors", "open_input", "standard_output",
           "check_output_path", "AtomicOutput", "output_file", "write_text", "write_figure",
           "FolderBusyError", "check_folder", "make_folder", "folder_lock", "signals_held",
           "CHUNK_BYTES"]
