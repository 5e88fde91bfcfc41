"""h110: two compares starting at once, each into a folder the other writes into through a
link, could both be refused (neither ran): each took its own folder, then found the other's
held. ``scripts/stress_compare_locks.py --at-lock crossed``: 1 of 20 both refused before. A
compare refused at a lock after its own folder's now lets go of all and takes them again.
Here the other compare is a lock the test holds, and lets go of when it would have been
refused by this one's."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Callable, Iterator

import pytest

import _compare_folder
from bomgraph import out_folder
from bomgraph.cli import main
from bomgraph.stdio import FolderBusyError, folder_lock

stream = _compare_folder.stream   # the fixture
_WHO = "`bomgraph compare`"


def _crossed(tmp_path: Path) -> tuple[Path, Path]:
    """``x/estimates`` a link to ``w/e``, ``w/estimates`` to ``x/e``."""
    x, w = tmp_path / "x", tmp_path / "w"
    for f in (x / "e", w / "e"):
        f.mkdir(parents=True)
    (x / "estimates").symlink_to(w / "e")
    (w / "estimates").symlink_to(x / "e")
    return x, w


def _count_tries(monkeypatch: pytest.MonkeyPatch, x: Path,
                 on_try: Callable[[int], None] = lambda n: None) -> list[str]:
    """The folders compare locks, as it locks them (``on_try(n)`` first, at its ``n``-th try
    of ``x``); no pause between tries."""
    lock, tries = out_folder.folder_lock, []

    @contextlib.contextmanager
    def counted(folder: str, what: str, shared: bool = False) -> Iterator[None]:
        tries.append(folder)
        if Path(folder) == x:
            on_try(sum(Path(f) == x for f in tries))
        with lock(folder, what, shared):
            yield

    monkeypatch.setattr(out_folder, "folder_lock", counted)
    monkeypatch.setattr(out_folder, "RETRY_S", 0.0, raising=False)
    return tries


def test_refused_after_its_own_folder_it_lets_go_and_tries_again(
        tmp_path: Path, stream: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture) -> None:
    """The other compare (into ``w``) holds ``w``, which this one (into ``x``) locks shared
    as a folder above the one it writes into through its link; the other one, finding ``x``
    held, is refused and lets go of ``w``. This one was refused too: neither ran. Now it lets
    go of ``x`` and tries again, and runs. Fails before (status 2)."""
    x, w = _crossed(tmp_path)

    def other_refused(n: int) -> None:
        if n == 2:   # x let go (else the other one could not have seen it free) ...
            with folder_lock(x, _WHO):
                pass
            other.close()     # ... and the other one, refused, let go of w

    tries = _count_tries(monkeypatch, x, other_refused)
    with contextlib.ExitStack() as other:
        other.enter_context(folder_lock(w, _WHO))   # the other compare, into w, has it
        assert main(_compare_folder.linked_cmd(stream, x, "triangulate")) == 0, \
            capsys.readouterr().err
    assert tries.count(x) == 2
    assert (w / "e" / "streams" / "triangulate" / "s.est").is_file()


def test_a_compare_that_keeps_the_lock_still_refuses_it_with_the_same_line(
        tmp_path: Path, stream: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture) -> None:
    """The other compare runs (holds ``w`` throughout): every try is refused, the last one's
    line is the error, and nothing is written through the link. Each try took ``x`` again
    (let go in between: the other one, taking its locks, could look at it)."""
    x, w = _crossed(tmp_path)
    tries = _count_tries(monkeypatch, x)
    with folder_lock(w, _WHO):
        assert main(_compare_folder.linked_cmd(stream, x, "triangulate")) == 2
    err = _compare_folder.one_error(capsys)
    assert f"{w}: another {_WHO}" in err and "is writing into this folder" in err, err
    assert f"(pid {os.getpid()})" in err
    assert tries.count(x) == out_folder.LOCK_RETRIES + 1
    assert not list((w / "e").rglob("*.est")) and not (x / "results.csv").exists()


def test_refused_at_its_own_folder_it_is_refused_at_once(tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch
                                                          ) -> None:
    """Refused at ``out`` it holds nothing, so nothing of it can refuse the other: no retry."""
    x, _ = _crossed(tmp_path)
    tries = _count_tries(monkeypatch, x)
    with folder_lock(x, _WHO):
        with pytest.raises(FolderBusyError, match="is writing into this folder"):
            with out_folder.compare_locks(x, [x / "results.csv"]):
                pass
    assert tries == [x]
