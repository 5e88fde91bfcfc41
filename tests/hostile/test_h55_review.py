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


# ---- version-1 estimate: the line of a repeated key ------------------------------------------

_V1 = {"format": "bomgraph-estimate", "version": 1, "method": "x",
       "landmarks": [[1, 0.0, 1.0], [2, 3.0, 4.0]], "poses": None,
       "checkpoints": [{"t": 0, "landmarks": [[1, 0, 1]], "poses": None}],
       "timing_s": {"total": 1.0}}


def _refusal(path: Path) -> str:
    with pytest.raises(StreamFormatError) as info:
        read_estimate(path)
    return str(info.value)


def test_a_repeat_inside_a_value_an_outer_repeat_replaced_names_a_real_line(
        tmp_path: Path) -> None:
    """The first repeated key was in an object a later repeat of ``checkpoints`` replaced:
    it was not in the parsed data, so its path was lost and the message said ``line 1: 't'``,
    a key the file's top level does not have; now the repeat that replaced it is named."""
    text = json.dumps(_V1, indent=1).replace('"t": 0,', '"t": 0,\n  "t": 0,').replace(
        '"timing_s"', '"checkpoints": [],\n "timing_s"')
    path = tmp_path / "e.json"
    path.write_text(text)
    lines = text.splitlines()
    want = next(n for n, ln in enumerate(lines, 1) if ln.startswith(' "checkpoints": []'))
    assert f"line {want}: 'checkpoints': appears twice" in _refusal(path)


def test_an_unknown_empty_key_is_named_on_its_line(tmp_path: Path) -> None:
    """The key ``""`` was taken for no key: line 1."""
    text = json.dumps({**_V1, "": 1}, indent=1)
    path = tmp_path / "e.json"
    path.write_text(text)
    want = next(n for n, ln in enumerate(text.splitlines(), 1) if ln.startswith(' "": 1'))
    assert want > 1 and f"line {want}: '': unknown key" in _refusal(path)
