"""A folder or file this process cannot write, for the tests of what bomgraph refuses there
(moved here from tests/test_h99_hermetic.py by h112, which needs it too)."""

from __future__ import annotations

import contextlib
import os
import subprocess
from pathlib import Path
from typing import Iterator

import pytest


@contextlib.contextmanager
def not_writable(*paths: Path) -> Iterator[None]:
    """``paths`` made unwritable for this process for the block: mode 0o555 / 0o444, and for
    root (whom modes do not stop) the immutable attribute (``chattr +i``)."""
    if os.geteuid() != 0:
        for p in paths:
            p.chmod(0o555 if p.is_dir() else 0o444)
        try:
            yield
        finally:
            for p in paths:
                p.chmod(0o755 if p.is_dir() else 0o644)
        return
    made = [p for p in paths
            if subprocess.run(["chattr", "+i", str(p)], capture_output=True).returncode == 0]
    try:
        if len(made) < len(paths):
            pytest.skip("root needs chattr +i (e2fsprogs, a file system that has it) to make "
                        "a folder unwritable")
        yield
    finally:
        for p in made:
            subprocess.run(["chattr", "-i", str(p)], check=True)
