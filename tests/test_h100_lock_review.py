"""h100, a review of compare's folder locks (6ceb783: a folder above a linked one is locked
shared): a compare through a link locked a folder above the one it leads to only when that
folder held a manifest, so neither a compare into it still running its first time (no manifest
yet) nor one writing into it through a link of its own (its manifest is in its own folder)
kept it out, and a compare into a folder kept out none writing below it through a link; a
folder both led to by a link and above another one was locked shared or exclusive by the order
of the files; a lock file that was a link was written through."""

from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Iterator

import pytest

import _compare_folder
import bomgraph
from bomgraph import out_folder
from bomgraph.cli import main
from bomgraph.out_folder import MANIFEST
from bomgraph.stdio import folder_lock


stream = _compare_folder.stream   # the fixture
_WHO = "`bomgraph compare`"


def _cmd(stream: Path, out: Path, methods: str = "triangulate") -> list[str]:
    return _compare_folder.linked_cmd(stream, out, methods)


_one_error = _compare_folder.one_error


def test_a_link_into_a_folder_another_compare_writes_through_a_link(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture) -> None:
    """``p/estimates`` linked to ``big``, ``q/estimates/streams`` to ``big/streams``: both
    write ``big/streams/triangulate/s.est``. ``big`` holds no manifest (p's is in ``p``), so
    q never locked it, nor p ``big/streams``: both ran at once, either started first. Fails
    before."""
    big = tmp_path / "big"
    (big / "streams").mkdir(parents=True)
    (p := tmp_path / "p").mkdir()
    (p / "estimates").symlink_to(big)
    (q := tmp_path / "q" / "estimates").mkdir(parents=True)
    (q / "streams").symlink_to(big / "streams")
    with folder_lock(big, _WHO):                       # p's compare, running
        assert main(_cmd(stream, q.parent)) == 2
        assert "is writing into this folder" in _one_error(capsys)
    with folder_lock(big / "streams", _WHO):           # q's compare, running
        assert main(_cmd(stream, p)) == 2
        assert "is writing into this folder" in _one_error(capsys)
    assert not list(big.rglob("*.est"))
    assert main(_cmd(stream, p)) == 0, capsys.readouterr().err   # alone: as before


def test_a_compare_running_its_first_time_has_no_manifest_yet(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture) -> None:
    """The first compare into ``top`` writes its manifest only once its runs are done: until
    then a compare through ``b/estimates/streams`` (linked to ``top/estimates/streams``) was
    not kept out, and the compare into ``top`` was never kept out by one running through such
    a link. Both write ``top/estimates/streams/triangulate/s.est``. Fails before."""
    top = tmp_path / "top"
    (top / "estimates" / "streams").mkdir(parents=True)
    (b := tmp_path / "b" / "estimates").mkdir(parents=True)
    (b / "streams").symlink_to(top / "estimates" / "streams")
    with folder_lock(top, _WHO):                       # the first compare into top, running
        assert not (top / MANIFEST).exists()
        assert main(_cmd(stream, b.parent)) == 2
        assert "is writing into this folder" in _one_error(capsys)
    with folder_lock(top / "estimates" / "streams", _WHO):   # b's compare, running
        assert main(_cmd(stream, top)) == 2
        assert "is writing into this folder" in _one_error(capsys)
    assert not list(top.rglob("*.est"))
    assert main(_cmd(stream, top)) == 0, capsys.readouterr().err


def test_a_compare_into_a_folder_above_starting_while_one_takes_its_locks(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The race: the first compare into ``top`` starts after one through ``b``'s link (to
    ``top/estimates/streams``) looked for locks above the folder it leads to, before it locked
    that folder: neither saw the other's lock. The folders above are looked at again once the
    linked one is held. Fails before (and without that second look)."""
    top = tmp_path / "top"
    (top / "estimates" / "streams").mkdir(parents=True)
    (b := tmp_path / "b" / "estimates").mkdir(parents=True)
    (b / "streams").symlink_to(top / "estimates" / "streams")
    lock, linked = out_folder.folder_lock, os.path.realpath(top / "estimates" / "streams")

    @contextlib.contextmanager
    def racing(folder: str, what: str, shared: bool = False) -> Iterator[None]:
        if os.path.realpath(folder) == linked and not shared:   # top's compare starts now
            into_top.enter_context(lock(top, _WHO))
        with lock(folder, what, shared):
            yield

    monkeypatch.setattr(out_folder, "folder_lock", racing)
    with contextlib.ExitStack() as into_top:
        assert main(_cmd(stream, b.parent)) == 2
        assert "is writing into this folder" in _one_error(capsys)
    assert not list(top.rglob("*.est"))


def test_a_folder_led_to_and_above_another_is_locked_exclusive_whatever_the_order(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture) -> None:
    """``estimates/streams/triangulate`` linked to ``x/sub`` and ``.../stmds-smacof`` to
    ``x``, a folder another compare wrote: the first file's link made ``x`` a folder above
    (shared) and the second's, which writes into ``x``, was not locked again: ``x`` was
    locked shared, so a compare writing below ``x`` through a link (shared too) ran beside
    one writing into it. Fails before."""
    x = tmp_path / "x"
    assert main(_cmd(stream, x)) == 0                  # another compare's folder
    (x / "sub").mkdir()
    (o := tmp_path / "o" / "estimates" / "streams").mkdir(parents=True)
    (o / "triangulate").symlink_to(x / "sub")
    (o / "stmds-smacof").symlink_to(x)
    capsys.readouterr()
    with open(x / ".bomgraph.lock", "rb") as held:     # one writing below x, through a link
        fcntl.flock(held, fcntl.LOCK_SH)
        assert main(_cmd(stream, o.parent.parent, "triangulate,stmds-smacof")) == 2
        assert "is writing below this folder" in _one_error(capsys)
    assert not (x / "s.est").exists()
    assert main(_cmd(stream, o.parent.parent, "triangulate,stmds-smacof")) == 0
    assert (x / "s.est").is_file() and (x / "sub" / "s.est").is_file()


@pytest.mark.parametrize("target", ["notes", "missing"])
def test_a_lock_file_that_is_a_link_is_refused_not_written_through(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture, target: str) -> None:
    """``OUT/.bomgraph.lock`` a link to a user's file of digits: compare emptied it and wrote
    its pid there (a file's own lock is refused if it holds anything but a pid, h67); a link
    to no file made one there. Refused now, as any lock that is not a plain file. Fails
    before."""
    (out := tmp_path / "out").mkdir()
    notes = tmp_path / target
    if target == "notes":
        notes.write_text("7\n")
    (out / ".bomgraph.lock").symlink_to(notes)
    assert main(_cmd(stream, out)) == 2
    assert "is not a bomgraph lock" in _one_error(capsys)
    assert (notes.read_text() == "7\n") if target == "notes" else not notes.exists()
    assert not (out / "results.csv").exists()


def test_a_folder_above_of_another_user_is_locked_shared_without_writing_to_it(
        tmp_path: Path, stream: Path) -> None:
    """Another user's compare through a link below a folder whose compare lock is not theirs
    (-rw-r--r--) failed, "[Errno 13] Permission denied: TOP/.bomgraph.lock": the shared lock
    opened it to write. So did every compare of a user through a link once root had compared
    into ``/`` (stop 43's CI). Read only now. Fails before. Here the lock belongs to uid 65534
    and the compare runs as root without the capabilities that override file permissions
    (``setpriv --bounding-set``), so the interpreter and the code stay readable to it."""
    if os.geteuid() != 0 or shutil.which("setpriv") is None:
        pytest.skip("needs root and setpriv to run a compare without override capabilities")
    assert main(_cmd(stream, tmp_path / "top")) == 0
    lock = tmp_path / "top" / ".bomgraph.lock"
    os.chown(lock, 65534, 65534)                                 # another user's compare's
    lock.chmod(0o644)
    (tmp_path / "top" / "sub").mkdir()
    (tmp_path / "u" / "out").mkdir(parents=True)
    (tmp_path / "u" / "out" / "estimates").symlink_to(tmp_path / "top" / "sub")
    no_override = ["setpriv", "--bounding-set=-dac_override,-dac_read_search,-fowner",
                   "--inh-caps=-dac_override,-dac_read_search,-fowner", sys.executable, "-c"]
    env = {**os.environ, "PYTHONPATH": str(Path(bomgraph.__file__).parent.parent)}
    probe = subprocess.run([*no_override, f"open({str(lock)!r}, 'r+')"], env=env,
                           capture_output=True, text=True)
    assert "Permission denied" in probe.stderr, probe.stderr   # the capabilities are gone
    code = "import sys; from bomgraph.cli import main; sys.exit(main(sys.argv[1:]))"
    proc = subprocess.run([*no_override, code, *_cmd(stream, tmp_path / "u" / "out")],
                          env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "top" / "sub" / "streams" / "triangulate" / "s.est").is_file()
    assert lock.stat().st_uid == 65534 and lock.stat().st_mode & 0o777 == 0o644
