"""h104: a cached result belongs to the recording's bytes as they are now. The key of a
recording imported on use (``DatasetSource``) held only its files' sizes and modification
times, so a recording replaced by other bytes of the same size with its times kept (``cp -p``,
``rsync -a``, ``touch -r``, an archive that keeps times) reused the old data's results; and a
stream file's digest and stream (``FileSource``) were kept per process by path, size and
mtime, so a long-lived session saw such a rewrite of it neither in its key nor in its runs."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np
import pytest
from dataset_excerpts import LANDMARKS, make_mrclam, rewrite_keeping_size_and_times

from bomgraph import file_digest
from bomgraph.bench import Executor, execute_counted, strip_timings, task_key
from bomgraph.experiments import Arm, Task
from bomgraph.sim import SimConfig, simulate
from bomgraph.sources import DatasetSource, FileSource
from bomgraph.stream_file import write_stream


def untimed(result: dict) -> str:
    """A result without its wall times, as text (its NaNs equal)."""
    return json.dumps(strip_timings([result]), sort_keys=True)


def moved_landmark(data: bytes) -> bytes:
    """The landmark table of :func:`make_mrclam` with landmark 6 at x = 2.1 m, not 2.0 m."""
    old = f"  6 \t {LANDMARKS[6][0]!r} \t ".encode()
    assert LANDMARKS[6][0] == 2.0 and data.count(old) == 1
    return data.replace(old, b"  6 \t 2.1 \t ")


def test_a_recording_replaced_with_its_size_and_times_kept_runs_again(tmp_path: Path) -> None:
    """A corrected landmark table (a landmark 10 cm away: the same size) copied over the old one
    with its times kept: the runs are not taken from the cache, and score against the new
    table. Unchanged, the run is taken from the cache. Before h104 the third sweep took the
    old table's result from the cache."""
    make_mrclam(tmp_path / "m")
    source = DatasetSource("mrclam", str(tmp_path / "m"), robot=1)
    task = Task("e", Arm("tri", "triangulate"), source, checkpoint_every=40)

    def sweep() -> tuple[dict, int]:
        (result,), n_cached = execute_counted([task], Executor("serial"),
                                              cache_dir=tmp_path / "cache")
        assert result["ok"], result.get("error")
        return result, n_cached

    first, n_first = sweep()
    again, n_again = sweep()
    assert (n_first, n_again) == (0, 1)
    assert untimed(again) == untimed(first)
    rewrite_keeping_size_and_times(tmp_path / "m" / "Landmark_Groundtruth.dat",
                                   moved_landmark)
    second, n_second = sweep()
    assert n_second == 0
    assert second["key"] != first["key"]
    mpe = [[c["mpe_m"] for c in r["checkpoints"]] for r in (first, second)]
    assert mpe[1] != mpe[0], mpe
    assert len(list((tmp_path / "cache").glob("*.json"))) == 2


def test_a_stream_file_rewritten_with_its_times_kept_is_seen_in_the_same_process(
        tmp_path: Path) -> None:
    """A session that keeps running: the key and the stream follow the file's bytes, not the
    path, size and mtime it had when it was first read. Before h104 both stayed the old
    file's."""
    path = tmp_path / "run.jsonl"
    write_stream(simulate(SimConfig(n_steps=20, n_landmarks=8), np.random.default_rng(0)), path)
    source = FileSource(str(path))
    key, stream = source.key(), source.stream()
    t = path.read_bytes().index(b'"odom": [') + len(b'"odom": [')
    rewrite_keeping_size_and_times(path, lambda d: d[:t] + (b"7" if d[t:t + 1] != b"7" else b"3")
                                   + d[t + 1:])
    assert source.key() != key
    assert source.stream().steps[1].odom[0] != stream.steps[1].odom[0]


@pytest.mark.parametrize("settled", [True, False], ids=["settled", "racy"])
def test_a_files_digest_is_kept_while_its_status_stays(tmp_path: Path, settled: bool,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """Hashed once while the file's status (device, inode, size, mtime, ctime) stays; any
    write changes its ctime, which ``touch -r`` does not put back, so an edit with the size
    and mtime kept is hashed again. A status changed less than RACY_NS before the hash is not
    kept: a file system with coarse timestamps keeps size, mtime and ctime through an edit
    within one tick of its clock (``racy``: such a status, the same before and after)."""
    file_digest.forget()
    path = tmp_path / "a.dat"
    path.write_bytes(b"1 2 3\n")
    if settled:  # every status counts as older than RACY_NS
        monkeypatch.setattr(file_digest, "RACY_NS", -10**18)
    else:
        now = time.time_ns()
        same_tick = (*file_digest._status(path.stat())[:3], now, now)
        monkeypatch.setattr(file_digest, "_status", lambda st: same_tick)
    reads: list[str] = []
    digest = file_digest.hashlib.file_digest
    monkeypatch.setattr(file_digest.hashlib, "file_digest",
                        lambda fh, name: reads.append(fh.name) or digest(fh, name))
    first = file_digest.file_sha256(path)
    assert file_digest.file_sha256(path) == first
    assert len(reads) == (1 if settled else 2)
    ctime = path.stat().st_ctime_ns
    rewrite_keeping_size_and_times(path, lambda d: b"1 2 4\n")
    while path.stat().st_ctime_ns == ctime:  # a coarse clock: its times set until it ticks
        st = path.stat()
        os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert path.read_bytes() == b"1 2 4\n"
    assert file_digest.file_sha256(path) != first


def test_the_key_of_a_recording_is_its_bytes_not_its_spelling(tmp_path: Path,
                                                              monkeypatch: pytest.MonkeyPatch
                                                              ) -> None:
    """The same folder named relatively or absolutely has the same key; a file's bytes
    changed (size and mtime kept) change it."""
    make_mrclam(tmp_path / "m")
    monkeypatch.chdir(tmp_path)
    arm = Arm("tri", "triangulate")
    absolute = Task("e", arm, DatasetSource("mrclam", str(tmp_path / "m"), robot=1))
    relative = Task("e", arm, DatasetSource("mrclam", "m", robot=1))
    key = task_key(absolute)
    assert task_key(relative) == key
    rewrite_keeping_size_and_times(tmp_path / "m" / "Robot1_Odometry.dat",
                                   lambda d: d.replace(b"0.08", b"0.09", 1))
    assert task_key(relative) != key and task_key(absolute) == task_key(relative)
