"""h68, a review of h63 (``compare --reference ARM`` with ARM also compared); each test
fails before h68's fix:

* a reference with its own ``checkpoint_every`` (a sweep file's reference table) and an arm
  of its method and options at the sweep's cadence: the arm's error against the
  reference's map is rounding (the same map), and the paired ratios over it came back as
  ~2e15 (before h63 such a run was no pair, as h59 made it);
* a failed run on a stream without truth (its reference failed, or itself) was written
  to final_by_run.csv as ``scored_against`` ``truth``: the runner set "truth" before any
  run and took it off only after a run that went well;
* the reference's own run on a stream where it maps nothing showed as ``reference (0)``
  in the by-run table, not ``no map (0)`` (the other arms there are unscored because of it).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from bomgraph.bench import Executor
from bomgraph.experiments import compare_experiments
from bomgraph.report import compare, final_by_run, format_by_run
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream


def _stream(tmp_path: Path, seed: int, n_steps: int = 60, truth: bool = False) -> str:
    stream = simulate(SimConfig(n_steps=n_steps), np.random.default_rng(seed))
    path = tmp_path / f"{'t' if truth else 'nt'}{seed}.jsonl"
    write_stream(stream if truth else dataclasses.replace(stream, truth=None), path)
    return str(path)


def test_a_reference_at_another_cadence_gives_no_1e15_ratios(tmp_path: Path) -> None:
    paths = [_stream(tmp_path, s) for s in range(2)]
    (tmp_path / "sweep.toml").write_text(
        f"streams = {json.dumps(paths)}\n"
        'reference = { name = "triangulate", checkpoint_every = 5 }\n'
        'methods = ["triangulate", "ekf", "stmds-cs"]\n')
    exps, _ = compare_experiments(config=str(tmp_path / "sweep.toml"))
    result = compare(exps, tmp_path / "out", executor=Executor("serial"), figures=False)
    tri = [r for r in result.results if r["arm"] == "triangulate"]
    assert {r["scored_against"] for r in tri} == {"reference triangulate"}  # another run
    assert all(r["checkpoints"][-1]["mpe_m"] < 1e-9 for r in tri)  # ... of the same map
    ratios = [p.ratio_of_means for p in result.paired if p.ratio_of_means is not None]
    assert all(math.isfinite(x) and x < 1e3 for x in ratios), ratios  # were 2.4e15
    by_arm = {p.arm: p for p in result.paired}
    assert by_arm["stmds-cs"].reference == "ekf" and by_arm["stmds-cs"].n_pairs == 2


def test_a_failed_run_without_truth_is_not_said_scored_against_the_truth(
        tmp_path: Path) -> None:
    paths = [_stream(tmp_path, 0), _stream(tmp_path, 1, truth=True)]
    # oracle reads the truth: as the reference on a stream without it, it fails there
    exps, _ = compare_experiments(streams=paths, methods="triangulate,oracle",
                                  reference="oracle")
    result = compare(exps, tmp_path / "out", executor=Executor("serial"), figures=False)
    got = {(r["arm"], r["run"]): (r["ok"], r.get("scored_against")) for r in result.results}
    assert got[("triangulate", "nt0")] == (False, "reference oracle"), got  # was "truth"
    assert got[("oracle", "nt0")] == (False, "itself (reference oracle)"), got
    assert got[("triangulate", "t1")] == (True, None) and got[("oracle", "t1")] == (True, None)
    with open(tmp_path / "out" / "final_by_run.csv", newline="") as fh:
        rows = {(r["arm"], r["run"]): r["scored_against"] for r in csv.DictReader(fh)}
    assert "truth" not in rows.values(), rows
    assert rows[("triangulate", "nt0")] == "reference oracle"


def test_a_reference_that_maps_nothing_shows_no_map(tmp_path: Path) -> None:
    paths = [_stream(tmp_path, 5, n_steps=4), _stream(tmp_path, 0)]
    exps, _ = compare_experiments(streams=paths, methods="triangulate,stmds-smacof",
                                  reference="stmds-smacof")
    result = compare(exps, tmp_path / "out", executor=Executor("serial"), figures=False)
    ref = {r["run"]: r for r in result.results if r["arm"] == "stmds-smacof"}
    assert ref["nt5"]["ok"] and ref["nt5"]["checkpoints"][-1]["n_mapped"] == 0
    table = format_by_run(final_by_run(result.results))
    line = next(x for x in table.splitlines() if x.startswith("stmds-smacof "))
    n = ref["nt0"]["checkpoints"][-1]["n_mapped"]
    assert line.split()[1:] == ["no", "map", "(0)", "reference", f"({n})"], line
