"""The result cache key follows every part of a task (h102's mutation audit: the key left
without the checkpoint cadence, the reference arm, the arm's prior fraction, the kept
estimate, a world's seed or a simulated run's design passed the cache tests, which compare
the keys of tasks that differ in their arm or run)."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np
import pytest

from bomgraph.bench import task_key
from bomgraph.experiments import Arm, Task
from bomgraph.sim import SimConfig, paper_design, simulate
from bomgraph.sources import DatasetSource, FileSource, SimSource, WorldSource
from bomgraph.stream_file import write_stream

ARM = Arm("tri", "triangulate", {"min_parallax_rad": 0.05})
SIM = SimConfig(n_steps=20, n_landmarks=8)
BASE = Task("e", ARM, SimSource(paper_design(0)[0], SIM), checkpoint_every=10)


@pytest.mark.parametrize("change", [
    {"experiment": "e"},   # nothing: the same key (below)
    {"arm": dataclasses.replace(ARM, options={"min_parallax_rad": 0.06})},
    {"arm": dataclasses.replace(ARM, method="ekf")},
    {"arm": dataclasses.replace(ARM, prior_fraction=0.2)},
    {"source": SimSource(paper_design(0)[1], SIM)},
    {"source": SimSource(paper_design(0)[0], dataclasses.replace(SIM, n_steps=21))},
    {"source": SimSource(paper_design(0)[0], SIM, prior_fraction=0.2)},
    {"source": SimSource(paper_design(0)[0], SIM, prior_sigma_xy_m=0.05)},
    {"checkpoint_every": 5},
    {"reference": Arm("ekf", "ekf")},
    {"keep_estimate": True},
], ids=lambda c: next(iter(c)) + "-" + str(next(iter(c.values())))[:30])
def test_each_part_of_a_task_is_in_its_key(change: dict) -> None:
    other = dataclasses.replace(BASE, **change)
    if other == BASE:
        assert task_key(other) == task_key(BASE)
    else:
        assert task_key(other) != task_key(BASE)


def test_a_worlds_seed_is_in_the_key() -> None:
    a = dataclasses.replace(BASE, source=WorldSource(SIM, 1))
    b = dataclasses.replace(BASE, source=WorldSource(SIM, 2))
    assert task_key(a) != task_key(b)
    assert task_key(a) == task_key(dataclasses.replace(BASE, source=WorldSource(SIM, 1)))


def test_a_stream_file_is_keyed_by_its_bytes(tmp_path: Path) -> None:
    stream = simulate(SIM, np.random.default_rng(0))
    write_stream(stream, tmp_path / "a.jsonl")
    (tmp_path / "copy.jsonl").write_bytes((tmp_path / "a.jsonl").read_bytes())
    key = task_key(dataclasses.replace(BASE, source=FileSource(str(tmp_path / "a.jsonl"))))
    assert key == task_key(dataclasses.replace(
        BASE, source=FileSource(str(tmp_path / "copy.jsonl"))))
    write_stream(simulate(SIM, np.random.default_rng(1)), tmp_path / "copy.jsonl")
    assert key != task_key(dataclasses.replace(
        BASE, source=FileSource(str(tmp_path / "copy.jsonl"))))


def test_a_recordings_files_are_in_its_key(tmp_path: Path) -> None:
    """A rewritten file of the same size (an edited number; its time stamp moved on, as a
    write moves it) changes the key."""
    path = tmp_path / "run.g2o"
    path.write_text("EDGE_SE2 1 2 0.5 0 0 1 0 0 1 0 1\n")
    key = task_key(dataclasses.replace(BASE, source=DatasetSource("g2o", str(path))))
    st = path.stat()
    path.write_text("EDGE_SE2 1 2 0.6 0 0 1 0 0 1 0 1\n")
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))
    assert key != task_key(dataclasses.replace(BASE, source=DatasetSource("g2o", str(path))))
