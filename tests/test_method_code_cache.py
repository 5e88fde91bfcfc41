"""The cache key follows the method code that this process runs, in a notebook too.

- A method whose class has no source file (defined in a notebook cell or in ``python -c``) is
  run, never taken from the cache: no key can follow an edit of code that is not in a file.
  Before, its key held only the method's name, so a sweep re-run after an edit of the cell
  silently returned the old code's results.
- A method in a module file, edited and reloaded (``importlib.reload``, IPython's
  autoreload) between two sweeps of one process, is keyed with the new code. Before, the
  process kept the first hash: the second sweep returned the old code's cached result, and
  without the cache failed as a "stale worker".
- Edited and not reloaded, the process still runs the old code: a serial run fails saying
  so, and nothing is cached under the edited file's key."""

from __future__ import annotations

import importlib
import logging
import os
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from _depth_mapper import depth_mapper

from bomgraph import mapper, method_code
from bomgraph.bench import Executor, execute, is_cached, task_key
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream

CELL = depth_mapper("DEPTH", "CellMapper")


@pytest.fixture
def cell_module(monkeypatch: pytest.MonkeyPatch) -> types.ModuleType:
    """A module like a notebook's ``__main__``: code run from a string, no ``__file__``."""
    mod = types.ModuleType("bomgraph_test_cell")
    monkeypatch.setitem(sys.modules, mod.__name__, mod)
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    mapper.register_method("cell-method", f"{mod.__name__}:CellMapper", "defined in a cell")
    return mod


def _run_cell(mod: types.ModuleType, depth_m: float, exp: Experiment, cache: Path) -> dict:
    exec(compile(CELL.replace("DEPTH *", f"{depth_m!r} *"), "<cell>", "exec"), mod.__dict__)
    (res,) = execute(exp.tasks(), Executor("serial"), cache_dir=cache)
    assert res["ok"], res.get("error")
    return res


def test_a_method_without_source_file_is_never_taken_from_the_cache(
        cell_module: types.ModuleType, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=40), np.random.default_rng(3)), stream)
    exp = Experiment("cell", "cell", (Arm("cell-method", "cell-method"),),
                     sources=(FileSource(str(stream)),))
    cache = tmp_path / "cache"
    with caplog.at_level(logging.WARNING, logger="bomgraph"):
        first = _run_cell(cell_module, 1.0, exp, cache)
    assert "not cached" in caplog.text and "'cell-method'" in caplog.text
    assert not any(cache.iterdir()), "a result of code without a source file was cached"
    assert not is_cached(exp.tasks()[0], cache, Executor("serial"))
    edited = _run_cell(cell_module, 3.0, exp, cache)   # the cell edited and run again
    mpe = [r["checkpoints"][-1]["mpe_m"] for r in (first, edited)]
    assert mpe[0] != mpe[1], "the edited cell's run returned the old code's result"
    assert first["key"] == task_key(exp.tasks()[0])    # the key itself is still made
    assert method_code.method_fingerprint("cell-method") == method_code.NO_SOURCE
    assert not method_code.method_has_source("cell-method")


FILE_METHOD = CELL.replace("DEPTH *", "DEPTH_M *") + "\nDEPTH_M = 1.0\n"


@pytest.fixture
def file_method(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[Path, Experiment]:
    """A method in a module file of its own, registered at run time, and a one-run sweep."""
    src = tmp_path / "code" / "bomgraph_test_filemethod.py"
    src.parent.mkdir()
    src.write_text(FILE_METHOD)
    monkeypatch.syspath_prepend(str(src.parent))
    monkeypatch.delitem(sys.modules, src.stem, raising=False)
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    mapper.register_method("file-method", f"{src.stem}:CellMapper", "in a file")
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=40), np.random.default_rng(3)), stream)
    yield src, Experiment("file", "file", (Arm("file-method", "file-method"),),
                          sources=(FileSource(str(stream)),))
    sys.modules.pop(src.stem, None)


def _final_mpe(exp: Experiment, cache: Path | None) -> dict:
    (res,) = execute(exp.tasks(), Executor("serial"), cache_dir=cache)
    return res


def test_an_edited_and_reloaded_module_is_keyed_with_its_new_code(
        file_method: tuple[Path, Experiment], tmp_path: Path) -> None:
    src, exp = file_method
    cache = tmp_path / "cache"
    first = _final_mpe(exp, cache)
    module = importlib.import_module(src.stem)
    src.write_text(FILE_METHOD.replace("DEPTH_M = 1.0", "DEPTH_M = 3.0"))
    importlib.reload(module)
    again = _final_mpe(exp, cache)
    fresh = _final_mpe(exp, None)
    assert first["ok"] and again["ok"] and fresh["ok"], (again.get("error"), fresh.get("error"))
    assert again["key"] != first["key"]
    mpe = [r["checkpoints"][-1]["mpe_m"] for r in (first, again, fresh)]
    assert mpe[1] == mpe[2] != mpe[0], "the reloaded code's sweep returned the old result"
    assert len(list(cache.glob("*.json"))) == 2


def test_an_edit_not_reloaded_fails_the_serial_run_and_caches_nothing_new(
        file_method: tuple[Path, Experiment], tmp_path: Path) -> None:
    src, exp = file_method
    first = _final_mpe(exp, None)
    src.write_text(FILE_METHOD.replace("DEPTH_M = 1.0", "DEPTH_M = 3.0"))  # no reload
    cache = tmp_path / "cache"
    second = _final_mpe(exp, cache)
    assert first["ok"] and not second["ok"]
    assert "was edited since" in second["error"] and "reload the module" in second["error"]
    # a serial run has no workers: it said "stale worker: restart the workers" (h41)
    assert "worker" not in second["error"], second["error"]
    assert "since this process imported it" in second["error"]
    assert list(cache.glob("*.json")) == []


def _module_with(src: Path, text: str) -> types.ModuleType:
    src.write_text(text)
    return importlib.import_module(src.stem)


DICT_METHOD = CELL.replace("DEPTH *", "DEPTH['m'] *") + "\nDEPTH = {'m': 1.0}\n"


@pytest.mark.parametrize("how", ["importlib.reload", "in place"])
def test_a_reload_that_changes_only_a_dict_constant_moves_the_key(
        file_method: tuple[Path, Experiment], tmp_path: Path, how: str) -> None:
    """A dict (list, array, object) constant edited and reloaded: the key was the old code's,
    so the second sweep returned the first's cached result. "in place" is what IPython 9's
    autoreload does by default: it runs the edited assignment again in the loaded module."""
    src, exp = file_method
    module = _module_with(src, DICT_METHOD)
    cache = tmp_path / "cache"
    first = _final_mpe(exp, cache)
    src.write_text(DICT_METHOD.replace("{'m': 1.0}", "{'m': 3.0}"))
    if how == "importlib.reload":
        importlib.reload(module)
    else:
        module.DEPTH = {"m": 3.0}
    again = _final_mpe(exp, cache)
    fresh = _final_mpe(exp, None)
    assert again["ok"] and fresh["ok"], (again.get("error"), fresh.get("error"))
    assert again["key"] != first["key"]
    mpe = [r["checkpoints"][-1]["mpe_m"] for r in (first, again, fresh)]
    assert mpe[1] == mpe[2] != mpe[0], "the reloaded code's sweep returned the old result"


INFO_METHOD = FILE_METHOD.replace(
    "return MapEstimate(ids, np.array([self.seen[i] for i in ids.tolist()]).reshape(-1, 2))",
    "return MapEstimate(ids, np.array([self.seen[i] for i in ids.tolist()]).reshape(-1, 2),\n"
    "                           info={'solver': 'depth along the first bearing'})")


def test_an_edit_not_reloaded_fails_though_the_results_hold_a_constant_of_the_code(
        file_method: tuple[Path, Experiment], tmp_path: Path) -> None:
    """The results kept a string constant of the method's code (its info): the byte code was
    compared through marshal, whose output follows reference counts, so the module looked
    reloaded and the edited file's key was taken for the old code's result, and cached."""
    src, exp = file_method
    _module_with(src, INFO_METHOD)
    first = _final_mpe(exp, None)
    assert first["ok"] and first["info"]["solver"] == "depth along the first bearing"
    src.write_text(INFO_METHOD.replace("DEPTH_M = 1.0", "DEPTH_M = 3.0"))  # no reload
    cache = tmp_path / "cache"
    second = _final_mpe(exp, cache)
    assert not second["ok"] and "was edited since" in second["error"], second.get("error")
    assert list(cache.glob("*.json")) == []


ODD = '''
class _RaisesOnModule:
    def __call__(self):
        pass
    @property
    def __module__(self):
        raise RuntimeError("not configured")


class _LazyProxy:  # as django.conf.settings before it is configured
    @property
    def __class__(self):
        raise LookupError("settings are not configured")


class _GetattrRaises:
    def __call__(self):
        pass
    def __getattr__(self, key):
        raise KeyError(key)


ODD = (_RaisesOnModule(), _LazyProxy(), _GetattrRaises())
A, B, C = ODD
globals()[3] = "a key that is not a string"
'''


def test_odd_module_contents_do_not_stop_the_key(
        file_method: tuple[Path, Experiment], tmp_path: Path) -> None:
    """Objects whose attributes raise (a lazy settings proxy, a ``__module__`` property) and a
    global that is not a string: computing the key read their attributes, or sorted the
    globals, and raised out of the sweep."""
    src, exp = file_method
    module = _module_with(src, FILE_METHOD + ODD)
    first = _final_mpe(exp, tmp_path / "cache")
    assert first["ok"], first.get("error")
    src.write_text(FILE_METHOD.replace("DEPTH_M = 1.0", "DEPTH_M = 3.0") + ODD)
    importlib.reload(module)
    again = _final_mpe(exp, tmp_path / "cache")
    assert again["ok"] and again["key"] != first["key"]


def test_a_plugin_edited_and_reloaded_between_two_sweeps_in_worker_processes(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The default executor's worker processes are kept by joblib from one sweep to the next
    and keep the code they imported: after an edit and a reload (a notebook), every run of
    the next sweep failed as a stale worker. The workers are now ended when a plugin's code
    changed since they ran it, and the sweep gives the serial run's results."""
    from _plugin_dist import write_dist_info

    from bomgraph import plugins

    site = tmp_path / "site"
    (site / "h39plug").mkdir(parents=True)
    (site / "h39plug" / "__init__.py").write_text("")
    src = site / "h39plug" / "mapper.py"
    src.write_text(FILE_METHOD)
    write_dist_info(site, "h39plug", {"h39-plug": "h39plug.mapper:CellMapper"})
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]))
    plugins.refresh()
    streams = []
    for seed in range(2):
        streams.append(tmp_path / f"s{seed}.jsonl")
        write_stream(simulate(SimConfig(n_steps=40), np.random.default_rng(seed)), streams[-1])
    exp = Experiment("plug", "plug", (Arm("h39-plug", "h39-plug"),),
                     sources=tuple(FileSource(str(p)) for p in streams))
    try:
        first = execute(exp.tasks(), Executor("processes", n_jobs=2))
        module = importlib.import_module("h39plug.mapper")
        src.write_text(FILE_METHOD.replace("DEPTH_M = 1.0", "DEPTH_M = 3.0"))
        importlib.reload(module)
        again = execute(exp.tasks(), Executor("processes", n_jobs=2))
        serial = execute(exp.tasks(), Executor("serial"))
    finally:
        for name in ("h39plug.mapper", "h39plug"):
            sys.modules.pop(name, None)
        plugins.refresh()
    assert all(r["ok"] for r in first)
    assert all(r["ok"] for r in again), [r.get("error") for r in again]
    assert [r["key"] for r in again] == [r["key"] for r in serial] != [r["key"] for r in first]
    assert ([r["checkpoints"][-1]["mpe_m"] for r in again]
            == [r["checkpoints"][-1]["mpe_m"] for r in serial])


def test_an_edit_not_reloaded_is_not_served_from_the_cache_of_the_old_code(
        file_method: tuple[Path, Experiment], tmp_path: Path) -> None:
    """The same sweep twice in one process with a cache (a notebook), the module edited and
    not reloaded between: the second sweep keyed the task with the code still loaded, found
    the first sweep's result and returned it, where without that cache entry the run fails
    saying to reload (docs/USAGE.md: "edited and not reloaded, its runs fail saying so")."""
    src, exp = file_method
    cache = tmp_path / "cache"
    first = _final_mpe(exp, cache)
    importlib.import_module(src.stem)
    src.write_text(FILE_METHOD.replace("DEPTH_M = 1.0", "DEPTH_M = 3.0"))  # no reload
    second = _final_mpe(exp, cache)
    assert first["ok"] and not second["ok"], "the old code's cached result was returned"
    assert "was edited since this process imported it" in second["error"], second["error"]
    assert not is_cached(exp.tasks()[0], cache, Executor("serial"))
    assert len(list(cache.glob("*.json"))) == 1


def test_worker_processes_run_the_edited_plugin_though_this_process_holds_the_old(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A plugin imported in the sweeping process (a notebook that used it), then edited and
    not reloaded there: the local workers are restarted and run the code on disk, but the
    tasks were keyed with the code loaded here, so the first sweep's cached results of the
    old code came back (and without the cache, the new results were run and not cached:
    "the workers keyed them otherwise"). Worker runs are keyed with the code on disk."""
    from _plugin_dist import write_dist_info

    from bomgraph import plugins

    site = tmp_path / "site"
    (site / "h46plug").mkdir(parents=True)
    (site / "h46plug" / "__init__.py").write_text("")
    src = site / "h46plug" / "mapper.py"
    src.write_text(FILE_METHOD)
    write_dist_info(site, "h46plug", {"h46-plug": "h46plug.mapper:CellMapper"})
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]))
    plugins.refresh()
    streams = []
    for seed in range(2):
        streams.append(tmp_path / f"s{seed}.jsonl")
        write_stream(simulate(SimConfig(n_steps=40), np.random.default_rng(seed)), streams[-1])
    exp = Experiment("plug", "plug", (Arm("h46-plug", "h46-plug"),),
                     sources=tuple(FileSource(str(p)) for p in streams))
    cache = tmp_path / "cache"
    workers = Executor("processes", n_jobs=2)
    try:
        importlib.import_module("h46plug.mapper")  # used here too, before the edit
        first = execute(exp.tasks(), workers, cache_dir=cache)
        src.write_text(FILE_METHOD.replace("DEPTH_M = 1.0", "DEPTH_M = 3.0"))  # no reload
        again = execute(exp.tasks(), workers, cache_dir=cache)
        cached = is_cached(exp.tasks()[0], cache, workers)
        uncached = execute(exp.tasks(), workers)
    finally:
        for name in ("h46plug.mapper", "h46plug"):
            sys.modules.pop(name, None)
        plugins.refresh()
    assert all(r["ok"] for r in first + again + uncached), [r.get("error") for r in again]
    mpe = [[r["checkpoints"][-1]["mpe_m"] for r in rs] for rs in (first, again, uncached)]
    assert mpe[1] == mpe[2] != mpe[0], "the old code's cached results were returned"
    assert [r["key"] for r in again] == [r["key"] for r in uncached]
    assert cached and len(list(cache.glob("*.json"))) == 4  # both codes' results kept
