"""Folders bomgraph makes in the temporary folder for one process's while (a dispatch's run
marks, a local Dask cluster's scratch space), each with an :data:`OWNER` file naming that
process, so that one left by a process ended by SIGKILL (or a power cut) is removed by a later
one (:func:`remove_stale`), and nobody else's is touched. Imports nothing from bomgraph.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import shutil
import socket
import stat
import tempfile
from typing import Any, Iterator

_log = logging.getLogger(__name__)

#: the file in such a folder naming the process that made it
OWNER = "owner.json"


@contextlib.contextmanager
def owned_folder(prefix: str, root: str | None = None) -> Iterator[str]:
    """A new folder ``PREFIX*`` in ``root`` (made if missing; default: the temporary folder)
    for the block, with its :data:`OWNER` file; removed with all in it when the block ends
    (also on an exception: Ctrl-C, SIGTERM made one). The stale folders of this ``prefix``
    there are removed first (:func:`remove_stale`)."""
    if root is not None:
        root = os.path.abspath(root)
        os.makedirs(root, exist_ok=True)
    remove_stale(prefix, root)
    with tempfile.TemporaryDirectory(prefix=prefix, dir=root,
                                     ignore_cleanup_errors=True) as path:
        with open(os.path.join(path, OWNER), "w", encoding="utf-8") as fh:
            json.dump(owner(), fh)
        yield path


def owner() -> dict[str, Any]:
    """This process, as an :data:`OWNER` file names it: its pid, and the host, kernel boot
    and pid namespace in which that pid means this process (the namespace's link alone is the
    same on every machine for its first processes, ``pid:[4026531836]``: the boot id tells two
    machines of one name apart)."""
    try:
        namespace: str | None = os.readlink("/proc/self/ns/pid")
        with open("/proc/sys/kernel/random/boot_id", encoding="ascii") as fh:
            boot: str | None = fh.read().strip() or None
    except OSError:  # not Linux: no namespace to compare, no folder is ever removed
        namespace = boot = None
    return {"pid": os.getpid(), "host": socket.gethostname(), "pid_ns": namespace,
            "boot_id": boot}


def remove_stale(prefix: str, root: str | None = None) -> None:
    """Remove the folders ``PREFIX*`` in ``root`` (default: the temporary folder) that a
    process ended by SIGKILL
    (or a power cut) left: only those of this user whose :data:`OWNER` file names a process
    of this host, kernel boot and pid namespace that is no longer there. A folder without
    that file (being made, or made by an older bomgraph), of another user, host, machine of
    the same name or container, or of a live process (or of a pid taken again since) is left
    alone."""
    me = owner()
    uid = getattr(os, "getuid", lambda: None)()
    root = tempfile.gettempdir() if root is None else root
    if me["pid_ns"] is None or me["boot_id"] is None or uid is None:
        return
    try:
        names = [n for n in os.listdir(root) if n.startswith(prefix)]
    except OSError:
        return
    for name in names:
        path = os.path.join(root, name)
        try:
            st = os.stat(path, follow_symlinks=False)
            if st.st_uid != uid or not stat.S_ISDIR(st.st_mode):
                continue
            with open(os.path.join(path, OWNER), encoding="utf-8") as fh:
                made_by = json.load(fh)
        except (OSError, ValueError):
            continue
        pid = made_by.get("pid") if isinstance(made_by, dict) else None
        if (type(pid) is int and pid > 0 and made_by.get("host") == me["host"]
                and made_by.get("pid_ns") == me["pid_ns"]
                and made_by.get("boot_id") == me["boot_id"] and not alive(pid)):
            shutil.rmtree(path, ignore_errors=True)
            _log.debug("removed %s, left by process %d, which is gone", path, pid)


def alive(pid: int) -> bool:
    """Whether a process ``pid`` exists (another user's too; a zombie too)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # PermissionError: it exists, another user's
        return True
    return True


__all__ = ["OWNER", "alive", "owned_folder", "owner", "remove_stale"]
