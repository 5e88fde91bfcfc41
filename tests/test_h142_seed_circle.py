"""A circle of seeds through presets is refused in one line, as other circles are (h142).

h137's circle check compared each method's options with its ``preset`` taken out, so a plugin
whose preset ``ping`` seeds it with preset ``pong``, and ``pong`` with ``ping``, was never seen
going round: ``compare --methods NAME@ping`` ended in a ``RecursionError`` traceback, exit 1,
instead of the one-line refusal, exit 2."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from _plugin_dist import installed

from bomgraph.cli import main
from bomgraph.errors import ConfigError
from bomgraph.mapper import check_method_options
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream

MODULE = '''
"""A plugin whose presets seed it with each other."""
from dataclasses import dataclass
from typing import Any, ClassVar, Mapping, Optional

from bomgraph.config import Presets
from bomgraph.mapper import create_mapper


@dataclass(frozen=True)
class PingConfig(Presets):
    PRESETS: ClassVar = {
        "paper": {},
        "ping": {"seed_method": "h142-ping", "seed_options": {"preset": "pong"}},
        "pong": {"seed_method": "h142-ping", "seed_options": {"preset": "ping"}},
        "once": {"seed_method": "h142-ping", "seed_options": {"preset": "paper"}}}
    seed_method: str = "triangulate"
    seed_options: Optional[Mapping[str, Any]] = None


class Ping:
    """the map of its seed"""

    config_class = PingConfig

    def __init__(self, header, *, preset: Optional[str] = None, **options) -> None:
        cfg = PingConfig.preset(preset or "paper", **options)
        self.seed = create_mapper(cfg.seed_method, header, **dict(cfg.seed_options or {}))

    def step(self, step) -> None:
        self.seed.step(step)

    def estimate(self):
        return self.seed.estimate()
'''


@pytest.fixture()
def site(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    folder = tmp_path / "site"
    folder.mkdir()
    yield from installed(folder, monkeypatch, "h142ping", MODULE, {"h142-ping": "h142ping:Ping"})


@pytest.mark.parametrize("preset, path", [("ping", "h142-ping -> h142-ping -> h142-ping"),
                                          ("pong", "h142-ping -> h142-ping -> h142-ping")])
def test_a_circle_through_presets_is_refused(site: Path, preset: str, path: str) -> None:
    with pytest.raises(ConfigError) as err:
        check_method_options("h142-ping", {"preset": preset})
    error = str(err.value)
    assert error.startswith("method 'h142-ping': seed_method='h142-ping'"), error
    assert f"seeds itself ({path}): choose another seed method" in error, error


def test_a_method_seeded_by_another_preset_of_its_own_is_taken(site: Path) -> None:
    check_method_options("h142-ping", {"preset": "once"})  # once -> paper -> triangulate


def test_compare_refuses_it_in_one_line(site: Path, tmp_path: Path, capsys) -> None:
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=20), np.random.default_rng(3)), stream)
    out = tmp_path / "out"
    code = main(["compare", "--streams", str(stream), "--methods", "h142-ping@ping,h142-ping@once",
                 "--jobs", "1", "--no-figures", "--out", str(out)])
    lines = capsys.readouterr().err.splitlines()
    assert code == 2, lines[-20:]
    assert len(lines) == 1 and "seeds itself (h142-ping -> h142-ping -> h142-ping)" in lines[0], \
        lines[-20:]
    assert not out.exists()
