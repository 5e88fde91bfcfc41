"""Fixtures shared by the hostile battery (issue 13)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bomgraph.sim import SimConfig, simulate
from bomgraph.stream import Stream
from bomgraph.stream_file import write_stream


@pytest.fixture(scope="module")
def sim() -> Stream:
    """60 simulated steps of the paper's setup (seed 0)."""
    return simulate(SimConfig(n_steps=60), np.random.default_rng(0))


@pytest.fixture()
def work(tmp_path: Path, sim: Stream) -> Path:
    """A folder holding ``s.jsonl`` (60 simulated steps)."""
    write_stream(sim, tmp_path / "s.jsonl")
    return tmp_path
