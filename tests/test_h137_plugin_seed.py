"""A plugin's own hybrid has its ``seed_method`` checked before any run, as ``hybrid``'s is
(h137).

A researcher's hybrid (a plugin whose factory takes ``seed_method`` and ``seed_options`` and
builds that method as its seed) could not have its seed checked: ``compare --option
seeded:seed_method=nope`` (or a bound, or seed options the seed refuses) ran, and every run
of the method failed, one at a time, mid-sweep, exit 1. The built-in hybrids' check
(``check_seed``) now lives in ``bomgraph.mapper`` and
:func:`bomgraph.mapper.check_method_options` makes it for any method with a
``seed_method``: the command refuses in one line, exit 2, before any run; the default seed
of the plugin (or of its preset) is checked too, and seeds that go round in a circle are
refused (building them would never end)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from _plugin_dist import installed

from bomgraph.errors import ConfigError
from bomgraph.mapper import check_method_options
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream

ROOT = Path(__file__).resolve().parents[1]

MODULE = '''
"""A user's own hybrid: its seed is any registered method, built as it starts."""
from dataclasses import dataclass
from typing import Any, ClassVar, Mapping, Optional

from bomgraph.config import Presets
from bomgraph.mapper import MapEstimate, create_mapper


class Seeded:
    """the map of its seed"""

    def __init__(self, header, *, seed_method: str = "triangulate",
                 seed_options: Optional[Mapping[str, Any]] = None) -> None:
        self.seed = create_mapper(seed_method, header, **dict(seed_options or {}))

    def step(self, step) -> None:
        self.seed.step(step)

    def estimate(self) -> MapEstimate:
        return self.seed.estimate()


class Circle(Seeded):
    """its seed is itself, by default"""

    def __init__(self, header, *, seed_method: str = "h137-circle") -> None:
        super().__init__(header, seed_method=seed_method)


@dataclass(frozen=True)
class SeededConfig(Presets):
    PRESETS: ClassVar = {"paper": {}, "typo": {"seed_method": "stmds-smacoff"}}
    seed_method: str = "triangulate"


class WithPresets(Seeded):
    """a configuration with presets"""

    config_class = SeededConfig

    def __init__(self, header, *, preset: Optional[str] = None, **options) -> None:
        cfg = SeededConfig.preset(preset or "paper", **options)
        super().__init__(header, seed_method=cfg.seed_method)
'''

METHODS = {"h137-seeded": "h137seeded:Seeded", "h137-circle": "h137seeded:Circle",
           "h137-presets": "h137seeded:WithPresets"}


@pytest.fixture()
def site(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    folder = tmp_path / "site"
    folder.mkdir()
    yield from installed(folder, monkeypatch, "h137seeded", MODULE, METHODS)


BAD = [
    ("h137-seeded", {"seed_method": "nope"},
     "method 'h137-seeded': seed_method='nope', seed_options={}: unknown method 'nope'"),
    ("h137-seeded", {"seed_method": "oracle"},
     "method 'h137-seeded': seed_method='oracle' is a bound (it needs the truth"),
    ("h137-seeded", {"seed_options": {"bogus": 1}},
     "method 'h137-seeded': seed_method='triangulate', seed_options={'bogus': 1}: "
     "TriangulateConfig: unknown option bogus"),
    ("h137-seeded", {"seed_options": 3},
     "method 'h137-seeded': seed_options must be a mapping (a JSON object) of the options of "
     "'triangulate', got 3"),
    ("h137-seeded", {"seed_method": "h137-seeded", "seed_options": {"seed_method": "nope"}},
     "method 'h137-seeded': seed_method='h137-seeded', seed_options={'seed_method': 'nope'}: "
     "method 'h137-seeded': seed_method='nope'"),
    ("h137-circle", {}, "method 'h137-circle': seed_method='h137-circle' seeds itself "
                        "(h137-circle -> h137-circle)"),
    ("h137-presets", {"preset": "typo"},
     "method 'h137-presets': seed_method='stmds-smacoff', seed_options={}: unknown method "
     "'stmds-smacoff'"),
    ("hybrid", {"seed_method": "h137-seeded", "seed_options": {"seed_method": "oracle"}},
     "HybridConfig: seed_method='h137-seeded', seed_options={'seed_method': 'oracle'}: "
     "method 'h137-seeded': seed_method='oracle' is a bound"),
]


@pytest.mark.parametrize("method, options, error", BAD)
def test_a_seed_is_checked_before_any_run(site: Path, method: str, options: dict,
                                          error: str) -> None:
    with pytest.raises(ConfigError) as err:
        check_method_options(method, options)
    assert str(err.value).startswith(error), str(err.value)


@pytest.mark.parametrize("method, options", [
    ("h137-seeded", {}), ("h137-seeded", {"seed_method": "stmds-smacof",
                                          "seed_options": {"preset": "real"}}),
    ("h137-seeded", {"seed_method": "h137-seeded"}),  # seeded by itself seeded by triangulate
    ("h137-presets", {}), ("hybrid", {"seed_method": "h137-seeded"})])
def test_a_good_seed_is_taken(site: Path, method: str, options: dict) -> None:
    check_method_options(method, options)


def test_compare_refuses_a_plugin_hybrids_wrong_seed_before_any_run(site: Path,
                                                                     tmp_path: Path) -> None:
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=20), np.random.default_rng(3)), stream)
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(ROOT)]),
           "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, "-m", "bomgraph", "compare", "--streams",
                           str(stream), "--methods", "h137-seeded,triangulate", "--option",
                           "h137-seeded:seed_method=stmds-smacoff", "--jobs", "1",
                           "--no-figures", "--out", str(out)], env=env, cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stderr[-2000:]
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(
        "bomgraph: error: --option h137-seeded: options {'seed_method': 'stmds-smacoff'}: "
        "method 'h137-seeded': seed_method='stmds-smacoff', seed_options={}: unknown method "
        "'stmds-smacoff'"), proc.stderr
    assert not out.exists()  # nothing ran, nothing written
