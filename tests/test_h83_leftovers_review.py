"""Review of h79's removal of leftover temporary files (h83).

Two writers of one name (two ``bomgraph run --out same.est``, two sweeps sharing a cache
folder) remove each other's *finished* temporary files' names from their listing only by
luck: a file listed, then renamed into place by its writer before the remover opened or
locked it, was reported as ``WARNING: could not remove ..., left by an interrupted writer:
[Errno 2] No such file or directory`` (2 processes writing one name 1,000 times each: 6 such
lines). And where there is no ``flock`` (Windows; simulated here by making ``import fcntl``
fail) compare's removal took a live writer's file, whose rename then failed with
FileNotFoundError: the output was lost.
"""

from __future__ import annotations

import logging
import os
import sys
from pathlib import Path

import pytest

from bomgraph import claims
from bomgraph.stdio import AtomicOutput, write_text


def _partials(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".partial"))


def _warnings(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]


def test_a_file_put_in_place_after_it_was_listed_is_no_warning(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        caplog: pytest.LogCaptureFixture) -> None:
    """The second writer lists the first's temporary file; the first renames it into place
    before the second opens it. Fails before h83: a WARNING 'could not remove ..., left by an
    interrupted writer: [Errno 2] No such file or directory'."""
    path = tmp_path / "key.json"
    first = AtomicOutput(path)
    first.open().write("first")
    real_scandir = os.scandir

    class Listing:  # the folder as listed; the first writer finishes just after
        def __init__(self, folder: str) -> None:
            with real_scandir(folder) as entries:
                self.entries = list(entries)

        def __enter__(self) -> object:
            if first.fh is not None:
                first.commit()
            return iter(self.entries)

        def __exit__(self, *exc: object) -> None:
            return None

    monkeypatch.setattr(os, "scandir", Listing)
    with caplog.at_level(logging.DEBUG):
        write_text(path, "second")
    assert first.fh is None  # the race happened
    assert _warnings(caplog) == []
    assert path.read_text() == "second" and _partials(tmp_path) == []


def test_a_file_put_in_place_after_it_was_opened_is_no_warning(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        caplog: pytest.LogCaptureFixture) -> None:
    """The remover has opened the first writer's temporary file; the first renames it into
    place and lets its lock go before the remover locks it: the remover's lock then holds,
    and the name it would remove is gone (or, worse, another file's). Fails before h83: the
    same WARNING; now nothing is removed and nothing said."""
    path = tmp_path / "key.json"
    first = AtomicOutput(path)
    first.open().write("first")
    tmp = first._tmp
    real_open = os.open

    def raced(name: object, flags: int, *args: object, **kwargs: object) -> int:
        fd = real_open(name, flags, *args, **kwargs)
        if os.fspath(name) == tmp and first.fh is not None:
            first.commit()  # renamed into place, its claim released
        return fd

    monkeypatch.setattr(os, "open", raced)
    with caplog.at_level(logging.DEBUG):
        assert claims.remove_leftovers(str(tmp_path), ["key.json"]) == 0
    assert first.fh is None  # the race happened
    assert _warnings(caplog) == []
    assert path.read_text() == "first" and _partials(tmp_path) == []


def test_without_flock_nothing_is_removed(tmp_path: Path,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """No ``fcntl`` (Windows, simulated): writers hold no claim, so a live writer's file is
    not told from a killed one's. compare's removal (:func:`claims.remove_leftovers`) took
    a live writer's file and its rename failed with FileNotFoundError (output lost) before
    h83; now nothing is removed, neither by compare nor by a writer."""
    monkeypatch.setitem(sys.modules, "fcntl", None)
    dead = tmp_path / ".out.est.abcdefgh.partial"
    dead.write_text("left")
    live = AtomicOutput(tmp_path / "live.est")
    live.open().write("being written")
    write_text(tmp_path / "out.est", "written")  # a writer of the dead file's name
    assert dead.read_text() == "left"
    assert claims.remove_leftovers(str(tmp_path), ["out.est", "live.est"]) == 0
    assert claims.remove_unclaimed(str(dead)) is False and dead.exists()
    live.commit()
    assert (tmp_path / "live.est").read_text() == "being written"
    assert (tmp_path / "out.est").read_text() == "written"
    assert _partials(tmp_path) == [dead.name]


def test_a_sweep_removes_its_cache_folders_leftovers_once_and_a_cache_write_lists_nothing(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Each cache file written listed the whole cache folder (10,000 files: 7.7 ms a write,
    about what the write itself costs; a sweep's listings grow as the square of its runs).
    Now a sweep lists it once, at its start, and removes every cache file's leftover there,
    also those of keys it does not write again (before h83 they stayed: only the name
    written was cleaned); a live writer's (another sweep's) stays."""
    from bomgraph.bench import Executor, execute, task_key
    from bomgraph.experiments import Arm, Experiment
    from bomgraph.result_cache import write_cached
    from bomgraph.sim import SimConfig

    tasks = Experiment("t", "test", (Arm("tri", "triangulate"),), SimConfig(
        n_steps=20, n_landmarks=10), seed=3, n_layouts=1, n_starts=2).tasks()
    execute(tasks[:1], Executor("serial"), cache_dir=tmp_path)
    cached = task_key(tasks[0])
    dead = [tmp_path / f".{cached}.json.abcdefgh.partial",
            tmp_path / f".{'0' * 20}.json.zzzzzzzz.partial"]
    kept = [tmp_path / f".{cached}.jsonx.abcdefgh.partial", tmp_path / "notes.txt"]
    for p in dead + kept:
        p.write_text("left")
    live = AtomicOutput(tmp_path / f"{'1' * 20}.json")
    live.open().write("another sweep's")
    listed: list[str] = []
    real_scandir = os.scandir
    monkeypatch.setattr(os, "scandir", lambda p: listed.append(os.fspath(p)) or real_scandir(p))
    write_cached(tmp_path / f"{'2' * 20}.json", {"ok": True, "key": "2" * 20})
    assert listed == [] and all(p.exists() for p in dead)
    execute(tasks, Executor("serial"), cache_dir=tmp_path)  # the first from the cache
    assert listed.count(os.fspath(tmp_path)) == 1
    assert not any(p.exists() for p in dead) and all(p.exists() for p in kept)
    live.commit()
    assert (tmp_path / f"{'1' * 20}.json").read_text() == "another sweep's"
