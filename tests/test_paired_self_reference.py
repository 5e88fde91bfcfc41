"""h58: on a stream without truth, ``compare --reference ARM`` scores every arm against ARM's
final map, ARM's own run included (its error against itself: ~1e-16 m). The paired table
then defaulted to that arm as its reference and divided by that rounding noise: a user saw
``ratio 3864142503369924.50`` for the others. A run scored against itself is no score for the
paired comparison."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from bomgraph.bench import Executor
from bomgraph.experiments import compare_experiments
from bomgraph.report import compare
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream


def test_an_arm_scored_against_itself_is_no_pair(tmp_path: Path) -> None:
    stream = simulate(SimConfig(n_steps=60), np.random.default_rng(3))
    path = tmp_path / "notruth.jsonl"
    write_stream(dataclasses.replace(stream, truth=None), path)
    exps, _ = compare_experiments(streams=[str(path)], methods="triangulate,stmds-cs",
                                  reference="triangulate")
    result = compare(exps, tmp_path / "out", executor=Executor("serial"), figures=False)
    assert {r["arm"]: r["scored_against"] for r in result.results} == {  # h63: "itself"
        "triangulate": "itself (reference triangulate)", "stmds-cs": "reference triangulate"}
    (row,) = result.paired
    assert row.reference == "triangulate" and row.arm == "stmds-cs"
    # the reference arm's only run was scored against itself: nothing to pair with
    assert (row.n_pairs, row.unscored) == (0, 1), row
    assert row.ratio_of_means is None and row.ratio_median is None, row
    assert "no run scored by both" in row.note
    assert "triangulate is the --reference, scored against its own map on 1 of 1" in row.note
    # its own final map is still reported as it was scored (for the by-run table)
    ref_run = next(r for r in result.results if r["arm"] == "triangulate")
    assert math.isfinite(ref_run["checkpoints"][-1]["mpe_m"])
