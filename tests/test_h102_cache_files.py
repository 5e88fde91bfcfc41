"""The result cache's files and the code in its key (h102's mutation audit: a cached failure
or another task's result read back as this task's, timings of the method's info kept in a
reproducibility check, the bomgraph sources keyed by their names only, a plugin's version
left out of its fingerprint: each passed the cache tests)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from bomgraph import plugins
from bomgraph.result_cache import read_cached, strip_timings, write_cached

KEY = "0123456789abcdef0123"


def _result(**change: object) -> dict:
    r = {"experiment": "e", "arm": "a", "method": "triangulate", "run": "r0", "key": KEY,
         "ok": True, "checkpoints": [{"t": 10, "mpe_m": 0.01, "estimate_s": 0.002}],
         "total_s": 1.5, "step_median_s": 0.01, "info": {"iterations": 3, "solve_s": 0.2},
         "converged": True}
    return {**r, **change}


def test_only_a_successful_result_of_this_key_is_read_back(tmp_path: Path) -> None:
    path = tmp_path / f"{KEY}.json"
    write_cached(path, _result())
    assert read_cached(path) == _result()
    write_cached(path, _result(ok=False, error="ValueError: boom"))
    assert read_cached(path) is None            # a failure runs again
    write_cached(path, _result(key="ffffffffffffffffffff"))
    assert read_cached(path) is None            # another task's result


def test_strip_timings_by_hand() -> None:
    (got,) = strip_timings([_result()])
    assert got == {"experiment": "e", "arm": "a", "method": "triangulate", "run": "r0",
                   "key": KEY, "ok": True, "checkpoints": [{"t": 10, "mpe_m": 0.01}],
                   "info": {"iterations": 3}, "converged": True}


def test_the_code_fingerprint_follows_the_contents_of_the_sources(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    root = tmp_path / "pkg"
    root.mkdir()
    (root / "a.py").write_text("X = 1\n")
    monkeypatch.setattr(plugins, "_code_roots", lambda: [root])
    plugins.code_fingerprint.cache_clear()      # taken once a process: take it again
    try:
        before = plugins.code_fingerprint()
        plugins.code_fingerprint.cache_clear()
        assert plugins.code_fingerprint() == before
        (root / "a.py").write_text("X = 2\n")   # the same name and size, another value
        plugins.code_fingerprint.cache_clear()
        assert plugins.code_fingerprint() != before
    finally:
        monkeypatch.undo()
        plugins.code_fingerprint.cache_clear()  # the real sources' again for later tests


def test_a_plugins_version_is_in_its_fingerprint(tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    pkg = tmp_path / "h102_versioned_plugin"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "m.py").write_text("def make(header):\n    return None\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        one = plugins.disk_fingerprint("h102_versioned_plugin.m:make", "1.0")
        assert one == plugins.disk_fingerprint("h102_versioned_plugin.m:make", "1.0")
        assert one != plugins.disk_fingerprint("h102_versioned_plugin.m:make", "1.1")
    finally:
        for name in [n for n in sys.modules if n.startswith("h102_versioned_plugin")]:
            del sys.modules[name]


def test_the_written_cache_file_is_the_result_as_json(tmp_path: Path) -> None:
    path = tmp_path / f"{KEY}.json"
    write_cached(path, _result())
    assert json.loads(path.read_text()) == _result()


def test_a_name_registered_again_to_another_factory_of_the_package_changes_the_key(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The package's sources are the same; the factory the name runs is not."""
    from bomgraph import mapper
    from bomgraph.bench import task_key
    from bomgraph.experiments import Arm, Task
    from bomgraph.sim import SimConfig, paper_design
    from bomgraph.sources import SimSource

    pkg = tmp_path / "h102_two_factories"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "m.py").write_text("def make_a(header):\n    return None\n\n\n"
                              "def make_b(header):\n    return None\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        mapper.register_method("h102-two", "h102_two_factories.m:make_a", replace=True)
        task = Task("e", Arm("x", "h102-two"), SimSource(paper_design(0)[0], SimConfig()))
        first = task_key(task)
        mapper.register_method("h102-two", "h102_two_factories.m:make_b", replace=True)
        assert task_key(task) != first
    finally:
        mapper._REGISTRY.pop("h102-two", None)
        for name in [n for n in sys.modules if n.startswith("h102_two_factories")]:
            del sys.modules[name]
