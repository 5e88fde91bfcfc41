"""h80: ``OUT/estimates`` linked to a folder on a bigger disk (``ln -s /big/est
OUT/estimates``). The first compare wrote through the link; every later one was refused ("which
is a link to ...": a link on the way was taken for a link at the file), and its stale files
would never have been removed. A link to a folder on the way now works on every compare, the
manifest naming the folder it led to; a link at a file name stays refused (h67), and so does a
file reached through a link that led elsewhere when compare wrote it (a copy is not proof)."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import pytest

import _compare_folder
from bomgraph.bench import Executor
from bomgraph.cli import main
from bomgraph.experiments import Arm, Experiment
from bomgraph.out_folder import MANIFEST
from bomgraph.report import compare
from bomgraph.sim import SimConfig
from bomgraph.stdio import folder_lock


stream = _compare_folder.stream   # the fixture

_EST = Path("streams")            # estimates/EXPERIMENT (the experiment of --streams)


def _cmd(stream: Path, out: Path, methods: str = "triangulate,stmds-smacof") -> list[str]:
    return _compare_folder.linked_cmd(stream, out, methods)


def _linked(tmp_path: Path, name: str = "out", target: str = "big") -> tuple[Path, Path]:
    """``tmp_path/name`` with ``estimates`` a link to the folder ``tmp_path/target``."""
    out, big = tmp_path / name, tmp_path / target
    out.mkdir()
    big.mkdir(exist_ok=True)
    (out / "estimates").symlink_to(big)
    return out, big


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != ".bomgraph.lock"}


_one_error = _compare_folder.one_error


def test_a_linked_estimates_folder_works_on_every_compare(tmp_path: Path, stream: Path,
                                                          capsys: pytest.CaptureFixture
                                                          ) -> None:
    """The brief's reproduction: rc 0, then rc 2 "which is a link to" on the same compare
    again and on one with fewer methods (fails before)."""
    out, big = _linked(tmp_path)
    mine = big / "notes.txt"
    mine.write_text("my notes\n")
    assert main(_cmd(stream, out)) == 0
    smacof = big / _EST / "stmds-smacof" / "s.est"
    assert smacof.is_file() and (big / "index.csv").is_file()
    listed = {e["path"]: e for e in json.loads((out / MANIFEST).read_text())["files"]}
    assert listed["estimates/index.csv"]["via"] == {"estimates": str(big.resolve())}
    assert "via" not in listed["results.csv"]
    assert main(_cmd(stream, out)) == 0, capsys.readouterr().err
    edited = big / _EST / "triangulate" / "mine.est"
    edited.write_text("a user's estimate beside compare's\n")
    assert main(_cmd(stream, out, "triangulate")) == 0, capsys.readouterr().err
    assert not smacof.exists() and not smacof.parent.exists()   # stale, removed as in a folder
    assert (big / _EST / "triangulate" / "s.est").is_file()
    assert mine.read_text() == "my notes\n" and edited.is_file()  # never compare's
    assert (out / "estimates").is_symlink() and big.is_dir()      # the link and its folder stay


def test_a_users_file_in_the_linked_folder_is_refused_and_kept(tmp_path: Path, stream: Path,
                                                               capsys: pytest.CaptureFixture
                                                               ) -> None:
    """At a name compare writes, on the first compare (as in a plain folder), and once an
    earlier compare's file there was changed."""
    out, big = _linked(tmp_path)
    (big / "index.csv").write_text("my index\n")
    assert main(_cmd(stream, out)) == 2
    assert "index.csv, which is not listed as compare's" in _one_error(capsys)
    (big / "index.csv").unlink()
    assert main(_cmd(stream, out)) == 0
    stale = big / _EST / "stmds-smacof" / "s.est"
    stale.write_text("edited\n")                      # changed since: never removed
    assert main(_cmd(stream, out, "triangulate")) == 0, capsys.readouterr().err
    assert stale.read_text() == "edited\n"


def test_a_link_at_a_file_name_in_the_linked_folder_stays_refused(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture) -> None:
    """h67: through a link at a file's name compare replaced a file outside its folder."""
    out, big = _linked(tmp_path)
    assert main(_cmd(stream, out)) == 0
    keep = tmp_path / "index.csv"
    (big / "index.csv").rename(keep)
    (big / "index.csv").symlink_to(keep)
    before = keep.read_bytes()
    assert main(_cmd(stream, out)) == 2
    assert "which is a link to" in _one_error(capsys)
    assert keep.read_bytes() == before


def test_a_link_pointed_elsewhere_since_proves_nothing_there(tmp_path: Path, stream: Path,
                                                             capsys: pytest.CaptureFixture
                                                             ) -> None:
    """The link changed between compares: a copy of the earlier files in the folder it leads
    to now is not compare's (removing its stale files would remove the user's copy), so the
    compare is refused, saying so; a new empty folder is written as a new one, and the files
    of the folder linked before are left alone."""
    out, big = _linked(tmp_path)
    assert main(_cmd(stream, out)) == 0
    copy = tmp_path / "copy"
    shutil.copytree(big, copy)
    before = _files(copy)
    (out / "estimates").unlink()
    (out / "estimates").symlink_to(copy)
    assert main(_cmd(stream, out, "triangulate")) == 2
    err = _one_error(capsys)
    assert f"which is a link to {copy.resolve()}" in err and str(big.resolve()) in err
    assert _files(copy) == before
    (out / "estimates").unlink()                        # a folder again: no proof either
    shutil.copytree(copy, out / "estimates")
    assert main(_cmd(stream, out, "triangulate")) == 2
    assert "now a folder" in _one_error(capsys)
    shutil.rmtree(out / "estimates")
    new = tmp_path / "new"
    new.mkdir()
    (out / "estimates").symlink_to(new)
    old = _files(big)
    assert main(_cmd(stream, out, "triangulate")) == 0, capsys.readouterr().err
    assert (new / _EST / "triangulate" / "s.est").is_file()
    assert _files(big) == old                            # stmds-smacof's left where it was


def test_two_folders_linking_one_estimates_folder(tmp_path: Path, stream: Path,
                                                  capsys: pytest.CaptureFixture) -> None:
    """Each OUT has its own lock: a compare into b could write a's files at once. The linked
    folder is locked too; and one after the other, b's compare is refused (a's files are not
    listed in b's manifest), a's files untouched."""
    a, big = _linked(tmp_path, "a")
    b, _ = _linked(tmp_path, "b")
    with folder_lock(big, "`bomgraph compare`"):       # a compare into a, running
        assert main(_cmd(stream, b)) == 2
        assert "is writing into this folder" in _one_error(capsys)
    assert not (big / "index.csv").exists()
    assert main(_cmd(stream, a)) == 0
    before = _files(big)
    assert main(_cmd(stream, b, "triangulate")) == 2
    assert "which is not listed as compare's" in _one_error(capsys)
    assert _files(big) == before


def test_a_link_to_no_folder_is_refused_saying_so(tmp_path: Path, stream: Path,
                                                  capsys: pytest.CaptureFixture) -> None:
    """The big disk not mounted: the link leads nowhere ("which is a file" before)."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "estimates").symlink_to(tmp_path / "unmounted" / "est")
    assert main(_cmd(stream, out)) == 2
    assert "which is a link to" in _one_error(capsys)
    assert not (tmp_path / "unmounted").exists()


def test_a_linked_streams_folder_and_a_link_further_down(tmp_path: Path) -> None:
    """``OUT/streams`` (a simulated run's stream) and a folder under ``estimates/`` linked: the
    same rules; the stale file under the deeper link is removed, the linked folders stay."""
    out, big = tmp_path / "out", tmp_path / "big"
    (big / "streams").mkdir(parents=True)
    (big / "tri").mkdir()
    (out / "estimates" / "t").mkdir(parents=True)
    (out / "streams").symlink_to(big / "streams")
    (out / "estimates" / "t" / "tri").symlink_to(big / "tri")
    arms = (Arm("tri", "triangulate"), Arm("tri2", "triangulate"))
    exp = Experiment("t", "test", arms, SimConfig(n_steps=40, n_landmarks=20), seed=3,
                     n_layouts=1, n_starts=1)
    for _ in range(2):
        compare([exp], out, executor=Executor("serial"), estimates=True, figures=False)
    runs = sorted(p.name for p in (big / "tri").glob("*.est"))
    assert runs and len(list((big / "streams" / "t").iterdir())) == len(runs)
    compare([replace(exp, arms=arms[1:])], out, executor=Executor("serial"), estimates=True,
            figures=False)
    assert [p.name for p in (big / "tri").iterdir()] == [".bomgraph.lock"]  # its lock
    assert (out / "estimates" / "t" / "tri").is_symlink()
    assert len(list((big / "streams" / "t").iterdir())) == len(runs)  # tri2's, still
    assert sorted(p.name for p in (out / "estimates" / "t" / "tri2").iterdir()) == runs
