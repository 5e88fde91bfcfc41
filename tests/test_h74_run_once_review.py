"""Review of h71 (``bomgraph run --out`` reads the stream once), by h74.

- A failure that is not the stream's (the method's, the output's) made ``run`` read and check
  the whole stream file again from its first line, so that a bad line later in it is still the
  error reported: the lines the run had read were read twice (all of them when the output
  failed at the end, a disk full at the copy of the checkpoints), and the file was opened
  again, so a stream removed or replaced since gave its error instead of the method's. Now the
  same reader goes on from where the run stopped.
- The checkpoints waited in a second temporary file and were copied after the header at the
  end: the estimate took twice its size on the disk for a moment. Now they wait in the
  target's own temporary file, after room kept for the header, moved back in place at the end.
"""

from __future__ import annotations

import errno
import json
import os
import re
import textwrap
from pathlib import Path
from typing import Iterator

import pytest

from bomgraph import estimate_writer
from bomgraph.cli import main
from bomgraph.estimate_file import write_estimate
from bomgraph.mapper import create_mapper, run
from bomgraph.stream_file import read_stream
from bomgraph.stream_identity import stream_identity

from _run_once import counted_parses, simulated
from _runtime_method import runtime_method


@pytest.fixture(scope="module")
def stream(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return simulated(tmp_path_factory, 80, 12)


_parses = counted_parses


_FAILING = textwrap.dedent('''
    import os

    import numpy as np
    from bomgraph.mapper import MapEstimate

    class Failing:
        def __init__(self, header, **options):
            pass

        def step(self, step):
            if step.t == 3:
                gone = os.environ.get("H74_REMOVE")
                if gone:  # the stream file removed (or replaced) while the run reads it
                    os.remove(gone)
                raise RuntimeError("h74 fails at t = 3")

        def estimate(self):
            return MapEstimate(np.zeros(0, int), np.zeros((0, 2)))
''')


@pytest.fixture
def failing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    for _ in runtime_method(tmp_path, monkeypatch, "h74-failing", "h74failing", _FAILING,
                            "Failing", "fails at t = 3"):
        yield "h74-failing"


def test_a_method_failure_on_a_good_stream_reads_each_line_once(
        stream: Path, tmp_path: Path, failing: str, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture) -> None:
    """Fails before h74: 85 parses of the 81 step lines (the 4 the run had read, read again)."""
    parses = _parses(monkeypatch)
    est = tmp_path / "e.est"
    assert main(["run", str(stream), "--method", failing, "--out", str(est)]) == 1
    assert len(parses) == 81
    err = capsys.readouterr().err
    assert "h74 fails at t = 3" in err and "Traceback" not in err
    assert not est.exists() and not [p for p in os.listdir(tmp_path) if "partial" in p]


def test_the_method_error_stands_when_the_stream_file_is_gone(
        stream: Path, tmp_path: Path, failing: str, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture) -> None:
    """Fails before h74: "cannot open: No such file or directory" (exit 2) in place of the
    method's own error; the run's open reader has the rest of the stream all the same."""
    copy = tmp_path / "s.jsonl"
    copy.write_bytes(stream.read_bytes())
    monkeypatch.setenv("H74_REMOVE", str(copy))
    est = tmp_path / "e.est"
    assert main(["run", str(copy), "--method", failing, "--out", str(est)]) == 1
    err = capsys.readouterr().err
    assert "h74 fails at t = 3" in err and "cannot open" not in err, err
    assert not copy.exists() and not est.exists()


def test_a_failure_at_the_end_is_one_line_and_the_stream_is_not_read_again(
        stream: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture) -> None:
    """The disk full when the estimate is flushed to it at the end: one line, exit 2,
    nothing left behind and the previous estimate kept. Fails before h74: the stream, read
    to its end by the run, was read again (162 parses) before the error was reported."""
    def full(fd: int) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    out = tmp_path / "out"
    out.mkdir()
    est = out / "e.est"
    est.write_text("the previous estimate\n")
    parses = _parses(monkeypatch)
    monkeypatch.setattr(os, "fsync", full)
    assert main(["run", str(stream), "--method", "triangulate", "--out", str(est)]) == 2
    monkeypatch.undo()
    assert len(parses) == 81
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(est) in err[0] and "No space left" in err[0], err
    assert est.read_text() == "the previous estimate\n"
    assert os.listdir(out) == ["e.est"]


def test_the_estimate_takes_no_second_file(stream: Path, tmp_path: Path,
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    """Fails before h74: the checkpoints went to a second (unnamed) file beside the target
    and were copied after the header at the end, so the estimate took twice its size on the
    disk (a 1.29 MB estimate on a 2 MB tmpfs: 'No space left on device', where it fitted
    before h71). Now they wait in the target's own temporary file, after room for the header.
    The bytes are those of the estimate written with the stream's identity known first."""
    def refused(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    est = tmp_path / "e.est"
    with monkeypatch.context() as m:
        m.setattr(estimate_writer.tempfile, "TemporaryFile", refused)
        assert main(["run", str(stream), "--method", "triangulate", "--out", str(est),
                     "--checkpoint-every", "7"]) == 0
    s = read_stream(stream)
    given = tmp_path / "given.est"
    write_estimate(run(create_mapper("triangulate", s.header), s.steps, checkpoint_every=7,
                       method="triangulate"), given, stream=stream_identity(s.steps),
                   checkpoint_every=7)

    def without_timings(path: Path) -> list[str]:
        lines = path.read_text().splitlines()
        assert lines[-1].startswith('{"timing_s"')
        return [re.sub(r',"estimate_s":[^,}]+', "", line) for line in lines[:-1]]

    assert without_timings(est) == without_timings(given)
    assert sorted(os.listdir(tmp_path)) == ["e.est", "given.est"]


@pytest.mark.parametrize("room", [0, 5, 300])
def test_the_header_is_put_in_its_room_and_the_rest_moved_back(tmp_path: Path,
                                                               room: int) -> None:
    header = b'{"format":"x"}\n'
    body = bytes(range(256)) * (10_000 + 7)  # more than two chunks of 1 MiB
    path = tmp_path / "f"
    path.write_bytes(b" " * (len(header) + room) + body)
    fd = os.open(path, os.O_RDWR)
    try:
        estimate_writer._put_header(fd, header, len(header) + room)
    finally:
        os.close(fd)
    assert path.read_bytes() == header + body
    with pytest.raises(RuntimeError, match="more than the 3 kept"):
        estimate_writer._put_header(0, header, 3)


def test_a_bad_line_after_the_failure_is_still_what_is_refused(
        stream: Path, tmp_path: Path, failing: str, capsys: pytest.CaptureFixture) -> None:
    lines = stream.read_text().splitlines(keepends=True)
    last = json.loads(lines[-1])
    last["odom"][2] = "x"
    lines[-1] = json.dumps(last) + "\n"
    bad = tmp_path / "bad.jsonl"
    bad.write_text("".join(lines))
    assert main(["run", str(bad), "--method", failing, "--out", str(tmp_path / "e.est")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{bad}, line 82" in err[0] and "h74 fails" not in err[0], err


def test_an_interrupt_while_the_checkpoints_move_back_leaves_the_previous_file(
        stream: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C in finish() (the header written, the checkpoints half moved): nothing left
    beside the target, which is as it was, and the stream is not read again (81 parses: a
    KeyboardInterrupt is no failure of the method's to check the stream for)."""
    from bomgraph.file_run import run_file

    write_all, calls = estimate_writer._write_all, []

    def interrupted(fd: int, data: bytes) -> None:
        calls.append(len(data))
        if len(calls) == 2:  # the header went, then the first piece of the checkpoints
            raise KeyboardInterrupt
        write_all(fd, data)

    est = tmp_path / "e.est"
    est.write_text("the previous estimate\n")
    parses = _parses(monkeypatch)
    monkeypatch.setattr(estimate_writer, "_write_all", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_file(stream, "triangulate", out=est)
    assert len(calls) == 2 and len(parses) == 81
    assert est.read_text() == "the previous estimate\n"
    assert os.listdir(tmp_path) == ["e.est"]
