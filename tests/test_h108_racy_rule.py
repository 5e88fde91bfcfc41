"""h108: one rule for trusting a file's status, used by every reader that keeps what it read.

``file_digest.file_sha256`` (a recording's or a stream's bytes) and ``plugins``' source
digests and folder listings each had their own ``RACY_NS``, status and ``_aged``: the tests
set each module's knob apart, and one could change without the other. The rule is now
``file_digest.settled_status`` and ``cached_read``, and its one knob ``file_digest.RACY_NS``;
the source files' readers moved to ``bomgraph.source_files``. A fake clock here (no timing),
as tests/test_h105_review.py's: the status is the file's own.

A file whose mtime is ahead of the clock (``touch -d tomorrow``, an archive's) was never
settled, so it was read at every call: 50 digests of a 20 MB file took 26 ms with its mtime
an hour back and 792 ms with it a day ahead (kept: True / False). An mtime far ahead of the
clock is settled while it stays ahead (a ctime ahead never is: tests/test_h115_review.py).
"""

from __future__ import annotations

import hashlib
import os
import time
import types
from pathlib import Path
from typing import Callable

import pytest

from bomgraph import file_digest, source_files

USERS = ["file_sha256", "source digest", "source listing"]


def _user(name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
          ) -> tuple[Path, Callable[[], object], list[str]]:
    """A file (or folder) read by the user ``name``, the call that reads it through the rule,
    and the list of its reads so far (each read appends its path), with nothing kept yet."""
    reads: list[str] = []
    if name == "file_sha256":
        path = tmp_path / "a.dat"
        path.write_bytes(b"1 2 3\n")
        digest = hashlib.file_digest
        monkeypatch.setattr(file_digest.hashlib, "file_digest",
                            lambda fh, alg: reads.append(fh.name) or digest(fh, alg))
        monkeypatch.setattr(file_digest, "_KEPT", {})
        return path, lambda: file_digest.file_sha256(path), reads
    if name == "source digest":
        path = tmp_path / "m.py"
        path.write_bytes(b"x = 1\n")
        read = source_files.read
        monkeypatch.setattr(source_files, "read", lambda p: reads.append(str(p)) or read(p))
        monkeypatch.setattr(source_files, "_DISK", {})
        return path, lambda: source_files.disk_digest(path), reads
    path = tmp_path / "pkg"
    path.mkdir()
    (path / "m.py").write_text("x = 1\n")
    list_code = source_files._list_code
    monkeypatch.setattr(source_files, "_list_code",
                        lambda folder: reads.append(folder) or list_code(folder))
    monkeypatch.setattr(source_files, "_FOLDERS", {})
    monkeypatch.setattr(source_files, "_LISTED", {})
    return path, lambda: source_files.py_files(str(path)), reads


def _clock(monkeypatch: pytest.MonkeyPatch, at_ns: int) -> list[int]:
    """The rule's clock, stopped at ``at_ns`` (set ``[0]`` to move it), and the monotonic
    clock stopped too (the clock stopped alone looks stepped back: ``_read_clock``)."""
    clock = [at_ns]
    monkeypatch.setattr(file_digest, "time", types.SimpleNamespace(time_ns=lambda: clock[0]))
    monkeypatch.setattr(file_digest, "monotonic_ns", lambda: 0)
    return clock


def _changed_ns(path: Path) -> int:
    st = path.stat()
    return max(st.st_mtime_ns, st.st_ctime_ns)


@pytest.mark.parametrize("user", USERS)
@pytest.mark.parametrize(("racy_ns", "reads_of_two"), [(2_000_000_000, 2), (100_000_000, 1)],
                         ids=["racy", "settled"])
def test_one_knob_governs_every_reader_of_a_status(
        user: str, racy_ns: int, reads_of_two: int, tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Half a second after the file's change, read twice: with ``file_digest.RACY_NS`` 2 s
    its status is racy and it is read twice; with 0.1 s it is settled and read once. Fails
    if a reader stops following the rule (keeps a racy status, or reads its own knob or
    clock: its own 2 s on the real clock, a few ms after the write, reads twice)."""
    path, call, reads = _user(user, tmp_path, monkeypatch)
    _clock(monkeypatch, _changed_ns(path) + 500_000_000)
    monkeypatch.setattr(file_digest, "RACY_NS", racy_ns)
    first = call()
    assert call() == first
    assert len(reads) == reads_of_two, reads


DAY_NS = 86_400 * 10**9


@pytest.mark.parametrize("user", USERS)
def test_a_time_far_ahead_of_the_clock_is_settled_while_it_stays_ahead(
        user: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Fails before (read at every call). An mtime a day ahead: once the ctime is settled,
    read once; within RACY_NS of the clock, racy (read at each call, nothing kept); past
    it, what was kept while it was ahead does not count (a write in its tick can leave the
    status as it was: the next test), and the status settled now is kept anew."""
    path, call, reads = _user(user, tmp_path, monkeypatch)
    ahead_ns = time.time_ns() + DAY_NS
    os.utime(path, ns=(ahead_ns, ahead_ns))
    clock = _clock(monkeypatch, path.stat().st_ctime_ns + 3_000_000_000)
    first = call()
    assert (call(), len(reads)) == (first, 1)
    clock[0] = ahead_ns - 1_000_000_000
    assert (call(), call(), len(reads)) == (first, first, 3)
    clock[0] = ahead_ns + 3_000_000_000
    assert (call(), call(), len(reads)) == (first, first, 4)


@pytest.mark.parametrize("user", USERS[:2])
def test_a_write_in_the_tick_of_a_time_set_ahead_is_seen_where_the_ctime_stays(
        user: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A file system whose ctime does not follow writes (Linux's vfat driver long read it
    from the file's creation time) tells a write by its mtime alone. A digest kept while the
    mtime was a day ahead, then a same-size write when the clock is in that mtime's tick (the
    file keeps its status): an hour later the new bytes are read. Fails with a time ahead
    settled without the status saying it was ahead (with the rule judging the ctime alone,
    the "ahead" flag still catches it here: tests/test_h115_review.py's mtime test)."""
    path, call, reads = _user(user, tmp_path, monkeypatch)
    status = file_digest._status
    monkeypatch.setattr(file_digest, "_status", lambda st: (*status(st)[:4], 0))
    ahead_ns = time.time_ns() + DAY_NS
    os.utime(path, ns=(ahead_ns, ahead_ns))
    clock = _clock(monkeypatch, time.time_ns())
    first = call()
    assert (call(), len(reads)) == (first, 1)
    data = path.read_bytes()
    path.write_bytes(data.replace(b"1", b"7"))  # written in the tick of ahead_ns:
    os.utime(path, ns=(ahead_ns, ahead_ns))     # its mtime is ahead_ns
    clock[0] = ahead_ns + 3_600 * 10**9
    assert call() != first


def test_code_written_into_a_linked_folder_during_its_listing_is_listed_next_time(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Fails before. A link to a folder without code is passed over and its status watched
    (h57: the first module written into it lists it). That status was taken after the
    listing: a module written in between, and the status then settled (the listing "takes"
    3 s here, a fake clock), was kept with a listing without it, so it was never listed."""
    root = tmp_path / "pkg"
    root.mkdir()
    (root / "m.py").write_text("x = 1\n")
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "x.csv").write_text("1\n")
    os.symlink(tmp_path / "data", root / "data")
    monkeypatch.setattr(source_files, "_FOLDERS", {})
    monkeypatch.setattr(source_files, "_LISTED", {})
    clock = _clock(monkeypatch, max(_changed_ns(root), _changed_ns(tmp_path / "data"))
                   + 3_000_000_000)
    scandir = os.scandir

    def slow_scandir(folder: str):  # noqa: ANN202
        entries = list(scandir(folder))
        if folder == str(root / "data"):
            (tmp_path / "data" / "new.py").write_text("y = 2\n")
            clock[0] = _changed_ns(tmp_path / "data") + 3_000_000_000
        return iter(entries)

    monkeypatch.setattr(source_files.os, "scandir", slow_scandir)
    assert [rel for rel, _ in source_files.py_files(str(root))] == ["m.py"]
    monkeypatch.setattr(source_files.os, "scandir", scandir)
    assert sorted(rel for rel, _ in source_files.py_files(str(root))) == ["data/new.py", "m.py"]
