"""h114: :func:`bomgraph.sweep.parse_method` called from Python without ``where`` named a
bad token by a sweep file's key, ``methods: unknown preset 'fast' of stmds-cs``, a key the
caller never wrote; it now names its parameter ``token``, as
:func:`bomgraph.command_line_sweep.run_method` does (h111). Every caller in the package passes
``where`` (the sweep file's key, the command line's option), so their messages do not change:
the sweep-file and command-line ones below pass before and after.

The Python test fails before (the messages began ``methods:``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bomgraph.cli import main
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream
from bomgraph.sweep import SweepError, parse_method, read_sweep


@pytest.mark.parametrize("token, what", [
    ("stmds-cs@fast", "unknown preset 'fast' of stmds-cs"),
    ("stmds-cs@", "'stmds-cs@' is not NAME or NAME@PRESET"),
    ("no-such-method", "unknown method 'no-such-method'"),
])
def test_parse_method_from_python_names_its_parameter(token: str, what: str) -> None:
    with pytest.raises(SweepError) as info:
        parse_method(token)
    assert str(info.value).startswith(f"token: {what}")


def test_parse_method_names_the_place_it_is_given() -> None:
    with pytest.raises(SweepError, match=r"^sweep\.toml: methods\[1\]: unknown preset"):
        parse_method("stmds-cs@fast", "sweep.toml: methods[1]")


def test_a_sweep_file_still_names_its_key(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    path.write_text('[[experiments]]\nname = "e"\nmethods = ["stmds-cs@fast"]\n'
                    '[[experiments.worlds]]\nname = "w"\nseeds = 1\n')
    with pytest.raises(SweepError) as info:
        read_sweep(path)
    assert str(info.value).startswith(f"{path}: experiments[0].methods[0]: unknown preset "
                                      "'fast'")


def test_compare_still_names_its_option(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=20, n_landmarks=10), np.random.default_rng(1)),
                 stream)
    assert main(["compare", "--streams", str(stream), "--methods", "stmds-cs@fast",
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("bomgraph: error: --methods stmds-cs@fast: unknown preset 'fast'")
