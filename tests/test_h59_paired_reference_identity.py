"""h59: the paired table leaves out a run scored against its own arm's map (h58), judged by
label alone. A sweep may give the reference a label that is an arm's, with other options
(``reference = "stmds-cs"`` and ``[[methods]] name = "stmds-cs", options = {...}``): that arm
is scored against a different run's map, a real score, and its pairs were dropped."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from bomgraph.bench import Executor
from bomgraph.experiments import compare_experiments
from bomgraph.report import compare
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream


def test_a_reference_of_the_same_label_but_other_options_keeps_its_pairs(
        tmp_path: Path) -> None:
    stream = simulate(SimConfig(n_steps=60), np.random.default_rng(3))
    write_stream(dataclasses.replace(stream, truth=None), tmp_path / "notruth.jsonl")
    (tmp_path / "sweep.toml").write_text(
        'streams = ["notruth.jsonl"]\nreference = "stmds-cs"\n'
        '[[methods]]\nname = "triangulate"\n'
        '[[methods]]\nname = "stmds-cs"\noptions = { max_range_factor = 1.3 }\n')
    exps, _ = compare_experiments(config=str(tmp_path / "sweep.toml"))
    result = compare(exps, tmp_path / "out", executor=Executor("serial"), figures=False)
    mpe = {r["arm"]: r["checkpoints"][-1]["mpe_m"] for r in result.results}
    assert mpe["stmds-cs"] > 1e-9, mpe     # not its own map: a real error
    (row,) = result.paired
    assert row.reference == "stmds-cs" and row.arm == "triangulate"
    assert (row.n_pairs, row.unscored) == (1, 0), row
