"""A user's pass over the README (helper h46): an estimate file given with a stream it was not
computed from is refused by every command that reads the two together, not only by
``evaluate`` and ``export`` (``test_cli_hostile.py``, item 19). Same harness as the battery."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from hostile_helpers import bomgraph, one_error

from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream


def _estimate_of_another_stream(work: Path) -> Path:
    other = work / "other.jsonl"
    write_stream(simulate(SimConfig(n_steps=60), np.random.default_rng(1)), other)
    est = work / "other.est"
    assert bomgraph("run", other, "--method", "triangulate", "--out", est).returncode == 0
    return est


def test_plot_refuses_an_estimate_of_another_stream(work: Path) -> None:
    """It drew the map of one run over the truth of another, with a made-up MPE in the
    title, and exited 0."""
    est = _estimate_of_another_stream(work)
    out = work / "x.png"
    one_error(bomgraph("plot", est, work / "s.jsonl", "--out", out), "another stream",
              str(est), "s.jsonl")
    assert not out.exists()


def test_evaluate_refuses_a_reference_of_another_stream(work: Path) -> None:
    """The estimate was checked against the stream, the ``--reference`` estimate was not: it
    scored one run's map against another run's."""
    mine = work / "mine.est"
    assert bomgraph("run", work / "s.jsonl", "--method", "triangulate", "--out",
                    mine).returncode == 0
    ref = _estimate_of_another_stream(work)
    one_error(bomgraph("evaluate", mine, work / "s.jsonl", "--reference", ref),
              "another stream", str(ref), "s.jsonl")


def test_export_truth_of_a_stream_without_truth_names_the_file(work: Path) -> None:
    """``export --truth`` of a recording without truth said "the stream has no truth to
    export", naming no file."""
    lines = (work / "s.jsonl").read_text().splitlines()
    header = json.loads(lines[0])
    del header["truth"]
    bare = work / "bare.jsonl"
    bare.write_text("\n".join([json.dumps(header)] + lines[1:]) + "\n")
    one_error(bomgraph("export", "--truth", bare, "--format", "tum", "--out", work / "t.tum"),
              str(bare), "line 1", "truth")
    assert not (work / "t.tum").exists()
