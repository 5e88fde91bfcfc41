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


def _where(k: int, t: str) -> tuple[int, dict]:
    from distributed import get_worker

    return k, {"dir": get_worker().local_directory}


def test_the_folder_is_in_dasks_temporary_directory_when_one_is_set(temp_root: Path,
                                                                     tmp_path: Path) -> None:
    """Dask's ``temporary-directory`` (``DASK_TEMPORARY_DIRECTORY``: a disk with room, where
    the temporary folder is a small tmpfs) was set aside: the workers' scratch went to the
    temporary folder (h130). It is where the folder goes, and a killed sweep's is removed
    from there."""
    import dask.config

    chosen = tmp_path / "dask-tmp"
    chosen.mkdir()
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    dead = chosen / f"{SCRATCH_PREFIX}dead"
    dead.mkdir()
    (dead / owned_folders.OWNER).write_text(json.dumps({**owned_folders.owner(),
                                                        "pid": gone.pid}))
    with dask.config.set({"temporary-directory": str(chosen)}):
        out = list(dispatch(_where, [0], ["a"], scheduler=None, n_local=1, failed=_failed))
    ((_, res),) = out
    assert Path(res["dir"]).relative_to(chosen).parts[0].startswith(SCRATCH_PREFIX), res
    assert sorted(p.name for p in chosen.iterdir()) == []
    assert sorted(p.name for p in temp_root.iterdir()) == []


def test_a_dask_temporary_directory_that_is_a_file_is_one_line_naming_it(
        temp_root: Path, tmp_path: Path) -> None:
    """Before h124 Dask's "Cluster failed to start: Not a directory" traceback; h124's folder,
    made there, was "[Errno 17] File exists" naming no setting."""
    import dask.config

    from bomgraph.errors import ConfigError

    afile = tmp_path / "afile"
    afile.write_text("")
    with dask.config.set({"temporary-directory": str(afile)}):
        with pytest.raises(ConfigError, match=r"^Dask's temporary-directory /.*afile "
                                              r"\(DASK_TEMPORARY_DIRECTORY"):  # h136: shown_path
            list(dispatch(_task, [0], ["a"], scheduler=None, n_local=1, failed=_failed))
    assert sorted(p.name for p in temp_root.iterdir()) == []
