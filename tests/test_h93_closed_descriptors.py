"""A standard descriptor closed at the start (``<&-``, ``>&-``), which the program holds on
/dev/null since h92, named as an input or output (h93's review of h92), run as a user runs
it: ``bomgraph`` in a subprocess under a real shell redirect."""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BOMGRAPH = f"{shlex.quote(sys.executable)} -m bomgraph"
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
G2O = ("VERTEX_SE2 1 0 0 0\nVERTEX_SE2 2 1 0 0\nVERTEX_XY 100 5 0\nVERTEX_XY 101 0 5\n"
       "EDGE_BEARING_SE2_XY 1 100 0.0 400\nEDGE_BEARING_SE2_XY 1 101 1.5708 400\n"
       "EDGE_SE2 1 2 1 0 0 100 0 0 100 0 1000\nEDGE_BEARING_SE2_XY 2 100 0.0 400\n")


def _sh(script: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["bash", "-c", script], cwd=cwd, env=ENV, capture_output=True,
                          text=True, check=False)


@pytest.fixture(scope="module")
def work(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("closed")
    done = _sh(f"{BOMGRAPH} simulate --steps 10 --landmarks 5 --out s.jsonl && {BOMGRAPH} run "
               f"s.jsonl --method triangulate --out r.est", d)
    assert done.returncode == 0, done.stderr
    (d / "g.g2o").write_text(G2O)
    return d


@pytest.mark.parametrize("command", [
    "run /dev/stdin --method triangulate --out x.est <&-",
    "run /dev/fd/0 --method triangulate --out x.est <&-",
    "run /proc/self/fd/0 --method triangulate --out x.est <&-",
    "run /dev/stdout --method triangulate --out x.est >&-",
    "evaluate r.est /dev/stdin <&-",
    "evaluate /dev/stdin s.jsonl <&-",
    "import g2o /dev/stdin --out x.jsonl <&-",
    "import g2o g.g2o --truth /dev/fd/0 --out x.jsonl <&-",
    "import victoria /dev/stdin --out x.jsonl <&-",
])
def test_a_closed_descriptor_named_as_an_input_is_refused_as_closed(work: Path,
                                                                      command: str) -> None:
    """The name of a descriptor closed at the start was read as the /dev/null held on it: an
    empty input, refused for what it lacked (``empty file; line 1 must be the header``, ``no
    VERTEX_SE2 for pose 2 ...``), where before h92 the name was missing (``No such file``).
    It is refused as the closed descriptor it is now. Fails before h93."""
    done = _sh(f"{BOMGRAPH} {command}", work)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "was closed when bomgraph started" in lines[0], done.stderr
    assert not (work / "x.est").exists() and not (work / "x.jsonl").exists()


@pytest.mark.parametrize("out", ["//dev/fd/1", "//proc/self/fd/1"])
def test_a_closed_stdout_spelled_with_two_leading_slashes_is_refused(work: Path,
                                                                     out: str) -> None:
    """``//dev/fd/1`` is ``/dev/fd/1`` (two leading slashes are kept by ``abspath``, so the
    name was not taken for a descriptor's): under ``>&-`` the output went into the /dev/null
    held on descriptor 1 and the command exited 0 (before h92: refused). Fails before h93."""
    done = _sh(f"{BOMGRAPH} simulate --steps 3 --out {out} >&-", work)
    assert done.returncode == 2, done.stderr
    assert "that descriptor is not open" in done.stderr


def test_a_stdout_appended_to_spelled_with_two_leading_slashes_is_appended_to(
        work: Path) -> None:
    """``--out //dev/fd/1 >> f`` replaced f by the output (written beside it and renamed over
    it, as a file of that name), where ``--out /dev/fd/1 >> f`` appends to f (h79). Fails
    before h93: f lost its first line."""
    (work / "f.txt").write_text("kept\n")
    done = _sh(f"{BOMGRAPH} simulate --steps 3 --out //dev/fd/1 >> f.txt", work)
    assert done.returncode == 0, done.stderr
    text = (work / "f.txt").read_text()
    assert text.startswith("kept\n{\"format\": \"bomgraph-stream\""), text[:80]


def test_main_in_a_process_that_closed_its_sys_stdin(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """``sys.stdin.close()`` in the caller, then :func:`bomgraph.cli.main` with ``-`` as the
    input: ValueError (I/O operation on closed file) came out of main(), a traceback, where
    h92 took a closed ``sys.stdout`` or ``sys.stderr`` for the shell's ``>&-``. A closed
    ``sys.stdin`` is the shell's ``<&-`` now: ``-`` refused in one line, exit 2, and the
    caller's ``sys.stdin`` left as it was. Fails before h93."""
    import io

    from bomgraph.cli import main

    assert main(["simulate", "--steps", "5", "--out", str(tmp_path / "s.jsonl")]) == 0
    text = io.StringIO("")
    text.close()
    with open(tmp_path / "s.jsonl", encoding="utf-8") as binary:  # with a buffer, as stdin
        pass
    for closed in (text, binary):
        monkeypatch.setattr(sys, "stdin", closed)
        capsys.readouterr()
        assert main(["run", "-", "--method", "triangulate", "--out",
                     str(tmp_path / "r.est")]) == 2
        assert sys.stdin is closed
        assert "-: the standard input is closed" in capsys.readouterr().err
        assert main(["evaluate", "-", str(tmp_path / "s.jsonl")]) == 2
        assert "-: the standard input is closed" in capsys.readouterr().err
        assert not (tmp_path / "r.est").exists()


def _ok(k: int, _: object) -> tuple[int, dict]:
    return k, {"ok": True}


def _one_dies(k: int, _: object) -> tuple[int, dict]:
    if k == 1:
        import time

        time.sleep(0.3)  # after task 0's result is out: the worker starts after that
        os._exit(3)
    return k, {"ok": True}


def test_two_dispatches_under_way_with_stdout_closed(monkeypatch: pytest.MonkeyPatch) -> None:
    """Two dispatches under way at once (two ``compare`` calls in two threads of a process
    whose ``sys.stdout`` is None or closed): the one that had put /dev/null on
    ``sys.stdout`` put None back when it ended, while the other one's workers still started
    (one of its workers died: a pool of its own), and loky's flush raised AttributeError out
    of it, h92's fault again (seen with two threads: ``AttributeError("'NoneType' object
    has no attribute 'flush'")``). Here the two are interleaved in one thread. Fails before
    h93."""
    from bomgraph.processes import dispatch

    monkeypatch.setattr(sys, "stdout", None)
    failed = lambda k, why: {"ok": False, "error": why}  # noqa: E731
    first = dispatch(_ok, [0, 1], [None, None], 1, failed)
    out_a = [next(first)]
    second = dispatch(_one_dies, [0, 1], [None, None], 1, failed)
    out_b = [next(second)]
    out_a += list(first)  # ended: the second is still under way
    assert sys.stdout is not None
    out_b += list(second)
    assert sys.stdout is None
    assert sorted((k, r["ok"]) for k, r in out_a) == [(0, True), (1, True)]
    assert sorted((k, r["ok"]) for k, r in out_b) == [(0, True), (1, False)], out_b
