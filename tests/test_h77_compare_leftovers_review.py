"""h77, review of h75 (compare removes the temporary files killed compares left): what it must
never remove. A folder of compare's linked elsewhere (``estimates/`` on another disk) is not
inside the folder its lock covers: a file there named like a temporary one (another compare's,
writing now; a user's) was removed. A writer of another process (``bomgraph run --out
OUT/results.csv``) writing its temporary file right now had it removed under it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

import _compare_folder
from bomgraph import stdio
from bomgraph.cli import main
from bomgraph.out_folder import MANIFEST, OutputRecord
from bomgraph.stdio import AtomicOutput
from test_h75_compare_leftovers import _killed_writing


stream = _compare_folder.stream   # the fixture
_cmd = _compare_folder.compare_cmd

_TEMP = ".s.est.abcdefgh.partial"   # exactly the writer's pattern for s.est


def test_a_folder_linked_elsewhere_is_left_alone(tmp_path: Path, stream: Path) -> None:
    """Before h77 the file beside s.est in the linked folder was removed. Since h79 the
    writer of s.est there removes the ones no writer holds (killed writers' leftovers, which
    any writer of that name removes, :func:`bomgraph.claims.remove_leftovers`): another
    compare's, being written, holds its lock, as here, and stays."""
    import fcntl

    elsewhere = tmp_path / "elsewhere"
    (elsewhere / "streams" / "triangulate").mkdir(parents=True)
    theirs = elsewhere / "streams" / "triangulate" / _TEMP
    theirs.write_text("another compare's estimate, being written\n")
    out = tmp_path / "q"
    out.mkdir()
    (out / "estimates").symlink_to(elsewhere)
    with open(theirs, "rb") as held:
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)  # as its writer holds it
        assert main(_cmd(stream, out, "--estimates")) == 0
    assert theirs.read_text() == "another compare's estimate, being written\n"


def test_the_out_folder_itself_may_be_a_link(tmp_path: Path, stream: Path) -> None:
    real = tmp_path / "real"
    real.mkdir()
    out = tmp_path / "q"
    out.symlink_to(real)
    assert main(_cmd(stream, out, "--estimates")) == 0
    left = [real / ".results.csv.abcdefgh.partial",
            real / "estimates" / "streams" / "triangulate" / _TEMP,
            real / f".{MANIFEST}.abcdefgh.partial"]
    for p in left:
        p.write_text("left by a killed compare\n")
    assert main(_cmd(stream, out, "--estimates")) == 0
    assert [p for p in left if os.path.lexists(p)] == []


def test_listed_names_outside_the_folder_are_left_alone(tmp_path: Path, stream: Path) -> None:
    out = tmp_path / "q"
    assert main(_cmd(stream, out)) == 0
    outside = tmp_path / ".x.abcdefgh.partial"
    outside.write_text("mine\n")
    (tmp_path / "d").mkdir()
    absolute = tmp_path / "d" / ".y.abcdefgh.partial"
    absolute.write_text("mine\n")
    entry = '{{"path": "{}", "size": 1, "mtime_ns": 1, "sha256": "0"}}'
    lines = [(out / MANIFEST).read_text().rstrip("\n").rstrip("]}").rstrip(",\n"),
             entry.format("../x"), entry.format(tmp_path / "d" / "y")]
    (out / MANIFEST).write_text(",\n".join(lines) + "\n]}\n")
    assert OutputRecord(out).remove_leftovers([]) == 0
    assert outside.read_text() == absolute.read_text() == "mine\n"


def test_links_and_folders_named_so_are_left_alone(tmp_path: Path, stream: Path) -> None:
    out = tmp_path / "q"
    assert main(_cmd(stream, out)) == 0
    target = tmp_path / "target.csv"
    target.write_text("mine\n")
    (out / ".results.csv.abcdefgh.partial").symlink_to(target)
    (out / ".summary.csv.abcdefgh.partial").mkdir()
    (out / ".summary.csv.abcdefgh.partial" / "f").write_text("mine\n")
    assert main(_cmd(stream, out)) == 0
    assert os.path.islink(out / ".results.csv.abcdefgh.partial")
    assert target.read_text() == "mine\n"
    assert (out / ".summary.csv.abcdefgh.partial" / "f").read_text() == "mine\n"


def test_dry_run_removes_nothing(tmp_path: Path, stream: Path) -> None:
    out = tmp_path / "q"
    assert main(_cmd(stream, out)) == 0
    left = out / ".results.csv.abcdefgh.partial"
    left.write_text("left by a killed compare\n")
    assert main(_cmd(stream, out, "--dry-run")) == 0
    assert left.exists()
    assert main(_cmd(stream, out)) == 0
    assert not left.exists()


@pytest.mark.skipif(os.name != "posix", reason="the writers' lock is POSIX flock")
def test_another_processs_writer_keeps_its_temporary_file(tmp_path: Path,
                                                           stream: Path) -> None:
    """A writer still writing (another process's ``bomgraph run --out q/results.csv``; its
    temporary file open) keeps it: before h77 it was removed and the writer failed at its
    rename (FileNotFoundError) and its output was lost."""
    out = tmp_path / "q"
    out.mkdir()
    writer = AtomicOutput(out / "results.csv")
    writer.open().write("another process's output\n")
    try:
        assert OutputRecord(out).remove_leftovers([out / "results.csv"]) == 0
    finally:
        writer.commit()
    assert (out / "results.csv").read_text() == "another process's output\n"


def test_a_writer_killed_holds_nothing(tmp_path: Path, stream: Path) -> None:
    """Killed (SIGKILL) with its temporary file open and locked: the lock goes with it, and
    the next compare removes the file."""
    out = tmp_path / "q"
    assert main(_cmd(stream, out)) == 0
    code = ("import os, signal, sys\nfrom bomgraph.stdio import AtomicOutput\n"
            "AtomicOutput(sys.argv[1]).open().write('half')\n"
            "os.kill(os.getpid(), signal.SIGKILL)\n")
    env = {**os.environ, "PYTHONPATH": str(Path(stdio.__file__).parents[1])}
    proc = subprocess.run([sys.executable, "-c", code, str(out / "results.csv")], env=env)
    assert proc.returncode == -signal.SIGKILL
    assert len(list(out.glob(".results.csv.*.partial"))) == 1
    assert main(_cmd(stream, out)) == 0
    assert list(out.glob("*.partial")) == []


def test_a_leftover_of_a_name_neither_listed_nor_written_now(tmp_path: Path,
                                                            stream: Path) -> None:
    """A compare with --estimates killed writing the estimate, before it listed it, in a
    folder whose list has no estimate (the compare before wrote none), then one without
    --estimates: the estimate's temporary file was left (found by 36 kill -9 trials: 1 of
    them). Its journal names what it was writing: the next removes it."""
    out = tmp_path / "q"
    assert main(_cmd(stream, out, "--no-figures")) == 0
    _killed_writing("s.est", _cmd(stream, out, "--no-figures", "--estimates"), out)
    assert len(list(out.rglob(".s.est.*.partial"))) == 1
    assert main(_cmd(stream, out, "--no-figures")) == 0
    assert list(out.rglob("*.partial")) == []
