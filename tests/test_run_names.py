"""Two runs of one experiment may not share a name: the name keys the run's estimate file
(``compare --estimates``), its column in the tables and its map figure. A stream file
``w-seed0.jsonl`` beside a world ``w`` ran both, and the second estimate overwrote the first
while ``estimates/index.csv`` paired both streams with the one file (h20)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bomgraph.cli import main
from bomgraph.errors import ConfigError
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.sim import SimConfig, simulate
from bomgraph.sources import World
from bomgraph.stream_file import write_stream

SWEEP = """\
streams = ["w-seed0.jsonl"]
[[worlds]]
name = "w"
n_steps = 20
seeds = 1
[[methods]]
name = "triangulate"
"""


def test_a_sweep_whose_stream_is_named_like_a_world_run_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    write_stream(simulate(SimConfig(n_steps=20), np.random.default_rng(5)),
                 tmp_path / "w-seed0.jsonl")
    (tmp_path / "s.toml").write_text(SWEEP)
    out = tmp_path / "out"
    assert main(["compare", "--config", str(tmp_path / "s.toml"), "--estimates", "--jobs", "1",
                 "--no-progress", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "s.toml: worlds: world 'w' has a run named 'w-seed0', as is the stream" in err[0]
    assert not (out / "results.json").exists()
    (tmp_path / "s.toml").write_text(SWEEP.replace('name = "w"', 'name = "sim"'))
    assert main(["compare", "--config", str(tmp_path / "s.toml"), "--estimates", "--jobs", "1",
                 "--no-progress", "--no-figures", "--out", str(out)]) == 0
    assert len(list((out / "estimates").rglob("*.est"))) == 2


def test_an_experiment_refuses_two_runs_of_one_name(tmp_path: Path) -> None:
    world = World("w", SimConfig(n_steps=20), (0,))
    with pytest.raises(ConfigError, match=r"two runs are named 'w-seed0'"):
        Experiment("e", "e", (Arm("triangulate", "triangulate"),),
                   sources=(FileSource(str(tmp_path / "x.jsonl"), "w-seed0"),), worlds=(world,))
    Experiment("e", "e", (Arm("triangulate", "triangulate"),),
               sources=(FileSource(str(tmp_path / "x.jsonl"), "x"),), worlds=(world,))


def test_arm_labels_that_make_one_folder_name_keep_their_estimates_apart(
        tmp_path: Path) -> None:
    """``tri (x)`` and ``tri_x`` both made the folder ``tri_x``: one estimate was lost."""
    import csv

    write_stream(simulate(SimConfig(n_steps=20), np.random.default_rng(5)), tmp_path / "s.jsonl")
    (tmp_path / "l.toml").write_text(
        'streams = ["s.jsonl"]\n[[methods]]\nname = "triangulate"\nlabel = "tri (x)"\n'
        '[[methods]]\nname = "stmds-cs"\nlabel = "tri_x"\n')
    out = tmp_path / "out"
    assert main(["compare", "--config", str(tmp_path / "l.toml"), "--estimates", "--jobs", "1",
                 "--no-progress", "--no-figures", "--out", str(out)]) == 0
    with open(out / "estimates" / "index.csv") as f:
        rows = list(csv.DictReader(f))
    files = [out / r["estimate"] for r in rows]
    assert len(set(files)) == 2 and all(f.exists() for f in files)
    method = {"tri (x)": "triangulate", "tri_x": "stmds-cs"}
    for r, f in zip(rows, files):  # each file is its own arm's (the header names its method)
        assert json.loads(f.read_text().splitlines()[0])["method"] == method[r["arm"]]
