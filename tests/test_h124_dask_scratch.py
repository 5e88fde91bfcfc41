"""A local Dask cluster's scratch space is bomgraph's own folder, removed as it ends (h124).

Dask's default, ``dask-scratch-space`` in the temporary folder, was left behind by every
``--dask-local`` compare: its lock files after a normal end or Ctrl-C, the workers' lock files
after SIGTERM, the scheduler's and workers' folders after SIGKILL. The cluster now works in
a ``bomgraph-dask-*`` folder with an owner file, removed when the sweep ends; one a compare
ended by SIGKILL left is removed by the next, and nobody else's folder is touched."""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Iterator

import pytest

from bomgraph import owned_folders
from bomgraph.cluster import SCRATCH_PREFIX, dispatch


def _task(k: int, t: str) -> tuple[int, dict]:
    return k, {"ok": True, "t": t}


def _failed(k: int, why: str) -> dict:
    return {"ok": False, "error": why}


@pytest.fixture
def temp_root(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """The temporary folder of this process and of the workers it starts, with Dask's
    ``temporary-directory`` unset (conftest sets it for the other tests), as for a user."""
    import dask.config

    root = tmp_path / "tmp"
    root.mkdir()
    monkeypatch.setenv("TMPDIR", str(root))
    monkeypatch.setattr(tempfile, "tempdir", str(root))
    with dask.config.set({"temporary-directory": None}):
        yield root


def test_a_local_cluster_leaves_nothing_in_the_temporary_folder(temp_root: Path) -> None:
    out = list(dispatch(_task, [0, 1], ["a", "b"], scheduler=None, n_local=1, failed=_failed))
    assert sorted(out) == [(0, {"ok": True, "t": "a"}), (1, {"ok": True, "t": "b"})]
    assert sorted(p.name for p in temp_root.iterdir()) == []


def test_a_sweep_left_early_leaves_nothing_either(temp_root: Path) -> None:
    """Closed after its first result (what Ctrl-C and SIGTERM do to the generator)."""
    runs = dispatch(_task, [0, 1], ["a", "b"], scheduler=None, n_local=1, failed=_failed)
    next(runs)
    assert [p.name[:len(SCRATCH_PREFIX)] for p in temp_root.iterdir()] == [SCRATCH_PREFIX]
    runs.close()
    assert sorted(p.name for p in temp_root.iterdir()) == []


def test_the_folder_of_a_killed_sweep_is_removed_by_the_next_only(temp_root: Path) -> None:
    me = owned_folders.owner()
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    owners = {"dead": {**me, "pid": gone.pid}, "live": me, "no-owner": None}
    for name, owner in owners.items():
        folder = temp_root / f"{SCRATCH_PREFIX}{name}"
        (folder / "dask-scratch-space" / "worker-x").mkdir(parents=True)
        if owner is not None:
            (folder / owned_folders.OWNER).write_text(json.dumps(owner))
    (temp_root / "dask-scratch-space").mkdir()  # another program's Dask: not bomgraph's
    out = list(dispatch(_task, [0], ["a"], scheduler=None, n_local=1, failed=_failed))
    assert out == [(0, {"ok": True, "t": "a"})]
    assert sorted(p.name for p in temp_root.iterdir()) == [
        "bomgraph-dask-live", "bomgraph-dask-no-owner", "dask-scratch-space"]
