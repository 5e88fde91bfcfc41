"""The temporary files bomgraph's writers write under (:class:`bomgraph.stdio.AtomicOutput`),
and the lock a writer holds on its own while it writes it (h77): so that the removal of the
ones killed writers left (``kill -9``, a power cut) leaves the one another process writes now
(a ``bomgraph run --out OUT/results.csv`` while compare cleans ``OUT``; a second ``run`` of
the same ``--out``; two sweeps sharing a cache folder). ``flock`` is released when the writer
dies, ``kill -9`` too. The removers: every writer, of the name it writes
(:func:`remove_leftovers`), but the sweep cache's, whose folder each sweep cleans once
(:func:`remove_leftovers_like`, :func:`bomgraph.result_cache.remove_cache_leftovers`), and
compare, of the names its folder holds
(:meth:`bomgraph.out_folder.OutputRecord.remove_leftovers`)."""

from __future__ import annotations

import contextlib
import errno
import logging
import os
import re
import stat
import tempfile
from typing import Iterable

_log = logging.getLogger(__name__)

#: The name a writer writes ``NAME`` under until it renames it (:func:`new_temp_file`:
#: ``tempfile.mkstemp(prefix=".NAME.", suffix=".partial")``, 8 characters of tempfile's);
#: ``format(name=re.escape(NAME))`` gives the pattern of ``NAME``'s.
TEMP_NAME = r"\.{name}\.[a-z0-9_]{{8}}\.partial"
#: new names tried when a remover took each one as it was created (it never happens twice)
_ATTEMPTS = 8


def new_temp_file(folder: str, name: str) -> tuple[int, str, int | None]:
    """A new temporary file for ``name`` in ``folder`` (named as :data:`TEMP_NAME`): its
    descriptor, its path and its claim (a second descriptor holding an exclusive ``flock``
    on it until :func:`release`; None where there is no flock: the file is written all the
    same).

    Between its creation and its lock a file is unclaimed for microseconds, and a remover
    (:func:`remove_unclaimed`, which removes only under the lock) may take it then: the lock
    is therefore taken first and the file checked to be still in ``folder`` under its name
    after; one taken is let go (not removed: it is gone) and another made. Nothing is ever
    written into a removed file, without any timing assumption."""
    for _ in range(_ATTEMPTS):
        fd, path = tempfile.mkstemp(prefix=f".{name}.", suffix=".partial", dir=folder)
        try:
            held, taken = _claim(fd, path)
        except BaseException:
            os.close(fd)
            with contextlib.suppress(OSError):
                os.unlink(path)
            raise
        if not taken:
            return fd, path, held
        os.close(fd)
        _log.debug("%s was removed as it was created (another writer's cleaning); "
                   "writing under another name", path)
    raise OSError(errno.EAGAIN, f"each temporary file made for {name} was removed at once")


def _claim(fd: int, path: str) -> tuple[int | None, bool]:
    """The claim of the new file ``fd`` at ``path`` (None without flock), and whether a
    remover took the file first (then no claim)."""
    try:
        import fcntl
    except ImportError:
        return None, False
    held = os.dup(fd)
    try:
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:  # a remover holds it: it is removing it
        os.close(held)
        return None, True
    except OSError:  # no flock on this file system
        os.close(held)
        return None, False
    try:  # a remover that held the lock before has removed it
        kept = os.path.samestat(os.fstat(held), os.stat(path, follow_symlinks=False))
    except FileNotFoundError:
        kept = False
    except BaseException:
        os.close(held)
        raise
    if not kept:
        os.close(held)
        return None, True
    return held, False


def release(held: int | None) -> None:
    """Close :func:`new_temp_file`'s claim: the file is in place, or removed."""
    if held is not None:
        with contextlib.suppress(OSError):
            os.close(held)


def remove_unclaimed(path: str) -> bool:
    """Remove the regular file ``path`` unless a writer still holds it (its claim,
    :func:`new_temp_file`: another process's ``bomgraph run --out OUT/results.csv``
    writing now, which compare's folder lock does not cover; a writer killed holds nothing).
    Removed under the lock, so a writer that takes its lock after finds its file gone and
    makes another. Whether it was removed: not when it is gone, or no longer the file locked
    (its writer put it in place and let it go since it was listed: that is no leftover, h83),
    nor where there is no ``flock`` (no writer's file can be told from a dead one's, h83)."""
    try:
        import fcntl
    except ImportError:
        return False
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0)
                     | getattr(os, "O_NONBLOCK", 0))
    except FileNotFoundError:  # renamed into place, or removed, since it was listed
        return False
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return False
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            _log.debug("left %s: a writer is still writing it", path)
            return False
        try:  # the name may have been let go since it was opened (put in place: renamed)
            if not os.path.samestat(os.fstat(fd), os.stat(path, follow_symlinks=False)):
                return False
            os.unlink(path)
        except FileNotFoundError:
            return False
        return True
    finally:
        os.close(fd)


def _have_flock() -> bool:
    """Whether writers here hold claims (``fcntl.flock``; not on Windows)."""
    try:
        import fcntl
    except ImportError:
        return False
    return hasattr(fcntl, "flock")


def remove_leftovers(folder: str, names: Iterable[str], keep: str | None = None) -> int:
    """Remove the temporary files of ``names`` (:data:`TEMP_NAME`) in ``folder`` that no
    writer holds (:func:`remove_unclaimed`): the ones writers killed while writing left.
    Only regular files directly in ``folder`` so named (never a link, a folder or a device),
    never ``keep`` (the caller's own); none where there is no ``flock`` (Windows: a live
    writer's file cannot be told from a dead one's, and removing it lost that writer's output,
    h83). Returns how many were removed; one that cannot be removed is logged and left."""
    wanted = sorted(set(names))
    if not wanted:
        return 0
    return _remove_matching(folder, "|".join(re.escape(n) for n in wanted),
                            tuple(f".{n}." for n in wanted), keep)


def remove_leftovers_like(folder: str, name_pattern: str) -> int:
    """:func:`remove_leftovers` of every name in ``folder`` that the regular expression
    ``name_pattern`` matches whole, in one listing: for a folder of thousands of files one
    writer (the sweep cache) writes many names of, where a listing per file written cost as
    much as the write (10,000 files: 7.7 ms a listing, h83)."""
    return _remove_matching(folder, name_pattern, (".",), None)


def _remove_matching(folder: str, name_pattern: str, prefixes: tuple[str, ...],
                     keep: str | None) -> int:
    if not _have_flock():  # without flock no leftover is told from a live writer's file
        return 0
    pattern = re.compile(TEMP_NAME.format(name=f"(?:{name_pattern})"))
    try:  # the prefixes first: cheap, and a cache folder holds thousands
        with os.scandir(folder) as entries:
            found = [e.path for e in entries if e.name.startswith(prefixes)
                     and pattern.fullmatch(e.name) and e.is_file(follow_symlinks=False)]
    except OSError:  # no such folder (yet): nothing left there
        return 0
    removed = 0
    for path in found:
        if keep is not None and os.path.abspath(path) == os.path.abspath(keep):
            continue
        try:
            removed += remove_unclaimed(path)
        except OSError as exc:
            _log.warning("could not remove %s, left by an interrupted writer: %s", path, exc)
    return removed


__all__ = ["TEMP_NAME", "new_temp_file", "release", "remove_unclaimed", "remove_leftovers",
           "remove_leftovers_like"]
