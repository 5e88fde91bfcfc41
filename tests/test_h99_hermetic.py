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
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream


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


def test_dask_scratch_is_in_the_session_folder(tmp_path_factory: pytest.TempPathFactory
                                                ) -> None:
    import dask.config

    scratch = Path(dask.config.get("temporary-directory"))
    assert scratch.is_dir() and tmp_path_factory.getbasetemp() in scratch.parents, scratch
    assert os.environ["DASK_TEMPORARY_DIRECTORY"] == str(scratch)  # for the processes started
