"""Review of h74 (``bomgraph run --out``: the header put in the room kept for it, the rest of
the stream checked from where a failed run stopped), by h76.

- A checkpoint is due at t and the line after it is bad: the run reads that line (one step
  ahead) and the reader refuses it, then the run takes the checkpoint of t all the same; if
  the method fails there, the exception is the method's, with the stream's error only as its
  context. Since h74 the rest of the stream was checked from the reader, which had already
  raised: nothing more to read, so the method's error (exit 1) was reported, not the bad line
  (exit 2) as before h74 and as when the stream was checked before the run.
"""

from __future__ import annotations

import json
import os
import random
import textwrap
from pathlib import Path
from typing import Iterator

import pytest

from bomgraph import estimate_writer
from bomgraph.cli import main

from _run_once import simulated
from _runtime_method import runtime_method


@pytest.fixture(scope="module")
def stream(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return simulated(tmp_path_factory, 40, 8)


_FAILING = textwrap.dedent('''
    import numpy as np
    from bomgraph.mapper import MapEstimate

    class FailingEstimate:
        def __init__(self, header, **options):
            self.t = -1

        def step(self, step):
            self.t = step.t

        def estimate(self):
            if self.t == 10:
                raise RuntimeError("h76 fails estimating at t = 10")
            return MapEstimate(np.zeros(0, int), np.zeros((0, 2)))
''')


@pytest.fixture
def failing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    for _ in runtime_method(tmp_path, monkeypatch, "h76-failing", "h76failing", _FAILING,
                            "FailingEstimate", "fails estimating at t = 10"):
        yield "h76-failing"


def _bad_at(stream: Path, t: int, tmp_path: Path) -> Path:
    lines = stream.read_text().splitlines(keepends=True)
    step = json.loads(lines[1 + t])
    step["odom"][2] = "x"
    lines[1 + t] = json.dumps(step) + "\n"
    bad = tmp_path / "bad.jsonl"
    bad.write_text("".join(lines))
    return bad


@pytest.mark.parametrize("bad_t", [11, 12, 30])
def test_a_bad_line_read_before_the_method_failed_is_what_is_refused(
        stream: Path, tmp_path: Path, failing: str, bad_t: int,
        capsys: pytest.CaptureFixture) -> None:
    """Fails before h76 for bad_t = 11 (the line read ahead of the due checkpoint at t = 10,
    whose estimate fails): "method h76-failing failed ..." and exit 1 in place of the bad
    line (exit 2; 0b32e97, before h71, gave exit 2 too). 12 and 30 passed already."""
    bad = _bad_at(stream, bad_t, tmp_path)
    est = tmp_path / "e.est"
    assert main(["run", str(bad), "--method", failing, "--out", str(est)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{bad}, line {bad_t + 2}" in err[0], err
    assert "h76 fails" not in err[0]
    assert not est.exists() and not [p for p in os.listdir(tmp_path) if "partial" in p]


def test_the_method_error_stands_on_a_good_stream(
        stream: Path, tmp_path: Path, failing: str, capsys: pytest.CaptureFixture) -> None:
    est = tmp_path / "e.est"
    assert main(["run", str(stream), "--method", failing, "--out", str(est)]) == 1
    err = capsys.readouterr().err
    assert "h76 fails estimating at t = 10" in err and "Traceback" not in err
    assert not est.exists()


_MIB = 1 << 20


@pytest.mark.parametrize("header_len,room", [(1, 1), (40, 40), (40, 41), (40, 59),
                                             (200, 219), (1, 1 + _MIB)])
@pytest.mark.parametrize("body_len", [0, 1, 18, 19, 20, _MIB - 1, _MIB, _MIB + 1,
                                      2 * _MIB + 19, 3 * _MIB - 7])
def test_put_header_over_sizes(tmp_path: Path, header_len: int, room: int,
                               body_len: int) -> None:
    """The move back of the checkpoints (h74) at the boundaries: a body smaller than, equal
    to and larger than the gap, around multiples of the 1 MiB chunk; random bytes, and
    nothing stale left at the end."""
    rng = random.Random(body_len * 7919 + room)
    header = bytes(rng.randrange(256) for _ in range(header_len - 1)) + b"\n"
    body = rng.randbytes(body_len)
    path = tmp_path / "f"
    path.write_bytes(b" " * room + body)
    fd = os.open(path, os.O_RDWR)
    try:
        estimate_writer._put_header(fd, header, room)
        assert os.lseek(fd, 0, os.SEEK_CUR) == header_len + body_len
    finally:
        os.close(fd)
    assert path.read_bytes() == header + body
