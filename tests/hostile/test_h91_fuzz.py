"""Faults found by helper h91's fuzz campaign against the command line (a seeded driver that
mutates valid streams, estimates, sweep files and dataset slices and runs ``bomgraph`` in
bounded subprocesses), each reduced to its smallest reproduction. Each test failed before
its fix."""

from __future__ import annotations

from pathlib import Path

import pytest

from bomgraph.sweep import SweepError, read_sweep


def _worlds(n: int, seeds: str) -> str:
    return "".join(f'[[worlds]]\nname = "w{i}"\nn_steps = 15\nn_landmarks = 6\nseeds = {seeds}\n'
                   for i in range(n))


def test_a_sweep_of_many_worlds_is_bounded_as_a_whole(tmp_path: Path) -> None:
    """2,000 worlds of 100,000 seeds each (each within the per-world bound) made 200 million
    seeds while the file was read: ``compare --config`` died of a MemoryError traceback.
    The sweep's simulated runs are counted as its worlds are read."""
    path = tmp_path / "many.toml"
    path.write_text('name = "fz"\n' + _worlds(11, "100000") + '[[methods]]\nname = "triangulate"\n')
    with pytest.raises(SweepError, match=r"many.toml: worlds\[10\].seeds: the sweep's simulated "
                                         r"runs would exceed 1,000,000"):
        read_sweep(path)


def test_a_sweep_of_many_methods_is_bounded_as_a_whole(tmp_path: Path) -> None:
    """One world of 100,000 seeds and 200 methods is 20 million tasks: ``compare --dry-run``
    ran past 5 minutes, its memory growing. Runs x methods are bounded too."""
    path = tmp_path / "arms.toml"
    path.write_text('name = "fz"\n' + _worlds(1, "[" + ", ".join(map(str, range(100_000))) + "]")
                    + "".join(f'[[methods]]\nname = "triangulate"\nlabel = "m{i}"\n'
                              for i in range(11)))
    with pytest.raises(SweepError, match=r"arms.toml: methods: the sweep's runs x methods would "
                                         r"exceed 1,000,000"):
        read_sweep(path)
