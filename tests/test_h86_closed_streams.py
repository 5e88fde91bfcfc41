"""Review of h83's closed stdout and stderr (h86). The command run in its caller's process
(:func:`bomgraph.cli.main`) whose ``sys.stderr`` is None while descriptor 2 is open (the
caller set it so, as ``pythonw`` does; or its stderr was closed and a file it opened then
took descriptor 2). h83 left ``sys.stderr`` None there, so

* a line printed to it went to stdout: ``simulate --out -`` into an ``io.StringIO`` ended the
  stream with ``wrote -: ...``;
* ``run``'s progress bar raised AttributeError (``None.isatty``): a traceback, exit 1;

and the command run with descriptor 2 closed left ``sys.stderr`` replaced in its caller.
"""

from __future__ import annotations

import io
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from bomgraph.cli import main
from bomgraph.estimate_file import untimed_estimate_text

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
SIMULATE = ["simulate", "--steps", "8", "--landmarks", "4"]


def test_no_line_goes_into_the_data_when_sys_stderr_is_none(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Fails before h86: the text ended with ``wrote -: 9 steps, ...``."""
    assert main([*SIMULATE, "--out", str(tmp_path / "plain")]) == 0
    text = io.StringIO()
    monkeypatch.setattr(sys, "stderr", None)
    monkeypatch.setattr(sys, "stdout", text)
    assert main([*SIMULATE, "--out", "-"]) == 0
    assert sys.stderr is None  # the caller's, as it was
    monkeypatch.undo()
    assert text.getvalue() == (tmp_path / "plain").read_text()


def test_run_with_sys_stderr_none_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Fails before h86: AttributeError: 'NoneType' object has no attribute 'isatty'."""
    stream = tmp_path / "plain"
    assert main([*SIMULATE, "--out", str(stream)]) == 0
    text = io.StringIO()
    monkeypatch.setattr(sys, "stderr", None)
    monkeypatch.setattr(sys, "stdout", text)
    assert main(["run", str(stream), "--method", "triangulate", "--out", "-"]) == 0
    monkeypatch.undo()
    assert text.getvalue().startswith('{"format"') and "landmarks mapped" not in text.getvalue()


def test_main_with_stderr_closed_leaves_its_caller_as_it_was(tmp_path: Path) -> None:
    """``2>&-`` in a program that calls main(): before h86 ``sys.stderr`` was a stream of
    bomgraph's after it, and descriptor 2 on /dev/null."""
    script = textwrap.dedent(f"""
        import os, sys
        from bomgraph.cli import main
        status = main({[*SIMULATE, "--out", str(tmp_path / "x")]!r})
        try:
            os.fstat(2)
            open2 = True
        except OSError:
            open2 = False
        print(status, sys.stderr is None, open2)
        """)
    done = subprocess.run(["bash", "-c", f'"{sys.executable}" -c "$0" 2>&-', script],
                          env=ENV, capture_output=True, text=True, check=False)
    assert done.stdout.splitlines()[-1] == "0 True False", done.stdout + done.stderr


def test_a_broken_pipe_with_stdout_closed_is_no_traceback(tmp_path: Path) -> None:
    """``--out FIFO >&-`` whose reader stops early: a BrokenPipeError, then AttributeError
    (``None.fileno``) in the quiet exit; a traceback, exit 1. Fails before h86."""
    os.mkfifo(tmp_path / "fifo")
    script = (f'(head -c 1 fifo > /dev/null) & "{sys.executable}" -m bomgraph simulate '
              f'--steps 3000 --out fifo >&-; status=$?; wait; exit $status')
    done = subprocess.run(["bash", "-c", script], cwd=tmp_path, env=ENV, capture_output=True,
                          text=True, check=False)
    assert "Traceback" not in done.stderr, done.stderr
    assert done.returncode == 141, done.stderr


def test_main_on_a_broken_stdout_pipe_leaves_no_descriptor(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The quiet exit of a closed pipe put /dev/null on stdout's descriptor and left the
    descriptor it opened for it open: one more a call of main(). Fails before h86."""
    read, write = os.pipe()
    os.close(read)
    with open(write, "w") as broken:
        monkeypatch.setattr(sys, "stdout", broken)
        before = len(os.listdir("/proc/self/fd"))
        assert main(["methods"]) == 141
        assert len(os.listdir("/proc/self/fd")) == before
        monkeypatch.undo()


@pytest.mark.parametrize("argv", [["run", "-", "--method", "triangulate", "--out", "x"],
                                  ["evaluate", "est", "-"]])
def test_a_closed_stdin_is_one_line(tmp_path: Path, argv: list[str]) -> None:
    """``-`` read with stdin closed (``<&-``, Python has no ``sys.stdin``): AttributeError
    (``None.buffer``), a traceback, exit 1, as a closed stdout was before h83. Fails
    before h86."""
    command = " ".join([f'"{sys.executable}" -m bomgraph', *argv])
    done = subprocess.run(["bash", "-c", f"{command} <&-"], cwd=tmp_path, env=ENV,
                          capture_output=True, text=True, check=False)
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and "standard input is closed" in done.stderr, \
        done.stderr


def test_dash_read_from_a_text_only_sys_stdin(tmp_path: Path,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """A caller in this process whose ``sys.stdin`` is a text stream (``io.StringIO``), as
    h83 made ``--out -`` write a text-only ``sys.stdout``: AttributeError before h86."""
    stream = tmp_path / "plain"
    assert main([*SIMULATE, "--out", str(stream)]) == 0
    assert main(["run", str(stream), "--method", "triangulate", "--out",
                 str(tmp_path / "a.json")]) == 0
    monkeypatch.setattr(sys, "stdin", io.StringIO(stream.read_text()))
    assert main(["run", "-", "--method", "triangulate", "--out", str(tmp_path / "b.json")]) == 0
    a, b = (untimed_estimate_text((tmp_path / n).read_text()) for n in ("a.json", "b.json"))
    assert a == b


G2O = ("EDGE_SE2 0 1 1.0 0.0 0.1 100 0 0 100 0 400\n"
       "EDGE_SE2 1 2 1.0 0.0 0.1 100 0 0 100 0 400\n"
       "EDGE_BEARING_SE2_XY 0 10 0.5 1000\nEDGE_BEARING_SE2_XY 1 10 0.3 1000\n"
       "EDGE_BEARING_SE2_XY 2 10 0.2 1000\n")


@pytest.mark.parametrize("command", ["run plain --method triangulate", "import g2o plain",
                                     "export est --stream plain --format tum",
                                     "import mrclam . --robot 1 --no-calibrate"])
def test_out_dash_appended_to_an_input_is_refused(tmp_path: Path, command: str) -> None:
    """``--out - >> INPUT``: refused as ``--out /dev/stdout >> INPUT`` is, before anything is
    computed (export: before it writes). Fails before h86: the input read, then the output
    appended to it (run: the estimate after the stream's lines; import, which h83 made write
    stdout: a stream after the g2o edges; export: its text after the stream's lines; mrclam's
    folder: refused before reading it, as /dev/stdout is, by the input check)."""
    if "mrclam" in command:  # an input folder: a file in it, the other files too small
        (tmp_path / "plain").write_text("# Barcodes\n")
    elif not command.startswith("import"):
        assert main([*SIMULATE, "--out", str(tmp_path / "plain")]) == 0
        assert main(["run", str(tmp_path / "plain"), "--method", "triangulate", "--out",
                     str(tmp_path / "est")]) == 0
    else:
        (tmp_path / "plain").write_text(G2O)
    before = (tmp_path / "plain").read_bytes()
    for out in ("/dev/stdout", "-"):
        done = subprocess.run(["bash", "-c", f'"{sys.executable}" -m bomgraph {command} '
                               f"--out {out} >> plain"], cwd=tmp_path, env=ENV,
                              capture_output=True, text=True, check=False)
        assert done.returncode == 2, (out, done.stderr)
        assert "is the input " in done.stderr and done.stderr.count("\n") == 1, done.stderr
        assert (tmp_path / "plain").read_bytes() == before
