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
