"""``bomgraph run --out`` reads the stream once (h71): it read and validated the whole stream
for its identity (the estimate header's SHA-256 of the steps) and then again for the run, half
the time of a long triangulate run. Now the steps are hashed as the run reads them and the
header is written once they are known; the file, the errors and their precedence are as
before."""

from __future__ import annotations

import json
import os
import textwrap
from pathlib import Path
from typing import Iterator

import pytest

from bomgraph.cli import main
from bomgraph.estimate_file import (EstimateWriter, read_estimate, stream_file_identity,
                                    write_estimate)
from bomgraph.mapper import create_mapper, run
from bomgraph.stream_file import read_stream
from bomgraph.stream_identity import StreamHasher, stream_identity

from _run_once import counted_parses, simulated
from _runtime_method import runtime_method


@pytest.fixture(scope="module")
def stream(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return simulated(tmp_path_factory, 80, 12)


_parses = counted_parses


@pytest.mark.parametrize("every", ["10", "100000"])
def test_run_parses_each_step_line_once(stream: Path, tmp_path: Path, every: str,
                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """Fails before h71: 162 parses of the 81 step lines (the identity's pass, the run's)."""
    parses = _parses(monkeypatch)
    est = tmp_path / "e.est"
    assert main(["run", str(stream), "--method", "triangulate", "--out", str(est),
                 "--checkpoint-every", every, "--json"]) == 0
    assert len(parses) == 81
    monkeypatch.undo()
    got = read_estimate(est)
    assert got.stream == stream_file_identity(stream)
    with open(est, encoding="utf-8") as fh:
        assert json.loads(fh.readline())["checkpoint_every"] == int(every)


def test_a_hashed_header_is_the_header_given_first(stream: Path, tmp_path: Path) -> None:
    """The same bytes whether the writer is given the identity or hashes the steps itself
    (options and cadence in the header too: its keys in the same order)."""
    s = read_stream(stream)
    result = run(create_mapper("triangulate", s.header), s.steps, checkpoint_every=10,
                 method="triangulate")
    given, hashed = tmp_path / "given.est", tmp_path / "hashed.est"
    write_estimate(result, given, stream=stream_identity(s.steps), options={"a": 1},
                   checkpoint_every=10)
    hasher = StreamHasher()
    with EstimateWriter(hashed, "triangulate", stream=hasher, options={"a": 1},
                        checkpoint_every=10) as w:
        for c in result.checkpoints:
            w.add(c)
        for st in s.steps:  # the steps may come while it writes: read at finish()
            hasher.add(st)
        w.finish(result)
    assert hashed.read_bytes() == given.read_bytes()
    assert sorted(os.listdir(tmp_path)) == ["given.est", "hashed.est"]  # no temporary left


def _bad_last_line(stream: Path, tmp_path: Path) -> Path:
    lines = stream.read_text().splitlines(keepends=True)
    last = json.loads(lines[-1])
    last["odom"][2] = "x"
    lines[-1] = json.dumps(last) + "\n"
    bad = tmp_path / "bad.jsonl"
    bad.write_text("".join(lines))
    return bad


def test_a_bad_last_line_is_refused_and_the_previous_estimate_kept(
        stream: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    bad = _bad_last_line(stream, tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    est = out / "e.est"
    est.write_text("the previous estimate\n")
    assert main(["run", str(bad), "--method", "triangulate", "--out", str(est),
                 "--checkpoint-every", "10"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{bad}, line 82" in err[0] and "'odom" in err[0], err
    assert est.read_text() == "the previous estimate\n"
    assert os.listdir(out) == ["e.est"]


_FAILING = textwrap.dedent('''
    import numpy as np
    from bomgraph.mapper import MapEstimate

    class Failing:
        def __init__(self, header, **options):
            pass

        def step(self, step):
            if step.t == 3:
                raise RuntimeError("h71 fails at t = 3")

        def estimate(self):
            return MapEstimate(np.zeros(0, int), np.zeros((0, 2)))
''')


@pytest.fixture
def failing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    for _ in runtime_method(tmp_path, monkeypatch, "h71-failing", "h71failing", _FAILING,
                            "Failing", "fails at t = 3"):
        yield "h71-failing"


def test_a_bad_line_after_a_method_failure_is_still_what_is_refused(
        stream: Path, tmp_path: Path, failing: str, capsys: pytest.CaptureFixture) -> None:
    """The stream was validated before the run: a bad line anywhere came before a method's
    failure (exit 2, not 1), and still does though the run now reads the stream itself."""
    est = tmp_path / "e.est"
    assert main(["run", str(stream), "--method", failing, "--out", str(est)]) == 1
    assert "h71 fails at t = 3" in capsys.readouterr().err
    bad = _bad_last_line(stream, tmp_path)
    assert main(["run", str(bad), "--method", failing, "--out", str(est)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{bad}, line 82" in err[0] and "h71 fails" not in err[0], err
    assert not est.exists() and not [p for p in os.listdir(tmp_path) if "partial" in p]


def test_compare_hashes_a_stream_once_for_all_its_estimates_and_its_cache_is_hit(
        stream: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture) -> None:
    """compare reads a stream file once for its arms (kept), but hashed its steps again for
    each arm's estimate file: fails before h71 (162 steps hashed for 2 arms of 81 steps).
    The cache keys are not touched: the second compare takes both runs from the cache."""
    hashed: list[int] = []
    add = StreamHasher.add

    def counted(self, step):
        hashed.append(1)
        return add(self, step)

    monkeypatch.setattr(StreamHasher, "add", counted)
    out = tmp_path / "cmp"
    argv = ["compare", "--streams", str(stream), "--methods", "triangulate,stmds-smacof",
            "--jobs", "1", "--no-figures", "--no-progress", "--estimates", "--out", str(out)]
    assert main(argv) == 0
    assert len(hashed) == 81
    monkeypatch.undo()
    files = sorted(out.glob("estimates/*/*/*.est"))
    assert len(files) == 2
    first = [f.read_bytes() for f in files]
    assert all(read_estimate(f).stream == stream_file_identity(stream) for f in files)
    capsys.readouterr()
    assert main(argv) == 0
    assert "(2 from the cache)" in capsys.readouterr().out
    assert [f.read_bytes() for f in files] == first


def test_identity_of_stream_is_stream_identity_kept_while_the_stream_lives(stream: Path) -> None:
    import gc

    from bomgraph import stream_identity as si
    from bomgraph.errors import ConfigError

    s = read_stream(stream)
    assert si.identity_of_stream(s) == stream_identity(s.steps) == stream_file_identity(stream)
    assert si.identity_of_stream(s) is si.identity_of_stream(s)
    key = id(s)
    assert key in si._OF_STREAM
    del s
    gc.collect()
    assert key not in si._OF_STREAM
    with pytest.raises(ConfigError, match="must be a Stream, got tuple"):
        si.identity_of_stream(())
