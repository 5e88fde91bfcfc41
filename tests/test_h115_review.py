"""h115: adversarial review of h108's one racy-clock rule (``file_digest.settled_status``).

- h108 trusted a status whose times were both far ahead of the clock ("a machine's whose clock
  is ahead"): a file on a server whose clock is ahead of ours, its timestamps in ticks of a
  second, was kept at once, and a same-size write in the same tick of the server's clock
  kept its status: the old digest (or listing) was served for the new bytes. Before h108 a
  time ahead was never settled. A ctime ahead is now never settled; an mtime ahead is, while
  the ctime is settled behind the clock.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from bomgraph import file_digest
from test_h108_racy_rule import USERS, _clock, _user

SKEW_NS = 10_000_000_000


@pytest.mark.parametrize("user", USERS)
def test_a_write_in_the_tick_of_a_server_whose_clock_is_ahead_is_seen(
        user: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Fails before (the second call served what the first read). The file system's clock is
    10 s ahead of ours (a file server's) and its times are whole ticks: two writes in one
    tick leave the file's (or folder's) status as it was; each call must read again."""
    path, call, reads = _user(user, tmp_path, monkeypatch)
    tick_ns = path.stat().st_ctime_ns  # the server's tick both writes are in
    status = file_digest._status
    monkeypatch.setattr(file_digest, "_status", lambda st: (*status(st)[:2], 0, tick_ns, tick_ns))
    _clock(monkeypatch, tick_ns - SKEW_NS)
    first = call()
    if user == "source listing":
        (path / "n.py").write_text("y = 2\n")
    else:
        path.write_bytes(path.read_bytes().replace(b"1", b"7"))
    assert call() != first
    assert len(reads) == 2, reads
