"""A method's ``info["converged"]`` that is not True, False or None (h98).

A plugin returning ``"yes"`` was cached as a result whose ``converged`` the cache's own check
(``result_cache.read_cached``: true, false or null) then refused on every later sweep, so the
run ran again each time, and the summary's ``np.mean`` of it ended ``compare`` in a
traceback. Now such a value is recorded as unknown (``converged`` None, as the report treats
a method that says nothing), with one warning naming the method and the key; the method's
own ``info`` keeps what it said. A numpy ``bool_`` (what ``np.all(...)`` returns) is a bool:
recorded as one, and cached.
"""

from __future__ import annotations

import importlib
import json
import logging
from pathlib import Path

import numpy as np
import pytest
from _depth_mapper import depth_mapper
from _plugin_site import write

from bomgraph import mapper
from bomgraph.bench import Executor, execute_counted
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.report import summarise
from bomgraph.result_cache import read_cached
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream

ESTIMATE = ("return MapEstimate(ids, np.array([self.seen[i] for i in ids.tolist()])"
            ".reshape(-1, 2))")


def _experiment(plugin_site: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                pkg: str, converged: str) -> Experiment:
    """A method (registered at run time as ``h98-conv``) whose info says ``converged =
    <converged>`` (an expression), and a one-run experiment of it."""
    code = depth_mapper("1.0").replace(
        ESTIMATE, ESTIMATE[:-1] + f", info={{'converged': {converged}}})")
    assert "info=" in code
    write(plugin_site / pkg / "__init__.py", "")
    write(plugin_site / pkg / "m.py", code)
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    importlib.import_module(f"{pkg}.m")
    mapper.register_method("h98-conv", f"{pkg}.m:DepthMapper")
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=20), np.random.default_rng(5)), stream)
    return Experiment("e", "e", (Arm("h98-conv", "h98-conv"),), sources=(FileSource(str(stream)),))


def test_a_numpy_bool_is_recorded_as_a_bool_and_cached(
        plugin_site: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    exp = _experiment(plugin_site, tmp_path, monkeypatch, "h98np", "np.bool_(True)")
    (res,), n_cached = execute_counted(exp.tasks(), Executor("serial"),
                                       cache_dir=tmp_path / "cache")
    assert res["ok"] and res["converged"] is True and n_cached == 0
    (again,), n_cached = execute_counted(exp.tasks(), Executor("serial"),
                                         cache_dir=tmp_path / "cache")
    assert n_cached == 1 and again["converged"] is True
    assert summarise([again])[0]["converged_rate"] == 1.0


def test_a_string_is_recorded_as_unknown_with_one_warning_and_cached(
        plugin_site: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        caplog: pytest.LogCaptureFixture) -> None:
    """Fails before: ``converged`` was "yes", the second sweep ran it again (the cache entry
    refused), and ``summarise`` raised TypeError."""
    exp = _experiment(plugin_site, tmp_path, monkeypatch, "h98str", "'yes'")
    with caplog.at_level(logging.WARNING):
        (res,), n_cached = execute_counted(exp.tasks(), Executor("serial"),
                                           cache_dir=tmp_path / "cache")
    assert res["ok"] and res["converged"] is None and n_cached == 0
    assert res["info"]["converged"] == "yes"              # the method's own words, kept
    said = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(said) == 1, said
    assert "h98-conv" in said[0] and "info['converged']" in said[0] and "'yes'" in said[0]
    (again,), n_cached = execute_counted(exp.tasks(), Executor("serial"),
                                         cache_dir=tmp_path / "cache")
    assert n_cached == 1 and again["converged"] is None
    row = summarise([again])[0]
    assert np.isnan(row["converged_rate"]) and row["n_converged_known"] == 0


@pytest.mark.parametrize("converged, warned", [("np.bool_(False)", True), ("False", True),
                                               ("np.bool_(True)", False), ("None", False)])
def test_bomgraph_run_warns_of_a_final_solve_that_did_not_converge(
        plugin_site: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        caplog: pytest.LogCaptureFixture, converged: str, warned: bool) -> None:
    """``run_file`` (``bomgraph run``) warns when the final map says it did not converge,
    also when it says so with a numpy ``bool_`` (before: only ``is False``, so a method
    returning ``np.bool_(False)`` got no warning)."""
    from bomgraph.file_run import run_file

    pkg = "h98run_" + "".join(c for c in converged if c.isalnum())
    exp = _experiment(plugin_site, tmp_path, monkeypatch, pkg, converged)
    with caplog.at_level(logging.WARNING, logger="bomgraph"):
        run_file(exp.sources[0].path, "h98-conv")
    said = [r.getMessage() for r in caplog.records if "did not converge" in r.getMessage()]
    assert len(said) == int(warned), said


@pytest.mark.parametrize("converged", [1, 0, 1.0, 0.0, 2, "yes"])
def test_a_cached_converged_that_is_a_number_is_a_cache_miss(
        tmp_path: Path, converged: object, caplog: pytest.LogCaptureFixture) -> None:
    """A hand-edited cache entry whose ``converged`` is a number is of the wrong shape, as
    ``2`` or ``"yes"`` is. Fails before for 1, 0, 1.0 and 0.0: the check was a membership
    test, ``in (None, True, False)``, and 1 == True, 0.0 == False, so the entry was read and
    its ``converged`` reached the per-run table as a number."""
    path = tmp_path / "key.json"
    path.write_text(json.dumps(
        {"ok": True, "key": "key", "experiment": "e", "arm": "a", "method": "m", "run": "r",
         "checkpoints": [], "total_s": 0.0, "step_median_s": 0.0, "info": {},
         "converged": converged}))
    with caplog.at_level(logging.WARNING):
        assert read_cached(path) is None
    assert "'converged' not true, false or null" in caplog.text and str(path) in caplog.text
