"""Review of h79's ``--out`` through a descriptor (h83), run as a user runs it: ``bomgraph``
in a subprocess under a real shell redirect.

* ``/proc/thread-self/fd/1`` and ``/proc/PID/task/TID/fd/1`` name the same descriptor as
  ``/proc/self/fd/1`` but were not recognised: ``>> f`` lost f's content (the file behind
  them was replaced), as ``/dev/stdout`` did before h79.
* ``simulate --out -`` and ``import ... --out -`` wrote a file named ``-`` in the working
  folder (and said ``wrote -`` on stderr), where ``run`` and ``export`` write stdout.
* with stdout closed (``>&-``) every command ended in a traceback (Python has no
  ``sys.stdout`` then), ``simulate --out FILE`` too after writing FILE.
"""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
BOMGRAPH = f"{shlex.quote(sys.executable)} -m bomgraph"
SIMULATE = f"{BOMGRAPH} simulate --steps 8 --landmarks 4"
G2O = ("EDGE_SE2 0 1 1.0 0.0 0.1 100 0 0 100 0 400\n"
       "EDGE_SE2 1 2 1.0 0.0 0.1 100 0 0 100 0 400\n"
       "EDGE_BEARING_SE2_XY 0 10 0.5 1000\nEDGE_BEARING_SE2_XY 1 10 0.3 1000\n"
       "EDGE_BEARING_SE2_XY 2 10 0.2 1000\n")


def _sh(script: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", "-c", script], cwd=cwd, env=ENV, capture_output=True,
                          check=False)


@pytest.mark.parametrize("name", ["/proc/thread-self/fd/1", "/proc/$$/task/$$/fd/1",
                                  "/proc/self/task/$$/fd/1"])
def test_other_names_of_this_process_stdout_append(tmp_path: Path, name: str) -> None:
    """``exec`` makes bomgraph's pid the shell's ``$$``. Fails before h83: f held the stream
    only, ``keep`` lost."""
    done = _sh(f"{SIMULATE} --out plain && echo keep > f && exec {SIMULATE} --out {name} >> f",
               tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "f").read_bytes() == b"keep\n" + (tmp_path / "plain").read_bytes()


def test_simulate_and_import_out_dash_write_stdout(tmp_path: Path) -> None:
    """Fails before h83: stdout empty, a file named ``-`` written."""
    (tmp_path / "in.g2o").write_text(G2O)
    done = _sh(f"{SIMULATE} --out plain && {SIMULATE} --out - > got", tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "got").read_bytes() == (tmp_path / "plain").read_bytes()
    assert b"wrote -" in done.stderr
    done = _sh(f"{BOMGRAPH} import g2o in.g2o --out plain.jsonl && "
               f"{BOMGRAPH} import g2o in.g2o --out - > got.jsonl", tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "got.jsonl").read_bytes() == (tmp_path / "plain.jsonl").read_bytes()
    assert not (tmp_path / "-").exists()


@pytest.mark.parametrize("command", ["simulate", "run", "export"])
def test_a_closed_stdout_is_one_line_never_a_traceback(tmp_path: Path, command: str) -> None:
    """``>&-``: an ``--out`` of stdout is refused in one line (exit 2); any other is written
    (exit 0). Fails before h83: a traceback, exit 1."""
    assert _sh(f"{SIMULATE} --out s.jsonl && {BOMGRAPH} run s.jsonl --method triangulate "
               f"--out e.est", tmp_path).returncode == 0
    cmd = {"simulate": SIMULATE, "run": f"{BOMGRAPH} run s.jsonl --method triangulate",
           "export": f"{BOMGRAPH} export e.est --format csv"}[command]
    for out in ("-", "/dev/stdout"):
        done = _sh(f"{cmd} --out {out} >&-", tmp_path)
        assert done.returncode == 2, done.stderr
        assert done.stderr.count(b"\n") == 1, done.stderr
        assert b"is not open" in done.stderr or b"is closed" in done.stderr, done.stderr
    done = _sh(f"{cmd} --out written >&-", tmp_path)
    assert done.returncode == 0 and done.stderr == b"", done.stderr
    assert (tmp_path / "written").stat().st_size > 0
    assert not (tmp_path / "-").exists()


def test_out_dev_stdout_on_a_socket_is_written(tmp_path: Path) -> None:
    """A service's stdout is often a socket (systemd's journal): this process's descriptor is
    written through a duplicate of it as a file's or a pipe's is. Fails before h83: refused,
    'exists and is neither a regular file, a character device nor a FIFO'; another process's
    socket stays refused (it cannot be opened by name)."""
    import socket

    expected = None
    for out in ("-", "/dev/stdout", "/dev/fd/1"):
        ours, theirs = socket.socketpair()
        with ours, theirs:
            writer = subprocess.Popen(["bash", "-c", f"{SIMULATE} --out {out}"], cwd=tmp_path,
                                      env=ENV, stdout=theirs, stderr=subprocess.PIPE)
            theirs.close()
            got = b""
            while chunk := ours.recv(1 << 16):
                got += chunk
            err = writer.stderr.read()
            writer.stderr.close()
            assert writer.wait() == 0, err
        expected = expected or got
        assert got == expected and got.startswith(b'{"format"'), got[:100]


def test_out_dash_in_process_reaches_a_text_only_stdout(tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """``main([... "--out", "-"])`` from a caller whose ``sys.stdout`` is a text stream
    without ``.buffer`` (``io.StringIO``, a notebook's): the output is written there. Fails
    before h83: ``run`` raised AttributeError ('_io.StringIO' object has no attribute
    'buffer'), ``simulate`` wrote a file named ``-``."""
    import io

    from bomgraph.cli import main

    monkeypatch.chdir(tmp_path)
    assert main(["simulate", "--steps", "8", "--landmarks", "4", "--out", "s.jsonl"]) == 0
    for argv in (["simulate", "--steps", "8", "--landmarks", "4"],
                 ["run", "s.jsonl", "--method", "triangulate"]):
        text = io.StringIO()
        monkeypatch.setattr(sys, "stdout", text)
        assert main([*argv, "--out", "-"]) == 0
        monkeypatch.setattr(sys, "stdout", sys.__stdout__)
        assert text.getvalue().startswith('{"format"'), text.getvalue()[:100]
    assert not (tmp_path / "-").exists()
    assert text.getvalue().startswith('{"format":"bomgraph-estimate"')


def test_a_closed_stderr_never_puts_lines_into_stdout_nor_fails(tmp_path: Path) -> None:
    """``2>&-``: Python has no ``sys.stderr``; a line printed to it went to stdout, into the
    data of ``--out -`` (``simulate --out - > f 2>&-``: f ended with ``wrote -: ...``), and
    ``run``'s progress bar raised AttributeError (exit 1, the traceback shown nowhere). Fails
    before h83; now those lines go nowhere, as asked."""
    done = _sh(f"{SIMULATE} --out plain && {SIMULATE} --out - > got 2>&- && "
               f"{BOMGRAPH} run plain --method triangulate --out - > est 2>&-", tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "got").read_bytes() == (tmp_path / "plain").read_bytes()
    assert (tmp_path / "est").read_bytes().endswith(b"}}\n")
    done = _sh(f"{SIMULATE} --out /no/such/folder/x 2>&-", tmp_path)
    assert done.returncode == 2 and done.stdout == b"", done.stdout
