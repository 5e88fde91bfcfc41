"""h55's review of h52's hostile-input merge (9ecef49): what it still got wrong. Each test
failed before its fix."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from hostile_helpers import ENV, bomgraph, one_error

from bomgraph.errors import StreamFormatError
from bomgraph.estimate_file import read_estimate


# ---- read_regular_file: a FIFO ----------------------------------------------------------------

def test_plot_results_refuses_a_results_file_that_is_a_fifo(tmp_path: Path) -> None:
    """``read_regular_file`` said it refused a FIFO before reading, but opened it first, and
    opening a FIFO for reading waits for a writer: `plot --results` hung (the timeout is a
    watchdog, the assertion the one error line)."""
    (tmp_path / "c").mkdir()
    os.mkfifo(tmp_path / "c" / "results.json")
    one_error(bomgraph("plot", "--results", tmp_path / "c", "--out", tmp_path / "r.png",
                       timeout=60), "results.json", "not a regular file")
    assert not (tmp_path / "r.png").exists()


def test_a_cache_file_that_is_a_fifo_is_a_miss(tmp_path: Path) -> None:
    """`compare` reading a cache entry that is a FIFO hung."""
    path = tmp_path / "0123456789abcdef0123.json"
    os.mkfifo(path)
    code = ("import logging, sys; logging.basicConfig(); "
            "from bomgraph.result_cache import read_cached; "
            "sys.exit(0 if read_cached(__import__('pathlib').Path(sys.argv[1])) is None else 3)")
    proc = subprocess.run([sys.executable, "-c", code, str(path)], env=ENV, timeout=60,
                          capture_output=True)
    assert proc.returncode == 0, proc.stderr.decode()
    assert "ignoring the unreadable cache file" in proc.stderr.decode()
