"""The lazy package keeps its submodules as attributes, and a signal ignored when the command
started stays ignored (a background job of a non-interactive shell ignores SIGINT)."""

import signal
import subprocess
import sys

import pytest

from bomgraph import cli


def test_submodules_are_attributes_of_the_package():
    # a fresh interpreter: in this one other tests have imported the submodules already
    code = ("import bomgraph; bomgraph.mapper.register_method; "
            "bomgraph.stream_file.read_stream; import pickle; "
            "assert not hasattr(bomgraph, 'no_such_module')")
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_an_ignored_signal_stays_ignored_during_the_command(monkeypatch, signum):
    seen = {}

    def command(args):
        seen["handler"] = signal.getsignal(signum)
        return 0

    monkeypatch.setitem(cli._COMMANDS, "cmd_methods", command)
    previous = signal.signal(signum, signal.SIG_IGN)
    hook = sys.unraisablehook
    try:
        assert cli.main(["methods"]) == 0
        assert signal.getsignal(signum) is signal.SIG_IGN
    finally:
        signal.signal(signum, previous)
    assert seen["handler"] is signal.SIG_IGN
    assert sys.unraisablehook is hook


def test_main_without_argv_in_process_restores_the_callers_handlers(monkeypatch):
    """``main()`` as a test or notebook calls it (argv from ``sys.argv``) left SIGINT and
    SIGTERM ignored and its unraisable hook in place: the caller's Ctrl-C stopped working.
    Only :func:`bomgraph.cli.program` (the installed command) leaves them ignored."""
    monkeypatch.setitem(cli._COMMANDS, "cmd_methods", lambda args: 0)
    monkeypatch.setattr(sys, "argv", ["bomgraph", "methods"])
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    hook = sys.unraisablehook
    assert cli.main() == 0
    assert {s: signal.getsignal(s) for s in before} == before
    assert sys.unraisablehook is hook


def test_the_installed_command_is_program():
    """The console script and ``python -m bomgraph`` run :func:`bomgraph.cli.program`."""
    import tomllib
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    scripts = tomllib.loads((root / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts["bomgraph"] == "bomgraph.cli:program"
    assert "sys.exit(program())" in (root / "bomgraph" / "__main__.py").read_text()
