"""The SHA-256 of an input file's bytes (a stream file, the files a recording's importer reads:
:func:`inputs_sha256`), what the runner's cache key (:func:`bomgraph.bench.task_key`) holds of
a source read from disk, so that a cached result belongs to the data as it is now, wherever it
is: a file replaced by other bytes of the same size with its modification time kept (``cp
-p``, ``rsync -a``, ``touch -r``, an archive's fixed times) runs again; a copy elsewhere does
not.

Each file is hashed once a process while its status stays the same: a sweep keys each of its
tasks (and a worker each task it runs), and MRCLAM6's 17 files (26 MB) took 18 ms to hash
against 0.4 ms to stat. The status is the device, inode, size, modification time and change
time (``ctime``, which any write sets and no tool puts back); a file whose status changed less
than :data:`RACY_NS` before it was hashed is hashed again the next time, as git's "racy" index
entries and :func:`bomgraph.plugins._disk_digest` (a file system with coarse timestamps keeps
the status through a same-size write within one tick of its clock).
"""

from __future__ import annotations

import hashlib
import os
import stat
import time
from pathlib import Path
from typing import Mapping

#: A file whose status changed less than this long [ns] before it was hashed is hashed again
#: the next time (2 s: FAT's timestamps; ext3 and HFS+ keep a second).
RACY_NS = 2_000_000_000

#: At most this many files' digests are kept (a recording of a few hundred files included).
MAX_KEPT = 4096

#: Per file (its absolute path): its :func:`_status` and the SHA-256 of the bytes read after it.
_KEPT: dict[str, tuple[tuple[int, ...], str]] = {}


def _status(st: os.stat_result) -> tuple[int, ...]:
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)


def _aged(status: tuple[int, ...], now_ns: int) -> bool:
    """Whether ``status`` had last changed over :data:`RACY_NS` before ``now_ns`` (mtime and
    ctime), the time it was taken at, so that it can stand for the bytes read after it: never
    on Windows, where ``st_ctime`` is the creation time, which a write does not change. The
    time before the status, not after the read (h105): a read that took seconds (a large file
    on a network disk) made a status taken within a tick of a write look aged, and a write in
    that tick during the read kept its status and a digest of neither content."""
    return os.name != "nt" and now_ns - max(status[3], status[4]) > RACY_NS


def file_sha256(path: str | os.PathLike[str]) -> str:
    """The hex SHA-256 of the bytes of the file at ``path`` (links followed), as they are now.

    Raises
    ------
    OSError
        The file cannot be opened or read.
    """
    name = os.path.abspath(path)  # a link's target is in the status (its device and inode)
    now_ns = time.time_ns()  # before the status (_aged)
    status = _status(os.stat(name))  # before the read: a write after it changes it
    kept = _KEPT.get(name)
    if kept is not None and kept[0] == status:
        return kept[1]
    with open(name, "rb") as fh:
        digest = hashlib.file_digest(fh, "sha256").hexdigest()
    if _aged(status, now_ns):
        if len(_KEPT) >= MAX_KEPT:
            _KEPT.clear()
        _KEPT[name] = (status, digest)
    return digest


def inputs_sha256(inputs: Mapping[str, str | os.PathLike[str] | None]) -> str:
    """One hex SHA-256 of the files an importer reads (role -> file, None where there is
    none), each named by its role and by whether its name ends in ``.gz`` (read decompressed),
    never by its folder or path, and hashed by :func:`file_sha256`: the same bytes anywhere
    have the same digest, and one byte changed in any of them changes it. A file that cannot
    be read counts by its size and modification time, one that is not a regular file (a FIFO,
    which hashing would block on) by what it is, one absent as absent: the importer that needs
    it says why it cannot."""
    h = hashlib.sha256()
    for role in sorted(inputs):
        path = inputs[role]
        gz = path is not None and Path(path).suffix == ".gz"
        digest = "absent" if path is None else _input_digest(path)
        h.update(f"{role}\0{'gz' if gz else ''}\0{digest}\0".encode())
    return h.hexdigest()


def _input_digest(path: str | os.PathLike[str]) -> str:
    try:
        st = os.stat(path)
    except OSError as exc:  # removed since it was found, a link broken since
        return f"absent ({exc.errno})"
    if not stat.S_ISREG(st.st_mode):  # its bytes cannot be told: DatasetSource refuses it
        return f"not a regular file ({stat.S_IFMT(st.st_mode):o})"
    try:
        return file_sha256(path)
    except OSError as exc:
        return f"unreadable ({exc.errno}) {st.st_size} {st.st_mtime_ns}"


#: What :func:`special_file` calls each kind of file that is neither regular nor a folder.
_SPECIAL = ((stat.S_ISFIFO, "FIFO"), (stat.S_ISCHR, "character device"),
            (stat.S_ISBLK, "block device"), (stat.S_ISSOCK, "socket"))


def special_file(path: str | os.PathLike[str]) -> str | None:
    """What ``path`` (links followed) is when it is a FIFO, device or socket, whose bytes
    cannot be hashed without being consumed (or never end), so a key holds what it is, not
    its bytes; None for a regular file, a folder, or nothing there."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return None
    return next((name for test, name in _SPECIAL if test(mode)), None)


def forget() -> None:
    """Forget every kept digest (each file is hashed again)."""
    _KEPT.clear()


__all__ = ["RACY_NS", "file_sha256", "inputs_sha256", "special_file", "forget"]
