"""h81: a figure's "not drawn" line named an arm whose runs were only partly scored against
its own map (a --reference's runs on streams without truth, beside its runs on a stream with
truth, which are drawn) as if none of its runs were drawn. Fails before h81's fix: the title
read "not drawn: triangulate (scored against its own map)" above triangulate's curve."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from bomgraph.cli import main
from bomgraph.figures import _results_data
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream


def _stream(path: Path, seed: int, truth: bool) -> str:
    stream = simulate(SimConfig(n_steps=60), np.random.default_rng(seed))
    write_stream(stream if truth else dataclasses.replace(stream, truth=None), path)
    return str(path)


def test_an_arm_scored_against_its_own_map_on_some_runs_is_said_so(tmp_path: Path) -> None:
    streams = [_stream(tmp_path / "nt0.jsonl", 0, False), _stream(tmp_path / "t1.jsonl", 1, True)]
    out = tmp_path / "out"
    assert main(["compare", "--streams", *streams, "--methods", "triangulate,stmds-cs",
                 "--reference", "triangulate", "--jobs", "1", "--no-figures",
                 "--out", str(out)]) == 0
    saved = json.loads((out / "results.json").read_text())
    final, curves, titles = _results_data(saved, out / "results.json", [])
    assert np.isfinite(curves["streams"]["triangulate"][1]).any()  # its t1 run is drawn
    assert "not drawn: triangulate on 1 of 2 runs (scored against its own map)" in titles[
        "streams"], titles
    assert "not drawn: triangulate (" not in titles["streams"]


def test_the_line_names_an_arm_alone_when_none_of_its_runs_is_drawn() -> None:
    from bomgraph.run_scoring import not_drawn_line  # h81's helper

    rows = [{"arm": "a", "self_scored": "itself"}, {"arm": "a", "self_scored": "itself"},
            {"arm": "b", "self_scored": ""}, {"arm": "c", "self_scored": "method"},
            {"arm": "c", "self_scored": ""}]
    assert not_drawn_line(rows) == ("\nnot drawn: a, c on 1 of 2 runs "
                                    "(scored against its own map)")
    assert not_drawn_line(rows[2:3]) == ""
