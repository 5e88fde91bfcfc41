"""A sweep of an installed plugin keyed as its runs are (review h47 of h46's change): the local
and Dask workers' runs are keyed with the plugin's sources on disk, a serial run's with the
code loaded here.

- :func:`bomgraph.report.plan_compare` and :func:`bomgraph.bench.is_cached` answer for the
  same executor as :func:`bomgraph.report.compare` and :func:`bomgraph.bench.execute` by
  default: they answered for a serial run while the run used local processes, so in a
  notebook holding an edited, not reloaded plugin the plan said "not cached" of runs the
  sweep then took from the cache.
- A sweep hashes each plugin's package once, not once per task: keyed with the sources on
  disk, the keys read the whole package for every task (800 tasks of a 301-file package:
  18.8 s before the first run, 0.09 s before h46's change).
- The plan with workers refuses a method registered at run time, as the sweep does."""

from __future__ import annotations

import importlib
import os
from dataclasses import replace
import sys
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest

from _depth_mapper import depth_mapper
from _plugin_dist import write_dist_info

from bomgraph import plugins
from bomgraph.bench import Executor, execute, is_cached
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.report import plan_compare
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream

CODE = depth_mapper("DEPTH_M") + "\nDEPTH_M = 1.0\n"


@pytest.fixture
def plugin(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
           ) -> Iterator[tuple[Path, Experiment]]:
    """An installed plugin ``h47-plug`` (package ``h47plug``) and a sweep of it on 4 streams."""
    site = tmp_path / "site"
    (site / "h47plug").mkdir(parents=True)
    (site / "h47plug" / "__init__.py").write_text("")
    src = site / "h47plug" / "mapper.py"
    src.write_text(CODE)
    write_dist_info(site, "h47plug", {"h47-plug": "h47plug.mapper:DepthMapper"})
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]))
    plugins.refresh()
    streams = []
    for seed in range(4):
        streams.append(tmp_path / f"s{seed}.jsonl")
        write_stream(simulate(SimConfig(n_steps=30), np.random.default_rng(seed)), streams[-1])
    try:
        yield src, Experiment("plug", "plug", (Arm("h47-plug", "h47-plug"),),
                              sources=tuple(FileSource(str(p)) for p in streams))
    finally:
        for name in ("h47plug.mapper", "h47plug"):
            sys.modules.pop(name, None)
        plugins.refresh()


def _taken_from_cache(exp: Experiment, out: Path, **kw: Executor) -> int:
    """How many runs :func:`execute` took from ``out/cache`` (its first progress call)."""
    seen: list[int] = []
    execute(exp.tasks(), cache_dir=out / "cache", progress=lambda d, n: seen.append(d), **kw)
    return seen[0]


def test_the_plan_answers_for_the_executor_that_compare_uses_by_default(
        plugin: tuple[Path, Experiment], tmp_path: Path) -> None:
    """A notebook: the plugin ran serially with the code now on disk (B), was reloaded to
    A and ran, then was edited back to B without a reload. The default executor (local
    processes) runs B, whose results are cached: compare/execute take them; the plan and
    is_cached said no (they answered for a serial run, which refuses the stale module)."""
    src, exp = plugin
    out = tmp_path / "out"
    edited = CODE.replace("DEPTH_M = 1.0", "DEPTH_M = 3.0")
    src.write_text(edited)
    module = importlib.import_module("h47plug.mapper")
    execute(exp.tasks(), Executor("serial"), cache_dir=out / "cache")   # B's results cached
    src.write_text(CODE)
    importlib.reload(module)
    execute(exp.tasks(), Executor("serial"), cache_dir=out / "cache")   # A ran and cached
    src.write_text(edited)                                              # B on disk, no reload
    plan = [r["cached"] for r in plan_compare([exp], out)]
    single = is_cached(exp.tasks()[0], out / "cache")
    assert _taken_from_cache(exp, out) == 4            # the default executor: no run
    assert plan == [True] * 4 and single, "the plan answered for a serial run"
    serial = Executor("serial")                        # which refuses the stale module
    assert [r["cached"] for r in plan_compare([exp], out, executor=serial)] == [False] * 4
    assert _taken_from_cache(exp, out, executor=serial) == 0


def test_a_sweep_hashes_a_plugin_package_once_not_once_a_task(
        plugin: tuple[Path, Experiment], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    src, exp = plugin
    out = tmp_path / "out"
    execute(exp.tasks(), Executor("serial"), cache_dir=out / "cache")
    reads: list[bool] = []
    fingerprint = plugins._fingerprint

    def counted(target: str, version: str | None, loaded: bool) -> str | None:
        reads.append(loaded)
        return fingerprint(target, version, loaded)

    monkeypatch.setattr(plugins, "_fingerprint", counted)
    workers = Executor("processes", n_jobs=2)
    for how in ("execute", "plan_compare"):
        for ex in (workers, Executor("serial")):
            reads.clear()
            if how == "execute":    # every run cached: no worker starts
                assert _taken_from_cache(exp, out, executor=ex) == 4
            else:
                assert all(r["cached"] for r in plan_compare([exp], out, executor=ex))
            assert len(reads) <= 2, (how, ex.backend, len(reads))   # loaded, and on disk once


def test_the_plan_refuses_a_run_time_method_for_workers_as_compare_does(
        plugin: tuple[Path, Experiment], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """``plan_compare`` with local processes listed the runs of a method registered at run
    time, which ``compare`` with the same executor then refused (its workers cannot see it)."""
    from bomgraph import mapper
    from bomgraph.errors import ConfigError

    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    mapper.register_method("h47-runtime", "h47plug.mapper:DepthMapper", "registered here")
    _, exp = plugin
    exp = Experiment("rt", "rt", (Arm("h47-runtime", "h47-runtime"),), sources=exp.sources)
    assert len(plan_compare([exp], tmp_path / "out", executor=Executor("serial"))) == 4
    with pytest.raises(ConfigError, match="registered at run time"):
        plan_compare([exp], tmp_path / "out", executor=Executor("processes", n_jobs=2))


LAZY = CODE.replace("DEPTH_M * np.array", "self.depth * np.array").replace(
    "        self.pose, self.seen = np.zeros(3), {}\n", '''        self.pose, self.seen = np.zeros(3), {}
        import os
        from pathlib import Path
        if os.environ.get("H47_SAVE_DURING_RUN") == "1":  # the user's save lands mid-run
            os.environ["H47_SAVE_DURING_RUN"] = "0"
            Path(__file__).with_name("helper.py").write_text("DEPTH_M = 3.0\\n")
        from h47plug import helper       # a module of the package, imported when needed
        self.depth = helper.DEPTH_M
''')


def test_a_run_during_which_its_package_was_edited_is_not_cached(
        plugin: tuple[Path, Experiment], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The key is taken before the run: a module of the plugin's package that the run imports
    later was read after an edit saved meanwhile, and the result of the new code was cached
    under the key of the old (a later sweep of the old code got it: MPE 1.93 m for 0.25 m)."""
    src, exp = plugin
    src.write_text(LAZY)
    helper = src.with_name("helper.py")
    helper.write_text("DEPTH_M = 1.0\n")
    exp = replace(exp, sources=exp.sources[:1])
    cache = tmp_path / "cache"
    monkeypatch.setenv("H47_SAVE_DURING_RUN", "1")
    (during,) = execute(exp.tasks(), Executor("serial"), cache_dir=cache)
    assert not during["ok"] and "was edited since" in during["error"], during
    assert list(cache.glob("*.json")) == [], "a result was cached under another code's key"


def test_a_check_after_the_run_that_fails_fails_the_run_not_the_sweep(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The stale check after a run was outside any try (h49): had it raised (a package
    broken meanwhile), the exception left the task. It is now the run's error."""
    from bomgraph import method_code

    def broken(task, *, worker):
        raise RuntimeError("the package went away")

    monkeypatch.setattr(method_code, "stale_plugin", broken)
    why = method_code.stale_after_run(object(), worker=True)
    assert "could not be checked after the run" in why and "went away" in why


def test_an_edit_between_import_and_first_key_is_not_taken_for_the_code_that_runs(
        plugin: tuple[Path, Experiment], tmp_path: Path) -> None:
    """bomgraph imported the plugin (``method_info``: ``bomgraph methods``, building a sweep),
    the file was then edited without a reload, and the first serial sweep ran the old code
    but cached it under the new code's key, because a loaded file was first read when first
    hashed (h47). Its contents are now recorded when bomgraph imports it: the serial run
    refuses the stale module, and nothing is cached."""
    from bomgraph.mapper import method_info

    src, exp = plugin
    method_info("h47-plug")                        # imports h47plug.mapper (DEPTH_M 1.0)
    assert "h47plug.mapper" in sys.modules
    src.write_text(CODE.replace("DEPTH_M = 1.0", "DEPTH_M = 3.0"))   # no reload
    out = tmp_path / "out"
    results = execute(exp.tasks()[:1], Executor("serial"), cache_dir=out / "cache")
    assert not results[0]["ok"] and "edited since this process imported it" in (
        results[0]["error"]), results[0]
    assert not list((out / "cache").glob("*.json"))
    # the package is hashed whole (the edit may be in another of its modules): it is named
    assert "(a source file of 'h47plug')" in results[0]["error"]
