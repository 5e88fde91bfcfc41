"""h115: adversarial review of h108's one racy-clock rule (``file_digest.settled_status``).

- h108 trusted a status whose times were both far ahead of the clock ("a machine's whose clock
  is ahead"): a file on a server whose clock is ahead of ours, its timestamps in ticks of a
  second, was kept at once, and a same-size write in the same tick of the server's clock
  kept its status: the old digest (or listing) was served for the new bytes. Before h108 a
  time ahead was never settled. A ctime ahead is now never settled; an mtime ahead is, while
  the ctime is settled behind the clock.
- Before h108 too: the clock stepped back (NTP) into the tick of a kept status, a same-size
  write there, the clock on again: the status matched, the old digest was served. A status
  now holds how many times the clock was seen to step back.
- No test failed with the rule judging the ctime alone (h108's vfat test is caught by its
  "ahead" flag), nor with the Windows guard removed.
- h108 fixed, unclaimed: a settled folder that could not be listed (out of file handles) had
  its empty listing kept until it changed; now nothing is kept (a test holds it).

Fake clocks as tests/test_h108_racy_rule.py's; a file system whose timestamps are coarse is
one whose status keeps one time for every write (``_status`` patched: ``_tick``).
"""

from __future__ import annotations

import errno
import os
import types
from pathlib import Path
from typing import Callable

import pytest

from bomgraph import file_digest, source_files
from test_h108_racy_rule import USERS, _clock, _user

SECOND_NS = 1_000_000_000


def _tick(monkeypatch: pytest.MonkeyPatch, path: Path) -> int:
    """Every write to ``path`` from now on lands in one tick of its file system's clock (the
    status keeps that time as ctime and mtime, and a folder's size): that tick's time."""
    tick_ns = path.stat().st_ctime_ns
    status = file_digest._status
    monkeypatch.setattr(file_digest, "_status",
                        lambda st: (*status(st)[:2], 0, tick_ns, tick_ns))
    return tick_ns


def _edit(user: str, path: Path) -> None:
    """A same-size edit of the file, or a module added to the folder."""
    if user == "source listing":
        (path / "n.py").write_text("y = 2\n")
    else:
        path.write_bytes(path.read_bytes().replace(b"1", b"7"))


@pytest.mark.parametrize("user", USERS)
def test_a_write_in_the_tick_of_a_server_whose_clock_is_ahead_is_seen(
        user: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Fails before (the second call served what the first read). The file system's clock is
    10 s ahead of ours (a file server's) and two writes land in one of its ticks: each call
    must read again."""
    path, call, reads = _user(user, tmp_path, monkeypatch)
    _clock(monkeypatch, _tick(monkeypatch, path) - 10 * SECOND_NS)
    first = call()
    _edit(user, path)
    assert call() != first
    assert len(reads) == 2, reads


@pytest.mark.parametrize("user", USERS)
@pytest.mark.parametrize("racy_call", [False, True], ids=["unseen", "seen racy"])
def test_a_write_after_the_clock_stepped_back_into_a_kept_tick_is_seen(
        user: str, racy_call: bool, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Fails before, and before h108. Kept 3 s after the file's tick; the clock set back
    2.5 s (NTP), a same-size write in that tick (called then or not), and 3 s on: the
    status is as it was kept, the new bytes must be read."""
    path, call, reads = _user(user, tmp_path, monkeypatch)
    tick_ns = _tick(monkeypatch, path)
    clock = _clock(monkeypatch, tick_ns + 3 * SECOND_NS)
    monotonic = [0]  # no step moves it
    monkeypatch.setattr(file_digest, "monotonic_ns", lambda: monotonic[0])
    first = call()
    assert (call(), len(reads)) == (first, 1)
    clock[0] = tick_ns + SECOND_NS // 2
    _edit(user, path)
    if racy_call:
        assert call() != first
    clock[0] += 3 * SECOND_NS
    monotonic[0] += 3 * SECOND_NS
    assert call() != first


@pytest.mark.parametrize("user", USERS[:2])
def test_a_write_in_the_tick_of_the_mtime_is_seen_where_the_ctime_stays(
        user: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Fails with the rule judging the ctime alone. A file system whose ctime does not follow
    writes (Linux's vfat driver long read it from the creation time): half a second after a
    write its mtime is racy, so nothing is kept, and a same-size write in the same tick is
    read 3 s later."""
    path, call, reads = _user(user, tmp_path, monkeypatch)
    tick_ns = path.stat().st_mtime_ns
    status = file_digest._status
    monkeypatch.setattr(file_digest, "_status", lambda st: (*status(st)[:3], tick_ns, 0))
    clock = _clock(monkeypatch, tick_ns + SECOND_NS // 2)
    first = call()
    _edit(user, path)
    clock[0] = tick_ns + 3 * SECOND_NS
    assert call() != first


def test_no_status_is_settled_on_windows(tmp_path: Path,
                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """``st_ctime`` is the creation time there, which a write does not change: nothing is
    kept, each call reads."""
    path = tmp_path / "a.dat"
    path.write_bytes(b"1\n")
    monkeypatch.setattr(file_digest, "RACY_NS", -10**18)  # any other status is settled
    assert file_digest.settled_status(path) is not None
    reads: list[int] = []
    read: Callable[[], int] = lambda: reads.append(1) or len(reads)  # noqa: E731
    monkeypatch.setattr(file_digest, "os", types.SimpleNamespace(name="nt", stat=os.stat))
    assert file_digest.settled_status(path) is None
    assert [file_digest.cached_read({}, path, read)[1] for _ in "ab"] == [1, 2]


def test_a_pause_between_the_two_clocks_readings_is_no_step_back(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A thread paused (5 ms) after reading the clock, before reading the monotonic clock,
    is not taken for a step back (what was kept is given again): on this 2-core machine,
    3 million readings in a row saw such pauses of up to 4 ms."""
    path, call, reads = _user("file_sha256", tmp_path, monkeypatch)
    now = [path.stat().st_ctime_ns + 3 * SECOND_NS]
    pause = [0]

    def clock() -> int:
        read = now[0]
        now[0] += pause[0]
        return read

    monkeypatch.setattr(file_digest, "time", types.SimpleNamespace(time_ns=clock))
    monkeypatch.setattr(file_digest, "monotonic_ns", lambda: now[0])
    first = call()
    pause[0] = 5_000_000
    assert (call(), call(), len(reads)) == (first, first, 1)


def test_a_folder_that_could_not_be_listed_is_listed_the_next_time(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Kept as h108 left it (before h108 the empty listing of a settled folder that could not
    be listed, out of file handles, was kept until the folder changed: its modules left out
    of the key)."""
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "m.py").write_text("x = 1\n")
    monkeypatch.setattr(file_digest, "RACY_NS", -10**18)  # every status settled
    monkeypatch.setattr(source_files, "_FOLDERS", {})
    monkeypatch.setattr(source_files, "_LISTED", {})
    scandir = os.scandir

    def out_of_handles(folder: str):  # noqa: ANN202
        raise OSError(errno.EMFILE, "Too many open files")

    monkeypatch.setattr(source_files.os, "scandir", out_of_handles)
    assert source_files.py_files(str(tmp_path / "pkg")) == []
    monkeypatch.setattr(source_files.os, "scandir", scandir)
    assert [rel for rel, _ in source_files.py_files(str(tmp_path / "pkg"))] == ["m.py"]
