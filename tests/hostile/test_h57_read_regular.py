"""``stdio.read_regular_file`` (opened without blocking since h55): a regular file is read
whole, and what it refuses leaves no file descriptor open."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from bomgraph.stdio import read_regular_file

_FDS = Path("/proc/self/fd")


def test_a_regular_file_is_read_whole(tmp_path: Path) -> None:
    data = os.urandom(3 << 20)   # more than one 1 MiB chunk
    (tmp_path / "f").write_bytes(data)
    assert read_regular_file(tmp_path / "f") == data


@pytest.mark.skipif(not _FDS.is_dir(), reason="counts descriptors in /proc/self/fd")
def test_refusing_a_directory_fifo_or_device_leaves_no_descriptor_open(tmp_path: Path) -> None:
    """A folder was opened with ``os.open`` (which succeeds on a folder), then ``open(fd)``
    raised IsADirectoryError without closing it: one descriptor leaked a call."""
    os.mkfifo(tmp_path / "p")
    for path in (tmp_path, tmp_path / "p", Path(os.devnull)):
        before = len(os.listdir(_FDS))
        for _ in range(5):
            with pytest.raises(OSError) as info:
                read_regular_file(path)
            assert info.value.strerror
        assert len(os.listdir(_FDS)) == before, path
