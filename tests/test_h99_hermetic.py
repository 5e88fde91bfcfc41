"""h99: the suite and bomgraph independent of the machine's state and of a second suite run
beside this one (``.ci/run`` runs the 3.11 and 3.13 suites side by side on one machine).

* ``--dask-local`` (and the library's ``Executor("dask", dask_local=N)``) started the local
  scheduler's HTTP server on port 8787: while anything else held it (the other suite's
  cluster, a notebook's) each run warned "UserWarning: Port 8787 is already in use" on the
  command line (``bomgraph: WARNING: ...node.py:195: UserWarning``), and under ``-W error``
  the cluster did not start. Fails before.
* The Hypothesis example database was the working folder's ``.hypothesis/`` (the checkout's,
  shared by both suites, replaying one run's examples in the next); it is off
  (``tests/conftest.py``). Fails before.
* Dask's scratch (``dask-scratch-space``) went to ``$TMPDIR``; it is in the session's folder.
* A compare written once into a folder this user cannot write (``/``, as on this machine in
  stop 43) refused every later compare through a link below it: the shared lock above could
  not create its file. Fails before.
"""

from __future__ import annotations

import contextlib
import os
import socket
import warnings
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest

from bomgraph.bench import Executor, execute
from bomgraph.cli import main
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.out_folder import MANIFEST
from bomgraph.sim import SimConfig, simulate
from bomgraph.stdio import folder_lock
from bomgraph.stream_file import write_stream

from _not_writable import not_writable  # tests/_not_writable.py


@contextlib.contextmanager
def _port_8787_in_use() -> Iterator[None]:
    """Port 8787 of this host held for the block: by this test, or already by someone else
    (bind refused), which is the same situation for the cluster started in the block."""
    sock = socket.socket()
    try:
        try:
            sock.bind(("127.0.0.1", 8787))
            sock.listen(1)
        except OSError:  # in use already
            pass
        yield
    finally:
        sock.close()


def test_a_local_dask_cluster_beside_another_on_port_8787_warns_nothing(tmp_path: Path) -> None:
    s = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=20, n_landmarks=8), np.random.default_rng(2)), s)
    exp = Experiment("e", "e", (Arm("tri", "triangulate"),), sources=(FileSource(str(s)),))
    with _port_8787_in_use(), warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        (out,) = execute(exp.tasks(), Executor("dask", dask_local=1))
    assert out["ok"], out.get("error")
    assert [str(w.message) for w in caught if "8787" in str(w.message)] == []


def test_no_hypothesis_example_database_in_the_working_folder() -> None:
    from hypothesis import settings

    assert settings().database is None
    assert settings(max_examples=3, deadline=None).database is None  # as the tests say it


def test_hypothesis_writes_nothing_in_the_working_folder() -> None:
    """Its ``constants`` and ``unicode_data`` caches went to the working folder's
    ``.hypothesis/`` (the checkout's) whatever the database setting, from the collection on."""
    from hypothesis.configuration import storage_directory

    where = storage_directory("constants", intent_to_write=False).path
    assert where.parent == Path(os.environ["HYPOTHESIS_STORAGE_DIRECTORY"]), where
    assert Path.cwd() not in where.parents, where
    assert where.parent.name.startswith("bomgraph-tests-hypothesis-"), where


def test_dask_scratch_is_in_the_session_folder(tmp_path_factory: pytest.TempPathFactory
                                                ) -> None:
    import dask.config

    scratch = Path(dask.config.get("temporary-directory"))
    assert scratch.is_dir() and tmp_path_factory.getbasetemp() in scratch.parents, scratch
    assert os.environ["DASK_TEMPORARY_DIRECTORY"] == str(scratch)  # for the processes started


def _compare_through_a_link(top: Path) -> list[str]:
    """``compare`` into ``top/sub/out``, its estimates a link to ``top/sub/big``, ``top``
    holding another compare's manifest."""
    sub = top / "sub"
    (sub / "out").mkdir(parents=True)
    (sub / "big").mkdir()
    (sub / "out" / "estimates").symlink_to(sub / "big")
    stream = sub / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=20, n_landmarks=8), np.random.default_rng(2)), stream)
    return ["compare", "--streams", str(stream), "--methods", "triangulate", "--jobs", "1",
            "--no-progress", "--no-figures", "--estimates", "-q", "--out", str(sub / "out")]


def test_a_compare_below_an_unwritable_folder_holding_a_manifest_runs(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """A compare once written into ``/`` (or any folder another user owns, or a read-only
    disk) made every later compare through a link below it exit 2 with "[Errno 1] Operation
    not permitted: '.../.bomgraph.lock'" (root, an immutable folder, as here; a user who cannot
    write there gets errno 13, EACCES, from the same open): the shared lock above could not
    create its file. Fails before."""
    top = tmp_path / "top"
    args = _compare_through_a_link(top)
    (top / MANIFEST).write_text('{"format": "bomgraph-compare-files", "version": 3, '
                                '"files": []}\n')
    with not_writable(top):
        assert main(args) == 0, capsys.readouterr().err
    assert (top / "sub" / "big" / "index.csv").is_file()
    assert not (top / ".bomgraph.lock").exists()


def test_an_unwritable_folders_lock_still_keeps_its_compare_out(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """The lock file there (this user cannot write it) is locked shared all the same: while
    a compare writes into that folder, one below it through a link is refused."""
    top = tmp_path / "top"
    args = _compare_through_a_link(top)
    (top / MANIFEST).write_text('{"format": "bomgraph-compare-files", "version": 3, '
                                '"files": []}\n')
    with folder_lock(top, "`bomgraph compare`"), not_writable(top / ".bomgraph.lock", top):
        assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{top}: another `bomgraph compare`" in err[0], err
    with not_writable(top / ".bomgraph.lock", top):  # and once it is done, it runs
        assert main(args) == 0, capsys.readouterr().err
