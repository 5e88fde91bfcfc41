"""An infinite method option (``--option KEY=inf``) is recorded so that it reads back as the
infinity (h62): it was written as ``null`` in an estimate file's ``options`` (and in
``methods --json``), and refused by ``compare``; now it is the string ``"Infinity"``
(:func:`bomgraph.jsonio.options_to_json`), and different values never share a cache key."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from bomgraph.bench import task_key
from bomgraph.cli import main
from bomgraph.errors import ConfigError
from bomgraph.estimate_file import read_estimate
from bomgraph.experiments import Arm, Experiment
from bomgraph.jsonio import options_from_json, options_to_json
from bomgraph.sources import FileSource


@pytest.fixture(scope="module")
def stream(tmp_path_factory) -> Path:
    s = tmp_path_factory.mktemp("inf") / "s.jsonl"
    assert main(["simulate", "--seed", "2", "--steps", "30", "--landmarks", "10",
                 "--out", str(s)]) == 0
    return s


def test_options_round_trip_with_infinities_at_any_depth() -> None:
    opts = {"k": math.inf, "m": -math.inf, "n": [1.5, math.inf], "t": {"u": -math.inf},
            "s": "inf", "x": 3, "b": True, "none": None}
    text = json.dumps(options_to_json(opts), allow_nan=False)
    assert '"k": "Infinity"' in text and '"m": "-Infinity"' in text
    assert options_from_json(json.loads(text)) == opts
    for spelled in ("Infinity", "-Infinity"):   # would read back as the number: refused
        with pytest.raises(ConfigError, match="read back"):
            options_to_json({"k": [spelled]})


def test_run_records_an_infinite_option_that_reads_back(stream, tmp_path) -> None:
    out = tmp_path / "e.est"
    assert main(["run", str(stream), "--method", "ekf", "--option",
                 "max_bearing_nonlinearity=inf", "--out", str(out)]) == 0
    head = json.loads(out.read_text().splitlines()[0])
    assert head["options"] == {"max_bearing_nonlinearity": "Infinity"}
    assert read_estimate(out).options == {"max_bearing_nonlinearity": math.inf}


def test_methods_json_keeps_an_infinite_default_and_preset(capsys) -> None:
    capsys.readouterr()
    assert main(["methods", "stmds-cs", "--json"]) == 0
    opts = {o["name"]: o for o in json.loads(capsys.readouterr().out)["options"]}
    assert opts["max_relative_range_sigma"]["default"] == "Infinity"
    assert main(["methods", "--json"]) == 0
    ekf = [r for r in json.loads(capsys.readouterr().out) if r["name"] == "ekf"][0]
    assert ekf["presets"]["real"]["max_bearing_nonlinearity"] == "Infinity"


def test_compare_takes_an_infinite_option_and_keys_each_value_apart(stream) -> None:
    keys: dict[str, object] = {}
    for value in (math.inf, -math.inf, 1e308, "inf", [math.inf], [1e308], 3, 3.0):
        arm = Arm("ekf", "ekf", {"max_bearing_nonlinearity": value})
        task = Experiment("x", "x", arms=(arm,), sources=(FileSource(str(stream)),)).tasks()[0]
        key = task_key(task)
        assert key not in keys, (value, keys.get(key))
        keys[key] = value
    assert Arm("ekf", "ekf", {"k": math.inf}).key()["options"] == {"k": "Infinity"}
    with pytest.raises(ConfigError, match="read back"):
        Arm("ekf", "ekf", {"k": "Infinity"})
    with pytest.raises(ConfigError, match="plain JSON"):
        Arm("ekf", "ekf", {"k": math.nan})
