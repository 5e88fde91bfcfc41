"""The SHA-256 of an input file's bytes (a stream file, the files a recording's importer reads:
:func:`inputs_sha256`), what the runner's cache key (:func:`bomgraph.bench.task_key`) holds of
a source read from disk, so that a cached result belongs to the data as it is now, wherever it
is: a file replaced by other bytes of the same size with its modification time kept (``cp
-p``, ``rsync -a``, ``touch -r``, an archive's fixed times) runs again; a copy elsewhere does
not.

Each file is hashed once a process while its status stays the same: a sweep keys each of its
tasks (and a worker each task it runs), and MRCLAM6's 17 files (26 MB) took 18 ms to hash
against 0.4 ms to stat. The status is the device, inode, size, modification time and change
time (``ctime``, which any write sets and no tool puts back). Which status can stand for the
bytes read after it (:func:`settled_status`, the "racy" rule of git's index) is decided here
once, for every reader that keeps what it read while the status stays (:func:`cached_read`):
this module's digests, and the listings and digests of a plugin's source files
(:mod:`bomgraph.source_files`).
"""

from __future__ import annotations

import hashlib
import os
import stat
import time
from pathlib import Path
from time import monotonic_ns
from typing import Callable, Mapping, TypeVar

#: A status whose modification or change time is within this long [ns] of the clock, behind
#: it or ahead (its change time ahead at all), is not trusted: the file is read again the
#: next time (2 s: FAT's timestamps; ext3 and HFS+ keep a second). The one knob of the rule
#: (:func:`settled_status`).
RACY_NS = 2_000_000_000

#: At most this many files' digests are kept (a recording of a few hundred files included).
MAX_KEPT = 4096

#: A file's device, inode, size, modification and change time, whether the modification time
#: is ahead of the clock, and the clock's steps back seen so far (:func:`settled_status`).
Status = tuple[int, ...]

#: Per file (its absolute path): its :func:`settled_status` and the SHA-256 of the bytes read
#: after it.
_KEPT: dict[str, tuple[Status, str]] = {}

#: The clock's steps back seen (:func:`_read_clock`), and its reading less the monotonic
#: clock's at the last status taken.
_STEPS = 0
_OFFSET: int | None = None

K = TypeVar("K", bound="str | os.PathLike[str]")
V = TypeVar("V")


def settled_status(path: str | os.PathLike[str]) -> Status | None:
    """The status of the file or folder at ``path`` (links followed: device, inode, size,
    modification and change time, and whether the modification time is ahead of the clock)
    if it can stand for the bytes or entries read after it; None when it cannot be taken,
    and on Windows (``st_ctime`` is the creation time there, which a write does not change).

    A write gives the file its clock's time, and a file system with coarse timestamps keeps
    the status through a same-size write within one tick. So the change time must be over
    :data:`RACY_NS` behind the clock read before the status (a write since has a later
    time), and so must the modification time, or be over :data:`RACY_NS` ahead of the clock
    read after it (a write before it has an earlier time): an mtime set ahead (``touch -d
    tomorrow``, an archive's) was read again at every call. A ctime ahead is never settled:
    no tool sets it, so the clock that wrote it is not this one (a file server's ahead of
    ours, or ours stepped back), and a same-size write in its tick keeps it (h115). An mtime
    ahead counts only while it stays ahead: the status says whether it is, so once the clock
    has passed it, what was kept under it no longer matches (a write in its tick may have
    kept the rest). The ctime alone would do where every write sets it; the mtime is
    checked too for a file system whose ctime does not follow writes (Linux's vfat driver
    long read it from the creation time). The clock is read before the status, not after
    the read: a read that took seconds (a large file on a network disk) made a status taken
    within a tick of a write look settled (h105, h107). The status holds how many times the
    clock was seen to step back (:func:`_read_clock`): a write after a step back can have
    the times of a status kept before it."""
    if os.name == "nt":
        return None
    before_ns, steps = _read_clock()
    try:
        status = _status(os.stat(path))
    except OSError:
        return None
    after_ns = time.time_ns()
    mtime_ns, ctime_ns = status[3:5]
    ahead = int(mtime_ns - after_ns > RACY_NS)
    if before_ns - ctime_ns > RACY_NS and (ahead or before_ns - mtime_ns > RACY_NS):
        return status + (ahead, steps)
    return None


def _read_clock() -> tuple[int, int]:
    """The clock's reading now and how many times it was seen to step back (set back by NTP
    or by hand): its reading less the monotonic clock's, which no step moves, fell since the
    last status (the monotonic clock read on either side, so that a pause between the two
    clocks' readings is not taken for a step; by over a millisecond, as a clock slewed apart
    from the other drifts). A step back and a same-size write in the tick of a status kept
    before it (taken well after that tick), the clock then on again, kept its status: the
    old bytes' digest was served (h115)."""
    global _STEPS, _OFFSET
    start_ns = monotonic_ns()
    now_ns = time.time_ns()
    end_ns = monotonic_ns()
    if _OFFSET is not None and now_ns - start_ns < _OFFSET - 1_000_000:
        _STEPS += 1
    _OFFSET = now_ns - end_ns
    return now_ns, _STEPS


def _status(st: os.stat_result) -> Status:
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)


def cached_read(kept: dict[K, tuple[Status, V]], path: K, read: Callable[[], V],
                most: int | None = None) -> tuple[Status | None, V]:
    """What ``read()`` returns for the file or folder at ``path`` (its bytes' digest, its
    entries), given again from ``kept`` while its :func:`settled_status` stays the same, and
    that status (None: not settled; nothing is then kept). The status is taken before the
    read, so a write during the read changes it. ``most``: ``kept`` is emptied before it
    would hold more."""
    status = settled_status(path)
    seen = kept.get(path)
    if status is not None and seen is not None and seen[0] == status:
        return status, seen[1]
    value = read()
    if status is not None:
        if most is not None and len(kept) >= most:
            kept.clear()
        kept[path] = (status, value)
    return status, value


def file_sha256(path: str | os.PathLike[str]) -> str:
    """The hex SHA-256 of the bytes of the file at ``path`` (links followed), as they are now.

    Raises
    ------
    OSError
        The file cannot be opened or read.
    """
    name = os.path.abspath(path)  # a link's target is in the status (its device and inode)

    def read() -> str:
        with open(name, "rb") as fh:
            return hashlib.file_digest(fh, "sha256").hexdigest()

    return cached_read(_KEPT, name, read, most=MAX_KEPT)[1]


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


__all__ = ["RACY_NS", "settled_status", "cached_read", "file_sha256", "inputs_sha256",
           "special_file", "forget"]
