"""``--out /dev/stdout`` (``/dev/fd/N``) with stdout appended to a file (``>> f``): the output
was opened by name, and on Linux opening ``/dev/stdout`` reopens its file truncated and
without the shell's ``O_APPEND``, so f's earlier content was lost (h79). A name of an open
descriptor is now written through a duplicate of it: ``>> f`` appends, ``> f`` gives exactly
the output, a pipe works, a device stays a device. Run as a user runs it: ``bomgraph`` in a
subprocess, under a real shell redirect."""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from _run_once import simulated

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
BOMGRAPH = f"{shlex.quote(sys.executable)} -m bomgraph"


@pytest.fixture(scope="module")
def stream(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return simulated(tmp_path_factory, 12, 6)


def _sh(script: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", "-c", script], cwd=cwd, env=ENV, capture_output=True,
                          text=True, check=False)


def _commands(stream: Path, tmp_path: Path) -> dict[str, str]:
    """Each writer, its ``--out`` left to the caller (the estimate exported is written first)."""
    est = tmp_path / "e.est"
    assert _sh(f"{BOMGRAPH} run {stream} --method triangulate --out {est}",
               tmp_path).returncode == 0
    return {"simulate": f"{BOMGRAPH} simulate --steps 8 --landmarks 4",
            "run": f"{BOMGRAPH} run {stream} --method triangulate",
            "export": f"{BOMGRAPH} export {est} --format csv"}


@pytest.mark.parametrize("command", ["simulate", "run", "export"])
def test_out_dev_stdout_appended_to_a_file_keeps_its_content(
        stream: Path, tmp_path: Path, command: str) -> None:
    """``echo keep > f; bomgraph CMD --out /dev/stdout >> f``: f is ``keep`` then the output.
    Fails before h79: f held the output only (``keep`` truncated away)."""
    cmd = _commands(stream, tmp_path)[command]
    done = _sh(f"{cmd} --out plain", tmp_path)
    assert done.returncode == 0, done.stderr
    expected = (tmp_path / "plain").read_bytes()
    if command == "run":  # the estimate's timings differ between runs: compare its header
        expected = expected.split(b"\n", 1)[0]
    done = _sh(f"echo keep > f && {cmd} --out /dev/stdout >> f && {cmd} --out /dev/fd/3 3>>f"
               f" && ln -sf /dev/stdout out && {cmd} --out out >> f", tmp_path)
    assert done.returncode == 0, done.stderr
    got = (tmp_path / "f").read_bytes()
    assert got.startswith(b"keep\n" + expected), got[:200]
    assert got.count(expected) == 3, got[:200]  # each appended after the one before
    done = _sh(f"echo keep > g && {cmd} --out /dev/stdout > g", tmp_path)  # truncated by the shell
    assert done.returncode == 0, done.stderr
    got = (tmp_path / "g").read_bytes()
    assert got.startswith(expected) and b"keep" not in got
    if command != "run":
        assert got == expected
    done = _sh(f"{cmd} --out /dev/stdout | cat > h", tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "h").read_bytes().startswith(expected)
    assert not [p.name for p in tmp_path.iterdir() if p.name.endswith(".partial")]


def test_a_device_named_directly_is_still_written(stream: Path, tmp_path: Path) -> None:
    """/dev/null and a FIFO named by their own names are opened as before (not descriptors)."""
    done = _sh(f"{BOMGRAPH} simulate --steps 5 --out /dev/null", tmp_path)
    assert done.returncode == 0 and "wrote /dev/null" in done.stdout, done.stderr
    os.mkfifo(tmp_path / "pipe")
    done = _sh(f"cat pipe > got & {BOMGRAPH} simulate --steps 5 --out pipe; wait", tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "got").read_bytes().startswith(b'{"format"')


def test_a_descriptor_that_is_an_input_or_read_only_is_refused(stream: Path,
                                                               tmp_path: Path) -> None:
    """``run s --out /dev/stdout >> s`` appended the estimate to the stream being read (and
    before h79 truncated it); ``--out /dev/stdin`` on a file wrote over the file read. Both are
    refused in one line, the file untouched."""
    own = tmp_path / "s.jsonl"
    own.write_bytes(stream.read_bytes())
    done = _sh(f"{BOMGRAPH} run s.jsonl --method triangulate --out /dev/stdout >> s.jsonl",
               tmp_path)
    assert done.returncode == 2 and "is the input s.jsonl" in done.stderr, done.stderr
    assert own.read_bytes() == stream.read_bytes()
    done = _sh(f"{BOMGRAPH} simulate --steps 5 --out /dev/stdin < s.jsonl", tmp_path)
    assert done.returncode == 2 and "open for reading only" in done.stderr, done.stderr
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr
    assert own.read_bytes() == stream.read_bytes()
