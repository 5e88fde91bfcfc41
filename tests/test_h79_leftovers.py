"""A writer killed with ``kill -9`` while writing NAME left ``.NAME.XXXXXXXX.partial`` beside
it forever (only compare cleaned its own folder). Every writer now removes, when it writes
NAME, the temporary files of exactly NAME's pattern in that folder that no writer holds
(:func:`bomgraph.claims.remove_leftovers`): never a live writer's (it holds a ``flock``),
never a link or anything but a regular file, never another name's or another folder's (h79).
"""

from __future__ import annotations

import fcntl
import json
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from bomgraph import claims
from bomgraph.result_cache import read_cached, write_cached
from bomgraph.stdio import AtomicOutput, write_text

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
#: a writer that opens NAME, writes, says so and waits to be killed
_KILLED_WRITER = """
import sys, time
from bomgraph.stdio import AtomicOutput
out = AtomicOutput(sys.argv[1])
out.open().write("half of it")
out.fh.flush()
print("writing", flush=True)
time.sleep(600)
"""


def _partials(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".partial"))


def _bomgraph(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bomgraph", *args], cwd=cwd, env=ENV,
                          capture_output=True, text=True, check=False)


def test_a_writer_killed_leaves_a_temporary_file_the_next_writer_of_its_name_removes(
        tmp_path: Path) -> None:
    """kill -9 mid-write, then ``bomgraph simulate --out est.est`` (any writer of the name):
    the killed writer's file is gone, logged with -v. Fails before h79: it stayed."""
    writer = subprocess.Popen([sys.executable, "-c", _KILLED_WRITER, "est.est"], cwd=tmp_path,
                              env=ENV, stdout=subprocess.PIPE, text=True)
    try:
        assert writer.stdout.readline() == "writing\n"
        left = _partials(tmp_path)
        assert len(left) == 1 and left[0].startswith(".est.est."), left
    finally:
        writer.send_signal(signal.SIGKILL)
        writer.wait()
        writer.stdout.close()
    assert _partials(tmp_path) == left  # what kill -9 leaves
    done = _bomgraph("-v", "simulate", "--steps", "5", "--out", "est.est", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert _partials(tmp_path) == []
    assert "removed 1 temporary file(s) of" in done.stderr, done.stderr


def test_only_unheld_regular_files_of_exactly_that_name_in_that_folder(tmp_path: Path) -> None:
    """A live writer's temporary file (its lock held), a link, a folder, another name's, a
    name off the pattern and another folder's stay; the dead ones of the name go."""
    other = tmp_path / "elsewhere"
    other.mkdir()
    dead = [tmp_path / ".out.jsonl.abcdefgh.partial", tmp_path / ".out.jsonl.0_9zzzzz.partial"]
    kept = [tmp_path / ".out.jsonl.abc.partial", tmp_path / ".other.jsonl.abcdefgh.partial",
            tmp_path / ".out.jsonlx.abcdefgh.partial", other / ".out.jsonl.abcdefgh.partial",
            tmp_path / "out.jsonl.abcdefgh.partial"]
    for p in dead + kept:
        p.write_text("left")
    target = other / "victim"
    target.write_text("a user's file")
    (tmp_path / ".out.jsonl.linkedxx.partial").symlink_to(target)
    (tmp_path / ".out.jsonl.folderxx.partial").mkdir()
    live = tmp_path / ".out.jsonl.livexxxx.partial"
    live.write_text("being written")
    with open(live, "rb") as held:
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)  # as a live writer holds its own
        done = _bomgraph("simulate", "--steps", "5", "--out", "out.jsonl", cwd=tmp_path)
        assert done.returncode == 0, done.stderr
    assert not any(p.exists() for p in dead)
    assert all(p.read_text() == "left" for p in kept)
    assert live.read_text() == "being written" and target.read_text() == "a user's file"
    assert (tmp_path / ".out.jsonl.linkedxx.partial").is_symlink()
    assert (tmp_path / ".out.jsonl.folderxx.partial").is_dir()


def test_two_writers_of_one_name_never_remove_each_others_file(tmp_path: Path) -> None:
    """A writer of NAME open (its temporary file claimed) while another writes NAME, as two
    sweeps sharing a cache folder write one key: the first's file stays and is put in place
    after the second's."""
    path = tmp_path / "key.json"
    entry = {"ok": True, "key": "key", "experiment": "e", "arm": "a", "method": "m",
             "run": "r", "checkpoints": [], "total_s": 0.0, "step_median_s": 0.0, "info": {},
             "converged": None}   # of the shape read_cached accepts (h91)
    first = AtomicOutput(path)
    first.open().write(json.dumps({**entry, "who": "first"}))
    write_cached(path, {**entry, "who": "second"})
    assert read_cached(path)["who"] == "second"
    assert len(_partials(tmp_path)) == 1
    first.commit()
    assert read_cached(path)["who"] == "first" and _partials(tmp_path) == []


def test_a_file_removed_between_its_creation_and_its_claim_is_not_written_into(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The microseconds between ``mkstemp`` and the writer's lock: another writer of the same
    name may take the new, still unclaimed file for a dead one and remove it. The writer must
    then write another, not the removed one (whose rename into place fails: the output was
    lost). Fails before h79 with FileNotFoundError."""
    made = tempfile.mkstemp
    calls: list[str] = []

    def raced(*args, **kwargs):
        fd, name = made(*args, **kwargs)
        if not calls:  # the first: another writer's cleaning takes it at once
            assert claims.remove_unclaimed(name)
        calls.append(name)
        return fd, name

    monkeypatch.setattr(tempfile, "mkstemp", raced)
    write_text(tmp_path / "out.txt", "all of it")
    assert (tmp_path / "out.txt").read_text() == "all of it"
    assert len(calls) == 2 and _partials(tmp_path) == []


def test_a_file_held_by_a_remover_at_its_claim_is_let_go(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The same race the other way round: the remover holds the new file's lock when the
    writer asks for it (and removes it after). The writer takes another name."""
    made = tempfile.mkstemp
    held: list[int] = []

    def raced(*args, **kwargs):
        fd, name = made(*args, **kwargs)
        if not held:  # a remover has it locked, about to remove it
            held.append(os.open(name, os.O_RDONLY))
            fcntl.flock(held[0], fcntl.LOCK_EX | fcntl.LOCK_NB)
            os.unlink(name)
        return fd, name

    monkeypatch.setattr(tempfile, "mkstemp", raced)
    try:
        write_text(tmp_path / "out.txt", "all of it")
    finally:
        os.close(held[0])
    assert (tmp_path / "out.txt").read_text() == "all of it" and _partials(tmp_path) == []
