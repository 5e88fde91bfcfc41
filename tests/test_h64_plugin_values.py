"""The values a method's modules hold in this process, in a serial run's key (h64).

- ``mymethod.set_depth(3.0)`` (``global DEPTH_M; DEPTH_M = d``) between two sweeps: a global
  its own code rebinds was taken for a lazy cache, so the module kept its file's key and the
  result of 1.0 (MPE 0.22 m) was served for code that runs 3.0 (2.13 m).
- A dict, list or set global changed in place (``TABLE["scale"] = 3.0``), or rebound to
  another one (``TABLE = {...}``): compared by identity, or not at all, so again the old
  value's result was served.

Now each global the module's code names (and each data attribute of its classes) that
differs from its value when loaded is in the key by value; a value set back, one rebound to
an equal object, and a cache the run fills itself keep the key (and the workers' key).
"""

from __future__ import annotations

import importlib
import logging
import sys
from pathlib import Path

import numpy as np
import pytest
from _depth_mapper import depth_mapper
from _plugin_site import write

from bomgraph import mapper
from bomgraph.bench import Executor, execute_counted, is_cached
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream

METHOD = depth_mapper(
    "DEPTH_M * TABLE['scale'] * len(ITEMS) * len(FLAGS) * Mine.GAIN[0]", "Mine",
    attrs="GAIN = [1.0]",
).replace("        self.pose, self.seen = np.zeros(3), {}",
          "        self.pose, self.seen = np.zeros(3), {}\n"
          "        _MEMO.setdefault('runs', []).append(1)\n"
          "        global _CALLS\n        _CALLS += 1") + '''
DEPTH_M = 1.0
TABLE = {"scale": 1.0}
ITEMS = [1]
FLAGS = {"a"}
_MEMO = {}
_CALLS = 0

def set_depth(depth):
    global DEPTH_M
    DEPTH_M = depth
'''


@pytest.fixture
def method(plugin_site: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """The method's module, imported by the user first (a notebook), registered at run time,
    and a one-run experiment of it."""
    write(plugin_site / "h64val" / "__init__.py", "")
    write(plugin_site / "h64val" / "m.py", METHOD)
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    module = importlib.import_module("h64val.m")
    mapper.register_method("h64-val", "h64val.m:Mine")
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=40), np.random.default_rng(3)), stream)
    exp = Experiment("e", "e", (Arm("h64-val", "h64-val"),), sources=(FileSource(str(stream)),))
    yield module, exp, tmp_path / "cache"
    sys.modules.pop("h64val.m", None)


def _sweep(exp: Experiment, cache: Path | None) -> tuple[float, int]:
    """The run's final MPE and how many runs came from the cache."""
    (res,), n_cached = execute_counted(exp.tasks(), Executor("serial"), cache_dir=cache)
    assert res["ok"], res.get("error")
    return res["checkpoints"][-1]["mpe_m"], n_cached


CHANGES = {
    "set_depth(3.0)": lambda m: m.set_depth(3.0),
    "DEPTH_M = 3.0 (rebound by its code too)": lambda m: setattr(m, "DEPTH_M", 3.0),
    "TABLE['scale'] = 3.0": lambda m: m.TABLE.__setitem__("scale", 3.0),
    "TABLE = {'scale': 3.0}": lambda m: setattr(m, "TABLE", {"scale": 3.0}),
    "ITEMS.append(1)": lambda m: m.ITEMS.append(1),
    "FLAGS.add('b')": lambda m: m.FLAGS.add("b"),
    "Mine.GAIN[0] = 3.0": lambda m: m.Mine.GAIN.__setitem__(0, 3.0),
}
UNDO = {
    "set_depth(3.0)": lambda m: m.set_depth(1.0),
    "DEPTH_M = 3.0 (rebound by its code too)": lambda m: setattr(m, "DEPTH_M", 1.0),
    "TABLE['scale'] = 3.0": lambda m: m.TABLE.__setitem__("scale", 1.0),
    "TABLE = {'scale': 3.0}": lambda m: setattr(m, "TABLE", {"scale": 1.0}),
    "ITEMS.append(1)": lambda m: m.ITEMS.pop(),
    "FLAGS.add('b')": lambda m: m.FLAGS.discard("b"),
    "Mine.GAIN[0] = 3.0": lambda m: m.Mine.GAIN.__setitem__(0, 1.0),
}


@pytest.mark.parametrize("change", list(CHANGES))
def test_a_value_set_between_two_sweeps_runs_again_and_set_back_is_cached(
        method, change: str) -> None:
    module, exp, cache = method
    first, _ = _sweep(exp, cache)
    CHANGES[change](module)
    second, n_cached = _sweep(exp, cache)
    fresh, _ = _sweep(exp, None)
    assert n_cached == 0 and second == fresh, f"the old value's result was served ({change})"
    assert second != first
    UNDO[change](module)
    again, n_cached = _sweep(exp, cache)
    assert (again, n_cached) == (first, 1)
    assert is_cached(exp.tasks()[0], cache, Executor("processes", n_jobs=2)), \
        "the workers' key (the files') is not the serial key of the file's values"


def test_a_value_set_before_the_first_sweep_is_not_keyed_as_the_files(method) -> None:
    module, exp, cache = method
    module.set_depth(3.0)
    mpe, _ = _sweep(exp, cache)
    assert mpe == _sweep(exp, None)[0]
    # the workers run the file's 1.0: the result of 3.0 is not theirs
    assert not is_cached(exp.tasks()[0], cache, Executor("processes", n_jobs=2))


@pytest.mark.parametrize("rebind", [
    lambda m: setattr(m, "TABLE", {"scale": 1.0}), lambda m: setattr(m, "ITEMS", [1]),
    lambda m: setattr(m, "FLAGS", {"a"}), lambda m: m.set_depth(1.0)],
    ids=["dict", "list", "set", "set_depth(1.0)"])
def test_an_equal_value_or_what_runs_change_themselves_keep_the_key(method, rebind) -> None:
    """The run fills _MEMO in place and counts in _CALLS (the method's own state); the user
    binds an equal value: the next sweep takes the cached result."""
    module, exp, cache = method
    first, _ = _sweep(exp, cache)
    assert module._CALLS == 1 and module._MEMO == {"runs": [1]}
    rebind(module)
    assert _sweep(exp, cache) == (first, 1)
    assert is_cached(exp.tasks()[0], cache, Executor("processes", n_jobs=2))


def test_a_value_that_cannot_be_hashed_is_not_cached_saying_so_once(
        method, caplog: pytest.LogCaptureFixture) -> None:
    module, exp, cache = method
    first, _ = _sweep(exp, cache)
    module.TABLE = {"scale": 1.0, "source": (i for i in range(3))}  # a generator
    with caplog.at_level(logging.WARNING, logger="bomgraph"):
        for _ in range(2):
            assert _sweep(exp, cache) == (first, 0)
    lines = [r.getMessage() for r in caplog.records if "cannot hash" in r.getMessage()]
    assert len(lines) == 2 and "h64val.m.TABLE is" in lines[0], lines
    assert len(list(cache.glob("*.json"))) == 1


def test_a_value_set_here_that_workers_do_not_see_is_said(
        method, caplog: pytest.LogCaptureFixture) -> None:
    """Worker processes import the files: ``set_depth(3.0)`` here is not theirs."""
    from bomgraph.method_code import new_sweep, warn_sourceless

    module, exp, _ = method
    new_sweep()
    with caplog.at_level(logging.WARNING, logger="bomgraph"):
        warn_sourceless(exp.tasks(), disk=True)
        module.set_depth(3.0)
        new_sweep()
        warn_sourceless(exp.tasks(), disk=True)
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 1 and "'h64-val'" in lines[0] and "do not see" in lines[0], lines


def test_workers_key_a_plugin_holding_a_value_that_cannot_be_hashed_as_the_client(
        plugin_site: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        caplog: pytest.LogCaptureFixture) -> None:
    """A worker keyed its run as a run in its process, values included: a global its code
    names that cannot be hashed (a generator, ``gtsam.LevenbergMarquardtParams()``) made its
    key "unhashable" where the client's is the files', and no run was cached ("the workers
    keyed them otherwise"). A worker now keys with the files it runs. Fails before."""
    import os

    from _plugin_dist import write_dist_info

    write(plugin_site / "h64gen" / "__init__.py", "")
    write(plugin_site / "h64gen" / "m.py", depth_mapper("DEPTH_M + 0 * len(str(GEN))", "Mine")
          + "\nDEPTH_M = 1.0\nGEN = (i for i in range(3))\n")
    write_dist_info(plugin_site, "h64gen", {"h64-gen": "h64gen.m:Mine"})
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(plugin_site),
                                                      os.environ.get("PYTHONPATH", "")]))
    from bomgraph import plugins

    plugins.refresh()
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=20), np.random.default_rng(3)), stream)
    exp = Experiment("e", "e", (Arm("h64-gen", "h64-gen"),), sources=(FileSource(str(stream)),))
    counts = []
    with caplog.at_level(logging.WARNING, logger="bomgraph"):
        for _ in range(2):
            (res,), n_cached = execute_counted(exp.tasks(), Executor("processes", n_jobs=2),
                                               cache_dir=tmp_path / "cache")
            assert res["ok"], res.get("error")
            counts.append(n_cached)
    assert counts == [0, 1], [r.getMessage() for r in caplog.records]
