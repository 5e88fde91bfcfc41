"""Test-session setup: single-threaded BLAS (the toolkit's matrices are small; multithreaded
BLAS on small matrices stalls on a loaded 2-core machine, see bomgraph.bench.run_task)."""

from __future__ import annotations

import pytest
from threadpoolctl import threadpool_limits


@pytest.fixture(autouse=True, scope="session")
def _single_threaded_blas():
    with threadpool_limits(limits=1):
        yield


@pytest.fixture(name="plugin_site")
def _plugin_site(tmp_path, monkeypatch):
    """A folder of plugin packages on ``sys.path`` (``_plugin_site.plugin_site``)."""
    from _plugin_site import plugin_site

    yield from plugin_site(tmp_path, monkeypatch)
