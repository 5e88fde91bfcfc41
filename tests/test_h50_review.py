"""h50's review of the lead's last commits (NAME@PRESET, plugins.load's record, the turn no
longer refused by importers): what it found, each test failing before."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest


def test_a_g2o_turn_beyond_a_full_turn_is_imported_when_its_edges_differ(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """Importers were to stop refusing a turn beyond 2 pi (g2o wraps angles: an EDGE_SE2 of 7
    rad is a valid file), but the turn was still judged against the step's own sigma: a g2o
    file whose edges' information differ (each step has its own ``odom_sigma``, as in most
    real files) was refused as before. The reader still warns of the turn."""
    from bomgraph.datasets.g2o import import_g2o
    from bomgraph.stream_file import read_stream, write_stream

    g2o = tmp_path / "turn.g2o"
    g2o.write_text("EDGE_SE2 0 1 1.0 0.0 7.0 100 0 0 100 0 400\n"
                   "EDGE_SE2 1 2 1.0 0.0 0.1 50 0 0 50 0 200\n"
                   "EDGE_BEARING_SE2_XY 0 10 0.5 1000\n"
                   "EDGE_BEARING_SE2_XY 1 10 0.3 1000\n"
                   "EDGE_BEARING_SE2_XY 2 10 0.2 1000\n")
    stream = import_g2o(g2o)                        # refused: "step 1 turns 7 rad"
    assert stream.steps[1].odom_sigma is not None and stream.steps[1].odom[2] == 7.0
    write_stream(stream, tmp_path / "s.jsonl")
    with caplog.at_level(logging.WARNING, logger="bomgraph"):
        read_stream(tmp_path / "s.jsonl")
    assert "turns 7 rad" in caplog.text
