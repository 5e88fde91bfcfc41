"""h96: a sweep's names were checked for repeats with ``list.count``, quadratic: a sweep
file of 20,000 worlds (0.7 MB) spent 3.7 s in it, and 16 MiB holds about 460,000 (hours).
The comparisons are counted here (no timing): before the fix, n labels took n^2."""

from __future__ import annotations

from pathlib import Path

import pytest

from bomgraph.errors import ConfigError
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.sweep import SweepError, check_unique, named_streams


class _Label(str):
    compared = 0

    def __eq__(self, other: object) -> bool:
        _Label.compared += 1
        return str.__eq__(self, other)

    __hash__ = str.__hash__


def test_repeated_names_are_found_in_linear_time() -> None:
    labels = [_Label(f"w{i}") for i in range(2_000)]
    _Label.compared = 0
    check_unique(labels, "worlds[].name")
    assert _Label.compared < 20_000
    with pytest.raises(SweepError, match=r"worlds\[\]\.name: 'w7' appears twice"):
        check_unique(labels + [_Label("w9"), _Label("w7")], "worlds[].name")


def test_stream_labels_keep_their_names() -> None:
    """named_streams, also counted by list.count before, made the same labels."""
    paths = [f"/d{i % 3}/run{i // 3}.jsonl" for i in range(3_000)] + ["/x/solo.jsonl"]
    named = dict(named_streams(paths))
    assert named["/d0/run5.jsonl"] == "d0-run5" and named["/x/solo.jsonl"] == "solo"
    assert len(set(named.values())) == len(paths)


@pytest.mark.parametrize("paths, kept", [
    (["/x/a.jsonl", "/y/a.jsonl", "/z/x-a.jsonl", "/w/x-a-0.jsonl"], "/w/x-a-0.jsonl"),
    (["/x/a.jsonl", "/y/a.jsonl", "/w/x-a-0.jsonl", "/v/x-a-0-0.jsonl"], "/v/x-a-0-0.jsonl"),
    (["/d/a.jsonl", "/d/a.json", "/e/d-a-1.jsonl", "/f/d-a-0.jsonl", "/g/d-a.jsonl"],
     "/f/d-a-0.jsonl")])
def test_a_numbered_label_is_not_another_files_stem(paths: list[str], kept: str) -> None:
    """Fails before (h101): ``x-a-0.jsonl`` beside ``x/a.jsonl`` and ``y/a.jsonl`` named two
    streams ``x-a-0``, and ``compare --streams`` refused its own labels ("two runs are named
    'x-a-0' ... rename the world or the source"). A stem no other file shares keeps its name."""
    named = dict(named_streams(paths))
    assert len(set(named.values())) == len(paths), named
    assert named[kept] == Path(kept).stem


def test_an_experiments_run_names_are_checked_in_linear_time() -> None:
    """h101: ``Experiment`` checked its runs' names for repeats with ``list.count`` too (a
    glob of 20,000 streams: 3.8 s, 100,000: minutes). Fails before: 4,000,000 comparisons."""
    sources = tuple(FileSource(f"/d/r{i}.jsonl", label=_Label(f"r{i}")) for i in range(2_000))
    arm = (Arm("triangulate", "triangulate"),)
    _Label.compared = 0
    Experiment("e", "e", arm, sources=sources)
    assert _Label.compared < 20_000
    with pytest.raises(ConfigError, match="two runs are named 'r7'"):
        Experiment("e", "e", arm, sources=sources + (FileSource("/x/r7.jsonl"),))
