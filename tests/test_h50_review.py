"""h50's review of the lead's last commits (NAME@PRESET, plugins.load's record, the turn no
longer refused by importers): what it found, each test failing before."""

from __future__ import annotations

import logging
import os
import subprocess
import sys
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest

from _depth_mapper import depth_mapper
from _plugin_dist import write_dist_info

from bomgraph import plugins

ROOT = Path(__file__).resolve().parents[1]


def test_a_g2o_turn_beyond_a_full_turn_is_imported_when_its_edges_differ(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """Importers were to stop refusing a turn beyond 2 pi (g2o wraps angles: an EDGE_SE2 of 7
    rad is a valid file), but the turn was still judged against the step's own sigma: a g2o
    file whose edges' information differ (each step has its own ``odom_sigma``, as in most
    real files) was refused as before. The reader still warns of the turn."""
    from bomgraph.datasets.g2o import import_g2o
    from bomgraph.stream_file import read_stream, write_stream

    g2o = tmp_path / "turn.g2o"
    g2o.write_text("EDGE_SE2 0 1 1.0 0.0 7.0 100 0 0 100 0 400\n"
                   "EDGE_SE2 1 2 1.0 0.0 0.1 50 0 0 50 0 200\n"
                   "EDGE_BEARING_SE2_XY 0 10 0.5 1000\n"
                   "EDGE_BEARING_SE2_XY 1 10 0.3 1000\n"
                   "EDGE_BEARING_SE2_XY 2 10 0.2 1000\n")
    stream = import_g2o(g2o)                        # refused: "step 1 turns 7 rad"
    assert stream.steps[1].odom_sigma is not None and stream.steps[1].odom[2] == 7.0
    write_stream(stream, tmp_path / "s.jsonl")
    with caplog.at_level(logging.WARNING, logger="bomgraph"):
        read_stream(tmp_path / "s.jsonl")
    assert "turns 7 rad" in caplog.text


@pytest.fixture
def two_packages(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """Installed plugins ``h50-base`` (package ``h50base``) and ``h50-sub`` (package
    ``h50sub``, whose module imports ``h50base.mapper`` to subclass its mapper)."""
    site = tmp_path / "site"
    for pkg in ("h50base", "h50sub"):
        (site / pkg).mkdir(parents=True)
        (site / pkg / "__init__.py").write_text("")
    base = site / "h50base" / "mapper.py"
    base.write_text(depth_mapper("DEPTH_M") + "\nDEPTH_M = 1.0\n")
    (site / "h50sub" / "mapper.py").write_text(
        "from h50base.mapper import DepthMapper\n\nclass SubMapper(DepthMapper):\n    pass\n")
    write_dist_info(site, "h50base", {"h50-base": "h50base.mapper:DepthMapper"})
    write_dist_info(site, "h50sub", {"h50-sub": "h50sub.mapper:SubMapper"})
    monkeypatch.syspath_prepend(str(site))
    plugins.refresh()
    try:
        yield base
    finally:
        for name in ("h50sub.mapper", "h50sub", "h50base.mapper", "h50base"):
            sys.modules.pop(name, None)
        plugins.refresh()


def test_a_plugin_imported_by_another_plugins_import_is_recorded_when_loaded(
        two_packages: Path, tmp_path: Path) -> None:
    """``plugins.load`` recorded a package's files only when that call imported the module
    itself: a plugin whose module another plugin's import had imported first (a subclass in
    another package) was first read when first hashed, so an edit in between, not reloaded,
    ran the old code and cached it under the new code's key (h47's bug, for that plugin)."""
    from bomgraph.bench import Executor, execute
    from bomgraph.experiments import Arm, Experiment, FileSource
    from bomgraph.mapper import method_factory, method_info
    from bomgraph.sim import SimConfig, simulate
    from bomgraph.stream_file import write_stream

    method_info("h50-sub")                          # imports h50sub.mapper, h50base.mapper
    assert "h50base.mapper" in sys.modules
    method_factory("h50-base")                      # bomgraph loads it: already imported
    two_packages.write_text(two_packages.read_text().replace("DEPTH_M = 1.0", "DEPTH_M = 3.0"))
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=30), np.random.default_rng(0)), stream)
    exp = Experiment("p", "p", (Arm("h50-base", "h50-base"),), sources=(FileSource(str(stream)),))
    cache = tmp_path / "cache"
    (res,) = execute(exp.tasks(), Executor("serial"), cache_dir=cache)
    assert not res["ok"] and "edited since this process imported it" in res["error"], res
    assert not list(cache.glob("*.json")), "the old code's result was cached under the new key"


def test_a_built_in_method_pays_nothing_for_the_plugins_record() -> None:
    """``plugins.load`` hashed the whole top-level package of every module it imported, the
    built-in methods' too (bomgraph's and baselines' files, about 5 ms a method per process,
    every worker included), though their code is keyed by ``code_fingerprint`` and never by
    the record."""
    code = ("from bomgraph import plugins\nfrom bomgraph.mapper import method_factory\n"
            "for m in ('stmds-smacof', 'ekf', 'triangulate'):\n    method_factory(m)\n"
            "print(len(plugins._LOADED))\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=True, timeout=300)
    assert out.stdout.strip() == "0", out.stdout
