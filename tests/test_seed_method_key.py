"""A plugin run as another method's seed (``hybrid --option seed_method=PLUGIN``) is part of
the task: its code is in the cache key, the workers check it is not stale, and a seed
registered at run time is refused by worker processes (h20: before, editing the seed plugin
left ``compare`` serving the old result from the cache)."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path
from typing import Iterator

import pytest

from bomgraph import mapper, plugins
from bomgraph.bench import Executor, execute, task_key
from bomgraph.errors import ConfigError
from bomgraph.experiments import Arm, Experiment, FileSource, Task
from bomgraph.method_code import method_code

SEED = '''\
"""A seed method for the test."""
from bomgraph.mapper import MapEstimate
import numpy as np


class Seed:
    """the test's seed"""

    def __init__(self, header) -> None:
        pass

    def step(self, step) -> None:
        pass

    def estimate(self) -> MapEstimate:
        return MapEstimate(np.zeros(0, np.int64), np.zeros((0, 2)))  # VERSION
'''


def _task(method: str, options: dict, tmp_path: Path) -> Task:
    stream = tmp_path / "s.jsonl"
    stream.write_text('{"format": "bomgraph-stream", "version": 1, "bearing_sigma_rad": 0.05, '
                      '"odometry_sigma": [0.03, 0.0, 0.05]}\n{"t": 0, "bearings": []}\n')
    exp = Experiment("seeded", "seeded", (Arm("h", method, options),),
                     sources=(FileSource(str(stream)),))
    return exp.tasks()[0]


@pytest.fixture
def seed_plugin(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """The seed package in this test's folder; forgotten after it (the package a test before
    imported from its own folder was the one keyed, and its edit test failed run after the
    other test: h99)."""
    pkg = tmp_path / "h20seedpkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "seed.py").write_text(SEED)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    mapper.register_method("h20-seed", "h20seedpkg.seed:Seed", "a seed")
    try:
        yield pkg / "seed.py"
    finally:
        for name in [m for m in sys.modules if m.split(".")[0] == "h20seedpkg"]:
            del sys.modules[name]
        plugins.refresh()


def test_a_seed_plugin_is_in_the_cache_key_and_an_edit_changes_it(
        seed_plugin: Path, tmp_path: Path) -> None:
    from bomgraph.plugins import source_fingerprint

    task = _task("hybrid", {"seed_method": "h20-seed", "seed_options": {"preset": "x"}},
                 tmp_path)
    before = task_key(task)   # method_info imports the factory (as a plugin's, h48)
    seed_plugin.write_text(SEED.replace("# VERSION", "# VERSION 2"))
    source_fingerprint.cache_clear()
    # this process runs the code it imported until it reloads it; a worker imports the new
    assert task_key(task) == before and task_key(task, disk=True) != before
    importlib.reload(sys.modules["h20seedpkg.seed"])
    source_fingerprint.cache_clear()
    assert task_key(task) == task_key(task, disk=True) != before
    assert task.methods() == ["hybrid", "h20-seed"]
    # a built-in seed, or an option that only ends in "method", adds nothing to the key
    plain = _task("stmds-smacof", {"tri_method": "ba"}, tmp_path)
    assert plain.methods() == ["stmds-smacof"]
    builtin_seed = _task("hybrid", {"seed_method": "ekf"}, tmp_path)
    assert builtin_seed.methods() == ["hybrid", "ekf"]
    assert method_code(builtin_seed) == {} and method_code(task)


def test_a_seed_registered_at_run_time_is_refused_by_workers(
        seed_plugin: Path, tmp_path: Path) -> None:
    task = _task("hybrid", {"seed_method": "h20-seed"}, tmp_path)
    with pytest.raises(ConfigError, match=r"method 'h20-seed' was registered at run time"):
        execute([task], Executor("processes", n_jobs=2))
