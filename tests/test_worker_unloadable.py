"""A worker that cannot load (or hash) a plugin the sweep's own process could gives failed
runs saying so, and the sweep goes on: before (h41), the worker's ``task_key`` raised out of
the worker, and for local worker processes out of :func:`bomgraph.bench.execute` as a
traceback (``NameError`` from the plugin's package, ``UnknownMethodError``), losing the
other runs. The plugin here is imported by this process, then broken on disk (an edit that
does not import) or uninstalled, before the fresh workers import it."""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from bomgraph import plugins
from bomgraph.bench import Executor, execute
from bomgraph.errors import UnknownMethodError
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def plugin(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    from _plugin_dist import write_dist_info

    site = tmp_path / "site"
    shutil.copytree(ROOT / "docs" / "examples" / "toy_plugin" / "toy_plugin", site / "h41toy")
    init = site / "h41toy" / "__init__.py"
    init.write_text("from .mapper import FirstSightMapper\n")
    dist = write_dist_info(site, "h41toy", {"h41-toy": "h41toy.mapper:FirstSightMapper"})
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(site),
                                                      os.environ.get("PYTHONPATH", "")]))
    plugins.refresh()
    streams = []
    for seed in range(2):
        streams.append(tmp_path / f"s{seed}.jsonl")
        write_stream(simulate(SimConfig(n_steps=30), np.random.default_rng(seed)), streams[-1])
    exp = Experiment("plug", "plug", (Arm("h41-toy", "h41-toy"),
                                      Arm("triangulate", "triangulate")),
                     sources=tuple(FileSource(str(p)) for p in streams))
    yield init, dist, exp
    for name in ("h41toy.mapper", "h41toy"):
        sys.modules.pop(name, None)
    plugins.refresh()


@pytest.mark.parametrize("how", ["broken", "uninstalled"])
def test_a_plugin_the_workers_cannot_load_is_a_failed_run_with_its_reason(
        plugin, how: str) -> None:
    init, dist, exp = plugin
    first = execute(exp.tasks(), Executor("serial"))  # this process imports the plugin
    assert all(r["ok"] for r in first), [r.get("error") for r in first]
    if how == "broken":
        init.write_text("from .mapper import FirstSightMapper\nundefined_name_h41\n")
        reason = ("UnknownMethodError: cannot read the source of "
                  "'h41toy.mapper:FirstSightMapper': importing it raised NameError: name "
                  "'undefined_name_h41' is not defined, in the process ")
    else:
        shutil.rmtree(dist)
        reason = "UnknownMethodError: unknown method 'h41-toy', in the process "
    res = execute(exp.tasks(), Executor("processes", n_jobs=2))
    ok = {(r["arm"], r["run"]): r["ok"] for r in res}
    assert ok == {("h41-toy", "s0"): False, ("h41-toy", "s1"): False,
                  ("triangulate", "s0"): True, ("triangulate", "s1"): True}
    for r in res:
        if not r["ok"]:
            assert r["error"].startswith(reason), r["error"]
            assert "every worker needs bomgraph and your plugins importable" in r["error"]
            assert "\n" not in r["error"]


def test_a_plugin_package_that_raises_on_import_is_an_unknown_method_error(
        plugin) -> None:
    """In the sweep's own process, a plugin whose package raises while imported (not an
    ImportError) was that exception's traceback out of execute; now one UnknownMethodError
    naming the method's target, as for a plugin that cannot be found."""
    init, _, exp = plugin
    init.write_text("from .mapper import FirstSightMapper\nundefined_name_h41\n")
    with pytest.raises(UnknownMethodError, match="cannot read the source of 'h41toy.mapper:"
                       "FirstSightMapper': importing it raised NameError: name "
                       "'undefined_name_h41' is not defined"):
        execute(exp.tasks(), Executor("serial"))


def test_run_task_outside_a_worker_raises_what_keying_raised(tmp_path: Path) -> None:
    """Outside a worker (``run_task`` called directly, a serial run), a task whose method
    cannot be loaded raised UnknownMethodError, as on main; h41's branch returned a failed run
    saying "every worker needs ... restart the workers", with no worker (h42)."""
    from bomgraph.bench import run_task

    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=20), np.random.default_rng(0)), stream)
    exp = Experiment("e", "e", (Arm("nope", "no-such-method-h42"),),
                     sources=(FileSource(str(stream)),))
    with pytest.raises(UnknownMethodError, match="unknown method 'no-such-method-h42'"):
        run_task(exp.tasks()[0])


def test_a_stream_file_a_worker_cannot_read_is_not_blamed_on_the_plugins(
        tmp_path: Path) -> None:
    """A worker that cannot read a task's stream file (a Dask worker on another machine
    without it; here ``_dispatch`` alone, which does not key the task first) fails the run
    when keying it: h41's branch told to make the plugins importable and restart the
    workers; now it names the file and says the workers read it there (h42)."""
    from bomgraph.bench import _dispatch

    gone = tmp_path / "gone.jsonl"
    exp = Experiment("e", "e", (Arm("tri", "triangulate"),), sources=(FileSource(str(gone)),))
    ((_, res),) = list(_dispatch(exp.tasks(), [0], Executor("processes", n_jobs=2)))
    assert not res["ok"] and "\n" not in res["error"], res
    assert res["error"].startswith(f"StreamFormatError: {gone}: cannot open: No such file"), \
        res["error"]
    assert "in the process " in res["error"] and "every worker reads" in res["error"]
    assert "plugins importable" not in res["error"], res["error"]


class _BrokenKey(FileSource):
    def key(self) -> dict:
        raise TypeError("a bug in a source's key (h42)")


def test_an_unexpected_error_keying_in_a_worker_keeps_its_traceback(tmp_path: Path) -> None:
    """Any other exception keying a task in a worker (a bug) is a failed run with its
    traceback in the result, not blamed on the plugins (h42)."""
    from bomgraph.bench import _indexed

    exp = Experiment("e", "e", (Arm("tri", "triangulate"),),
                     sources=(_BrokenKey(str(tmp_path / "s.jsonl")),))
    _, res = _indexed(0, exp.tasks()[0])
    assert not res["ok"]
    assert res["error"].startswith("TypeError: a bug in a source's key (h42), in the process")
    assert "plugins importable" not in res["error"], res["error"]
    assert "in key\n" in res.get("traceback", ""), res


@pytest.mark.parametrize("jobs", [1, 2])
def test_a_stream_file_removed_during_the_sweep_fails_its_runs_not_the_sweep(
        tmp_path: Path, jobs: int) -> None:
    """A stream file removed while the sweep runs (after the first result): execute keyed
    every finished task again from its file, so the sweep raised StreamFormatError in its own
    process and every run not yet returned was lost (h42 noticed). Now each task is keyed
    once, before any runs; the runs of the removed file that had not read it fail with the
    reason, the others give their maps."""
    streams = []
    for seed in range(4):
        streams.append(tmp_path / f"s{seed}.jsonl")
        write_stream(simulate(SimConfig(n_steps=30), np.random.default_rng(seed)), streams[-1])
    exp = Experiment("e", "e", (Arm("tri", "triangulate"), Arm("cs", "stmds-cs")),
                     sources=tuple(FileSource(str(p)) for p in streams))

    def progress(done: int, total: int) -> None:
        if done >= 1 and streams[2].exists():
            streams[2].unlink()

    out = execute(exp.tasks(), Executor.choose(jobs), cache_dir=tmp_path / "cache",
                  progress=progress)
    assert len(out) == 8
    mine = [r for r in out if r["run"] == "s2"]
    assert all(r["ok"] for r in out if r["run"] != "s2"), [r.get("error") for r in out]
    for r in mine:
        assert r["ok"] or (r["error"].startswith("StreamFormatError: ")
                           and "\n" not in r["error"]), r["error"]
    if jobs == 1:  # in order: s2's runs come after the removal
        assert not any(r["ok"] for r in mine)
