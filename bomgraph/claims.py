"""The lock a writer holds on its temporary file while it writes it (h77): so that compare,
removing the temporary files killed writers left in its folder
(:meth:`bomgraph.out_folder.OutputRecord.remove_leftovers`), leaves the one another process
(``bomgraph run --out OUT/results.csv``) is writing now. ``flock`` is released when the
writer dies, ``kill -9`` too."""

from __future__ import annotations

import contextlib
import logging
import os
import stat

_log = logging.getLogger(__name__)


def claim(fd: int) -> int | None:
    """A second descriptor of ``fd``'s file holding an exclusive ``flock`` on it until it is
    closed (or the process dies, ``kill -9`` too): a temporary file still being written, which
    ``compare``'s removal of killed writers' temporary files leaves alone (h77). None where
    there is no flock (the file is written all the same)."""
    try:
        import fcntl
    except ImportError:
        return None
    held = os.dup(fd)
    try:
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(held)
        return None
    return held


def release(held: int | None) -> None:
    """Close :func:`claim`'s descriptor: the file is in place, or removed."""
    if held is not None:
        with contextlib.suppress(OSError):
            os.close(held)


def remove_unclaimed(path: str) -> bool:
    """Remove the regular file ``path`` unless a writer still holds it (its lock,
    :func:`claim`: another process's ``bomgraph run --out OUT/results.csv``
    writing now, which compare's folder lock does not cover; a writer killed holds nothing).
    Whether it was removed."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0))
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return False
        try:
            import fcntl
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except ImportError:  # no flock here: writers hold no lock either
            pass
        except BlockingIOError:
            _log.debug("left %s: a writer is still writing it", path)
            return False
        os.unlink(path)  # unless a writer is between its mkstemp and its lock: microseconds
        return True
    finally:
        os.close(fd)


__all__ = ["claim", "release", "remove_unclaimed"]
