"""h111: :func:`bomgraph.command_line_sweep.run_method` called from Python with a bad method
token (an unknown preset, ``NAME@`` without one) or with the preset given twice said
``--method ...`` and ``--option preset=...``, options a library caller never gave. From Python
it now names the function's parameters (``token``, ``options['preset']``); ``bomgraph run``
still names its options (:func:`bomgraph.checks.option_named`, as h101 and h107 did for
compare and the file commands).

The library tests fail before (the messages began ``--method``); the command-line ones pass
before and after: they hold the options' names where they were.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bomgraph.cli import main
from bomgraph.command_line_sweep import run_method
from bomgraph.errors import ConfigError
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream
from bomgraph.sweep import SweepError


@pytest.fixture()
def stream(tmp_path: Path) -> Path:
    path = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=20, n_landmarks=10), np.random.default_rng(1)),
                 path)
    return path


@pytest.mark.parametrize("token, what", [
    ("stmds-cs@fast", "unknown preset 'fast' of stmds-cs"),
    ("stmds-cs@", "'stmds-cs@' is not NAME or NAME@PRESET"),
])
def test_run_method_from_python_names_its_parameter(token: str, what: str) -> None:
    with pytest.raises(SweepError) as info:
        run_method(token, {})
    assert str(info.value).startswith(f"token: {what}")
    assert "--" not in str(info.value)


def test_run_method_from_python_names_both_presets_by_parameter() -> None:
    with pytest.raises(ConfigError) as info:
        run_method("stmds-cs@real", {"preset": "paper"})
    assert str(info.value) == ("token='stmds-cs@real' and options['preset']: give the "
                               "preset once")


@pytest.mark.parametrize("method, what", [
    ("stmds-cs@fast", "--method: unknown preset 'fast' of stmds-cs"),
    ("stmds-cs@", "--method: 'stmds-cs@' is not NAME or NAME@PRESET"),
])
def test_bomgraph_run_still_names_its_option(method: str, what: str, stream: Path,
                                             tmp_path: Path,
                                             capsys: pytest.CaptureFixture) -> None:
    assert main(["run", str(stream), "--method", method, "--out", str(tmp_path / "e")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"bomgraph: error: {what}")
    assert not (tmp_path / "e").exists()


def test_bomgraph_run_names_both_options_of_a_preset_given_twice(
        stream: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["run", str(stream), "--method", "stmds-cs@real", "--option", "preset=paper",
                 "--out", str(tmp_path / "e")]) == 2
    assert capsys.readouterr().err.strip() == (
        "bomgraph: error: --method stmds-cs@real and --option preset=...: give the preset once")
