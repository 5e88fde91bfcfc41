"""A usage error of any bomgraph command is one line on stderr and exit 2 (h61: argparse
printed its usage block, four lines for ``run``, before the error)."""

from __future__ import annotations

import argparse
import subprocess
import sys
from typing import Iterator

import pytest

from bomgraph.cli import main
from bomgraph.cli_parser import build_parser


def _parsers() -> Iterator[argparse.ArgumentParser]:
    todo = [build_parser()]
    while todo:
        p = todo.pop()
        yield p
        for action in p._actions:
            if isinstance(action, argparse._SubParsersAction):
                todo.extend(action._name_parser_map.values())


PROGS = sorted(p.prog for p in _parsers())
#: the commands with a required argument (all but compare and methods)
NEEDY = sorted(p.prog for p in _parsers() if any(a.required for a in p._actions))


def test_every_command_is_covered() -> None:
    assert len(PROGS) == 12 and "bomgraph import mrclam" in PROGS and "bomgraph" in PROGS
    assert len(NEEDY) == 10


def _one_line(argv: list[str], prog: str, capsys: pytest.CaptureFixture, *needles: str) -> str:
    with pytest.raises(SystemExit) as stop:  # argparse's exit: main() does not catch it
        main(argv)
    assert stop.value.code == 2
    cap = capsys.readouterr()
    lines = cap.err.splitlines()
    assert len(lines) == 1 and cap.out == "", cap.err
    line = lines[0]
    assert line.startswith(f"{prog}: error: ") and line.endswith(f"; see {prog} --help"), line
    for n in needles:
        assert n in line, line
    return line


@pytest.mark.parametrize("prog", PROGS)
def test_an_unknown_option_is_one_line_naming_the_command(prog: str,
                                                          capsys: pytest.CaptureFixture) -> None:
    """The line names the innermost command (argparse's top parser said ``bomgraph: error:
    unrecognized arguments``), and the option when nothing required is missing first."""
    argv = prog.split()[1:]
    line = _one_line(argv + ["--no-such-option"], prog, capsys)
    assert "--no-such-option" in line or "are required" in line


@pytest.mark.parametrize("prog", NEEDY)
def test_a_missing_argument_is_one_line(prog: str, capsys: pytest.CaptureFixture) -> None:
    _one_line(prog.split()[1:], prog, capsys, "required")


def test_a_bad_value_and_an_invalid_choice(capsys: pytest.CaptureFixture) -> None:
    _one_line(["compare", "--jobs", "0"], "bomgraph compare", capsys, "--jobs")
    _one_line(["evaluate", "a", "b", "--align", "no"], "bomgraph evaluate", capsys, "'no'")
    _one_line(["nope"], "bomgraph", capsys, "invalid choice: 'nope'")
    _one_line(["methods", "--bogus"], "bomgraph methods", capsys, "unrecognized arguments")
    _one_line(["compare", "--progress", "--no-progress"], "bomgraph compare", capsys,
              "not allowed with")


def test_the_value_is_quoted_as_given_and_a_line_break_is_one_space(
        capsys: pytest.CaptureFixture) -> None:
    """Every run of spaces was squeezed to one: ``--jobs '1   2'`` was quoted as '1 2' (h67;
    fails before)."""
    _one_line(["compare", "--jobs", "1   2"], "bomgraph compare", capsys, "'1   2'")
    line = _one_line(["compare", "--jobs", "1\n2"], "bomgraph compare", capsys)
    assert "'1\\n2'" in line                           # repr(): argparse quotes it so


def test_the_installed_command_too() -> None:
    """The brief's reproduction: ``bomgraph run --bogus`` printed 5 lines."""
    proc = subprocess.run([sys.executable, "-m", "bomgraph", "run", "--bogus"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.splitlines() == [
        "bomgraph run: error: the following arguments are required: stream, --method, --out; "
        "see bomgraph run --help"]



def test_compare_on_an_unreadable_stream_is_one_line(tmp_path, capsys: pytest.CaptureFixture
                                                      ) -> None:
    """A stream with a bad step: compare's one error line (exit 2), not also a warning that
    its map figure could not be drawn (it printed both)."""
    good = tmp_path / "s.jsonl"
    assert main(["simulate", "--steps", "20", "--landmarks", "10", "--out", str(good)]) == 0
    bad = tmp_path / "bad.jsonl"
    bad.write_text(good.read_text().replace('"odom"', '"odum"', 1))
    capsys.readouterr()
    assert main(["compare", "--streams", str(bad), "--methods", "triangulate", "--jobs", "1",
                 "--no-progress", "--out", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'odum'" in err[0] and "error" in err[0], err
