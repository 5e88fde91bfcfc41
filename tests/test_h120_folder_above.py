"""h120: a compare into ``x/estimates`` ran beside one into ``x --estimates`` that held ``x``
(both wrote ``x/estimates``): it never looked above its own folder. The other order was
refused (the one into ``x`` locks ``x/estimates`` shared). Now a compare locks shared every
folder above its own that holds a lock file too. The other compare is a lock the test holds."""

from __future__ import annotations

import random

import pytest

import _compare_folder
from bomgraph import out_folder
from bomgraph.cli import main
from bomgraph.stdio import FolderBusyError, folder_lock

stream = _compare_folder.stream   # the fixture
_WHO = "`bomgraph compare`"


def test_a_compare_into_a_folder_below_one_being_written_is_refused(tmp_path, stream,
                                                                    capsys) -> None:
    """Fails before (status 0, results written into ``x/estimates``)."""
    x = tmp_path / "x"
    (x / "estimates").mkdir(parents=True)
    with folder_lock(x, _WHO):   # the compare into x, with --estimates, runs
        assert main(_compare_folder.compare_cmd(stream, x / "estimates", "--no-figures")) == 2
    err = _compare_folder.one_error(capsys)
    assert f"{x}: another {_WHO}" in err and "is writing into this folder" in err, err
    assert not (x / "estimates" / "results.csv").exists()


def test_two_compares_into_two_folders_below_one_still_run_side_by_side(tmp_path, stream,
                                                                         capsys):
    """A shared lock on the folder above (held by another compare into a folder below it)
    refuses nothing: two compares into two subfolders run side by side, as before."""
    x = tmp_path / "x"
    (x / "a").mkdir(parents=True)
    (x / "b").mkdir()
    with folder_lock(x, _WHO):
        pass   # a lock file in x, as an earlier compare into x leaves
    with folder_lock(x / "a", _WHO), folder_lock(x, _WHO, shared=True):  # the one into x/a
        assert main(_compare_folder.compare_cmd(stream, x / "b", "--no-figures")) == 0, \
            capsys.readouterr().err
    assert (x / "b" / "results.csv").is_file()


def test_a_retry_leaves_the_global_random_state_alone(tmp_path):
    """The pause before a retry is drawn from a generator of its own: a library user's
    ``random.seed`` sequence is not moved by a compare that was refused and retried. Fails
    before (the pauses came from ``random``'s global generator)."""
    x = tmp_path / "x"
    (x / "sub").mkdir(parents=True)
    random.seed(7)
    state = random.getstate()
    with folder_lock(x / "sub", _WHO):   # refused below its folder: retried, then refused
        with pytest.raises(FolderBusyError):
            with out_folder.compare_locks(x, [x / "sub" / "a.est"]):
                pass
    assert random.getstate() == state
