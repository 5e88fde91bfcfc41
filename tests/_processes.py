"""Whether a process of the machine still runs, for tests that end processes."""

from __future__ import annotations


def alive(pid: int) -> bool:
    """``pid`` runs (it exists and is not a zombie waiting to be reaped)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False
