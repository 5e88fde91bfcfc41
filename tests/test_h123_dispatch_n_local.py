"""``bomgraph.cluster.dispatch`` refuses a local cluster of no workers (h123).

From Python, ``dispatch(..., scheduler=None, n_local=-3)`` (or 0, 1.5, True) started a
cluster of no worker and waited forever ("no Dask worker left ..."), where the command line
refuses ``--dask-local -3``. It is now one ConfigError line naming ``n_local``, raised at the
call, before any cluster starts (so these tests cannot hang)."""

from __future__ import annotations

import pytest

from bomgraph.cluster import dispatch
from bomgraph.errors import ConfigError


def _task(k: int, t: str) -> tuple[int, dict]:
    return k, {"ok": True}


def _failed(k: int, why: str) -> dict:
    return {"ok": False, "error": why}


@pytest.mark.parametrize("n_local", [-3, 0, 1.5, 2.0, True, None, "2"])
def test_a_local_cluster_needs_an_integer_of_workers(n_local: object) -> None:
    with pytest.raises(ConfigError) as err:
        dispatch(_task, [0], ["a"], scheduler=None, n_local=n_local, failed=_failed)
    assert str(err.value) == f"n_local must be an integer >= 1, got {n_local!r}"


def test_with_a_scheduler_n_local_is_not_used() -> None:
    """bench passes ``n_local=0`` with a scheduler (``dask_local`` unset): not refused at
    the call (the generator is closed unstarted: no address is looked at)."""
    runs = dispatch(_task, [0], ["a"], scheduler="tcp://127.0.0.1:1", n_local=0,
                    failed=_failed)
    runs.close()
