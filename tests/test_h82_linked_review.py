"""h82, a review of h80 (a link to a folder on the way under ``OUT``): an arm labelled ``..``
made compare write outside ``OUT`` and the linked folder (``estimates/EXP/..`` resolved
through the link) and every later compare refused; a folder reached by two real paths (a bind
mount) was locked twice, so compare refused itself; a list from a bomgraph before h80 was said
to show that the folder was no link."""

from __future__ import annotations

import fcntl
import json
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import _compare_folder
from bomgraph.bench import Executor
from bomgraph.cli import main
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.out_folder import MANIFEST, slug, unique_slugs
from bomgraph.report import compare
from bomgraph.stdio import folder_lock


stream = _compare_folder.stream   # the fixture


def _cmd(stream: Path, out: Path, methods: str = "triangulate,stmds-smacof") -> list[str]:
    return _compare_folder.linked_cmd(stream, out, methods)


_one_error = _compare_folder.one_error


def test_a_dot_or_dot_dot_is_never_a_folder_name() -> None:
    assert slug("..") not in (".", "..") and slug(".") not in (".", "..")
    assert slug("...") == "..."                                   # a plain name
    names = unique_slugs(["..", ".", "_"])
    assert len(set(names.values())) == 3 and not {".", ".."} & set(names.values())


def test_an_arm_labelled_dot_dot_writes_under_the_linked_folder(tmp_path: Path,
                                                                 stream: Path) -> None:
    """``estimates/exp`` linked to ``big/x``: the arm ``..``'s estimate went to ``big/s.est``
    (``big/x/..``), outside both, listed as ``estimates/s.est``; the next compare was refused
    ("changed since"). Fails before."""
    out, big = tmp_path / "out", tmp_path / "big"
    (out / "estimates").mkdir(parents=True)
    (big / "x").mkdir(parents=True)
    (out / "estimates" / "exp").symlink_to(big / "x")
    exp = Experiment("exp", "t", (Arm("..", "triangulate"), Arm("tri", "triangulate")),
                     sources=(FileSource(str(stream), "s"),))
    for _ in range(2):
        compare([exp], out, executor=Executor("serial"), estimates=True, figures=False)
    assert not (big / "s.est").exists() and not (out / "estimates" / "s.est").exists()
    assert sorted(p.name for p in (big / "x").iterdir()) == [".bomgraph.lock", "_", "tri"]


def test_a_folder_reached_by_two_real_paths_is_locked_once(tmp_path: Path,
                                                           stream: Path) -> None:
    """Two links to one folder through a bind mount (or names differing in case on a
    case-insensitive disk): compare locked it twice and refused itself, "another compare
    (pid <its own>) is writing into this folder", on every run. Fails before. In a mount
    namespace of its own (``unshare -m``): the mount goes with it."""
    big, alias, out = tmp_path / "big", tmp_path / "alias", tmp_path / "out"
    for d in (big, alias, out / "estimates" / "streams"):
        d.mkdir(parents=True)
    (out / "estimates" / "streams" / "triangulate").symlink_to(big)
    (out / "estimates" / "streams" / "stmds-smacof").symlink_to(alias)
    mount = f"mount --bind {shlex.quote(str(big))} {shlex.quote(str(alias))}"
    if shutil.which("unshare") is None or subprocess.run(
            ["unshare", "-m", "sh", "-c", mount], capture_output=True).returncode != 0:
        pytest.skip("needs unshare -m and mount --bind (root) to bind-mount a folder")
    code = "import sys; from bomgraph.cli import main; sys.exit(main(sys.argv[1:]))"
    script = f"{mount} && exec " + shlex.join([sys.executable, "-c", code,
                                               *_cmd(stream, out)])
    proc = subprocess.run(["unshare", "-m", "sh", "-c", script], capture_output=True,
                          text=True)
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in big.iterdir()) == [".bomgraph.lock", "s.est"]


def test_a_list_from_before_links_were_noted_is_not_said_to_show_no_link(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture) -> None:
    """A bomgraph before h80 wrote through ``estimates`` linked elsewhere and listed no
    ``via`` (version 2): still refused (where the link led is not known), but the message
    said "when that was no link". Fails before."""
    out, big = tmp_path / "out", tmp_path / "big"
    out.mkdir()
    big.mkdir()
    (out / "estimates").symlink_to(big)
    assert main(_cmd(stream, out)) == 0
    listed = json.loads((out / MANIFEST).read_text())
    for e in listed["files"]:
        e.pop("via", None)
    (out / MANIFEST).write_text(json.dumps({**listed, "version": 2}))
    before = sorted(p.name for p in big.rglob("*"))
    assert main(_cmd(stream, out)) == 2
    err = _one_error(capsys)
    assert "which is a link to" in err and "when that was no link" not in err
    assert "names no link" in err
    assert sorted(p.name for p in big.rglob("*")) == before


def test_a_linked_folder_compare_removes_files_from_is_locked_too(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture) -> None:
    """A compare without ``--estimates`` removes the earlier estimates, through the link: it
    did so without the linked folder's lock, while another folder's compare (holding it) may
    be writing the same bytes there. Refused now, nothing removed. Fails before."""
    out, big = tmp_path / "out", tmp_path / "big"
    out.mkdir()
    big.mkdir()
    (out / "estimates").symlink_to(big)
    assert main(_cmd(stream, out)) == 0
    before = sorted(p.name for p in big.rglob("*"))
    no_estimates = [a for a in _cmd(stream, out) if a != "--estimates"]
    with folder_lock(big, "`bomgraph compare`"):           # another folder's, writing there
        assert main(no_estimates) == 2
        assert "is writing into this folder" in _one_error(capsys)
    assert sorted(p.name for p in big.rglob("*")) == before
    assert main(no_estimates) == 0
    assert [p.name for p in big.iterdir()] == [".bomgraph.lock"]   # then removed, as before
    assert main(_cmd(stream, out)) == 0
    big.rename(tmp_path / "unmounted")     # the disk away: nothing to remove there, no lock
    assert main(no_estimates) == 0, capsys.readouterr().err


def test_a_link_into_another_compares_folder_locks_that_folder(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture) -> None:
    """``a/estimates/streams`` linked to ``b/estimates/streams``, a folder of another
    compare's ``b``: a compare into ``a`` locked that folder only, never ``b``, so it wrote
    there while a compare into ``b`` ran (and one into ``b`` could start while it wrote). Now
    it locks ``b`` too. Fails before."""
    a, b = tmp_path / "a", tmp_path / "b"
    assert main(_cmd(stream, b)) == 0
    (a / "estimates").mkdir(parents=True)
    (a / "estimates" / "streams").symlink_to(b / "estimates" / "streams")
    other = tmp_path / "other.jsonl"                 # other names: nothing of b's replaced
    shutil.copy(stream, other)
    before = sorted(str(p) for p in b.rglob("*"))
    with folder_lock(b, "`bomgraph compare`"):       # a compare into b, running
        assert main(_cmd(other, a)) == 2
        assert "is writing into this folder" in _one_error(capsys)
    assert sorted(str(p) for p in b.rglob("*")) == before
    assert main(_cmd(other, a)) == 0, capsys.readouterr().err
    assert (b / "estimates" / "streams" / "triangulate" / "other.est").is_file()


def test_two_compares_through_links_below_another_compares_folder_run_side_by_side(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture) -> None:
    """Stop 43's CI: a compare had once written into ``/``, so every compare through a link
    locked ``/`` (a folder above its linked one that holds a manifest) exclusively, and the
    two Python versions' suites, run side by side, refused each other's. The folder above is
    now locked shared: a compare through a link below it runs while another such holds it,
    a compare into it is still refused (and refuses them), each saying which. Fails before."""
    top = tmp_path / "top"
    assert main(_cmd(stream, top)) == 0                          # top holds a manifest
    (big := top / "mine" / "big").mkdir(parents=True)
    a = tmp_path / "a"
    a.mkdir()
    (a / "estimates").symlink_to(big)
    with open(top / ".bomgraph.lock", "rb") as held:             # another one through a link
        fcntl.flock(held, fcntl.LOCK_SH)                         # (raw: as the old code's too)
        assert main(_cmd(stream, a)) == 0, capsys.readouterr().err
        assert main(_cmd(stream, top)) == 2                      # one into top: refused
        err = _one_error(capsys)
        assert "is writing below this folder, through a link" in err and "pid" not in err
    with folder_lock(top, "`bomgraph compare`"):                 # one into top, running
        assert main(_cmd(stream, a)) == 2
        assert "is writing into this folder" in _one_error(capsys)
    assert (top / ".bomgraph.lock").read_text().strip().isdigit()  # no holder's pid lost
