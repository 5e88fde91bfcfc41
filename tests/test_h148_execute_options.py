"""``execute()`` (the library's sweep, ``compare``'s executor) refuses an arm's options
before any run, as ``compare --methods`` and a sweep file do (h148: it ran the sweep, every run
of such an arm failing alike, a hybrid's unknown ``seed_method`` too)."""

from __future__ import annotations

from pathlib import Path

import pytest

from bomgraph.bench import Executor, execute
from bomgraph.errors import ConfigError
from bomgraph.experiments import Arm, Experiment
from bomgraph.sim import SimConfig


def _tasks(arms: tuple[Arm, ...], reference: Arm | None = None) -> list:
    return Experiment("x", "x", arms, sim=SimConfig(n_steps=20), n_layouts=1, n_starts=1,
                      reference=reference).tasks()


@pytest.mark.parametrize("bad,match", [
    (Arm("h", "hybrid", {"seed_method": "nope"}), r"arm 'h' \(hybrid.*seed_method='nope'"),
    (Arm("e", "ekf", {"nope": 1}), r"arm 'e' \(ekf.*unknown option"),
])
def test_execute_refuses_bad_options_before_any_run(tmp_path: Path, bad: Arm,
                                                    match: str) -> None:
    calls: list[tuple[int, int]] = []
    with pytest.raises(ConfigError, match=match):
        execute(_tasks((Arm("t", "triangulate"), bad)), Executor("serial"),
                cache_dir=tmp_path / "cache", progress=lambda i, n: calls.append((i, n)))
    assert calls == [] and not (tmp_path / "cache").exists()


def test_execute_refuses_a_reference_s_bad_options(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"arm 'ref' \(hybrid"):
        execute(_tasks((Arm("t", "triangulate"),),
                       reference=Arm("ref", "hybrid", {"seed_method": "oracle"})),
                Executor("serial"))
