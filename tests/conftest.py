"""Test-session setup: single-threaded BLAS (the toolkit's matrices are small; multithreaded
BLAS on small matrices stalls on a loaded 2-core machine, see bomgraph.bench.run_task), and
nothing written outside pytest's temporary folders: no Hypothesis example database in the
working folder (a checkout's ``.hypothesis/``, which both CI suites shared and which replayed
one run's examples in the next) and Hypothesis's other files (its ``constants`` and
``unicode_data`` caches, written there too) in a temporary folder of the session, Dask's worker scratch in the session's folder (not
``$TMPDIR/dask-scratch-space``, shared with every other Dask user of the machine), and no
bytecode (``__pycache__``) written by this process or the ones it starts: the tests edit
modules and reload or re-import them within a second, with the size unchanged (``1.0`` ->
``3.0``), where Python takes the old ``.pyc`` for fresh (it compares the source's mtime in
whole seconds and its size) and runs the old code: test_h56_plugin_keys failed so wherever
``PYTHONDONTWRITEBYTECODE`` was not set already."""

from __future__ import annotations

import os
import shutil
import sys
import tempfile

import pytest
from hypothesis import settings
from threadpoolctl import threadpool_limits

# the default of every @settings below it; tests/hostile/test_hypothesis_methods.py's own
# profiles say database=None themselves
settings.register_profile("bomgraph", database=None)
settings.load_profile("bomgraph")

# here, before any test module is imported or makes its environment from os.environ
sys.dont_write_bytecode = True
os.environ["PYTHONDONTWRITEBYTECODE"] = "1"


def pytest_configure(config: pytest.Config) -> None:
    """Hypothesis's storage folder (by default ``.hypothesis`` in the working folder, where it
    writes its caches while the test modules are collected) in a temporary folder of this
    session, removed at its end; the processes the tests start get it too."""
    from hypothesis.configuration import set_hypothesis_home_dir

    home = tempfile.mkdtemp(prefix="bomgraph-tests-hypothesis-")
    config.add_cleanup(lambda: shutil.rmtree(home, ignore_errors=True))
    os.environ["HYPOTHESIS_STORAGE_DIRECTORY"] = home
    set_hypothesis_home_dir(home)


@pytest.fixture(autouse=True, scope="session")
def _single_threaded_blas():
    with threadpool_limits(limits=1):
        yield


@pytest.fixture(autouse=True, scope="session")
def _dask_scratch_in_the_session_folder(tmp_path_factory: pytest.TempPathFactory):
    """Dask's ``temporary-directory`` (its workers' scratch) in this session's folder, for the
    clusters made here and, through the environment, for the processes the tests start."""
    import dask.config

    scratch = str(tmp_path_factory.mktemp("dask-scratch"))
    with pytest.MonkeyPatch.context() as mp, dask.config.set({"temporary-directory": scratch}):
        mp.setenv("DASK_TEMPORARY_DIRECTORY", scratch)
        yield


@pytest.fixture(name="plugin_site")
def _plugin_site(tmp_path, monkeypatch):
    """A folder of plugin packages on ``sys.path`` (``_plugin_site.plugin_site``)."""
    from _plugin_site import plugin_site

    yield from plugin_site(tmp_path, monkeypatch)
