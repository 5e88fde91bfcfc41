"""``compare --out DIR`` replaces a file in DIR only if an earlier compare wrote it, unchanged
since (its manifest, :class:`bomgraph.out_folder.OutputRecord`); any other file at a name it
writes is refused before anything runs, in one line, exit 2 (h61: a user's ``results.csv``
was silently replaced)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

import _compare_folder
from bomgraph import report
from bomgraph.bench import Executor
from bomgraph.cli import main
from bomgraph.experiments import Arm, Experiment, compare_experiments
from bomgraph.out_folder import MANIFEST
from bomgraph.report import compare
from bomgraph.sim import SimConfig
from bomgraph.stdio import OutputPathError

SMALL = SimConfig(n_steps=40, n_landmarks=20)


def _exp(name: str = "t") -> Experiment:
    return Experiment(name, "test", (Arm("tri", "triangulate"),), SMALL, seed=3, n_layouts=1,
                      n_starts=1)


stream = _compare_folder.stream   # the fixture
_cmd = _compare_folder.compare_cmd


def test_a_users_file_named_as_compare_names_its_results_is_refused_before_anything_runs(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture) -> None:
    """The brief's reproduction: rc 0 and the user's results.csv replaced by compare's."""
    out = tmp_path / "out"
    out.mkdir()
    mine = out / "results.csv"
    mine.write_text("my,data\n")
    capsys.readouterr()
    assert main(_cmd(stream, out)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(mine) in err[0] and "move it or choose another folder" in err[0]
    assert mine.read_text() == "my,data\n"
    assert sorted(p.name for p in out.iterdir()) == ["results.csv"]  # nothing ran or was written
    assert main(_cmd(stream, out, "--dry-run")) == 2          # what compare refuses, so does it


@pytest.mark.parametrize("name", ["summary.csv", "paired.csv", "results.json",
                                  "streams_s_maps.png", "streams_error_vs_time.png"])
def test_every_name_compare_writes_is_refused_when_it_is_a_users(
        tmp_path: Path, stream: Path, name: str) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / name).write_bytes(b"mine")
    (out / "notes.png").write_bytes(b"not a name compare writes")
    chosen, _ = compare_experiments(streams=[str(stream)], methods="triangulate")
    with pytest.raises(OutputPathError, match=f"{name}, which is not listed as compare.s"):
        compare(chosen, out, executor=Executor("serial"))
    assert (out / name).read_bytes() == b"mine"
    (out / name).unlink()
    compare(chosen, out, executor=Executor("serial"))
    assert (out / "notes.png").read_bytes() == b"not a name compare writes"


def test_a_users_estimates_and_cache_folders(tmp_path: Path, stream: Path) -> None:
    """A user's own folder named estimates: compare adds its files, refuses to replace one of
    theirs (index.csv), and never removes the others; a file named cache is refused."""
    out = tmp_path / "out"
    (out / "estimates").mkdir(parents=True)
    (out / "estimates" / "index.csv").write_text("mine\n")
    (out / "estimates" / "notes.txt").write_text("mine\n")
    chosen, _ = compare_experiments(streams=[str(stream)], methods="triangulate")
    with pytest.raises(OutputPathError, match="index.csv, which is not listed as compare.s"):
        compare(chosen, out, executor=Executor("serial"), estimates=True)
    compare(chosen, out, executor=Executor("serial"))                 # no estimates: no clash
    (out / "estimates" / "index.csv").rename(out / "estimates" / "my-index.csv")
    compare(chosen, out, executor=Executor("serial"), estimates=True)
    compare(chosen, out, executor=Executor("serial"))          # removes compare's estimates only
    assert sorted(p.name for p in (out / "estimates").iterdir()) == ["my-index.csv", "notes.txt"]
    cache = tmp_path / "c2" / "cache"
    cache.parent.mkdir()
    cache.write_text("mine\n")
    with pytest.raises(OutputPathError, match="cache, which is a file"):
        compare(chosen, cache.parent, executor=Executor("serial"))
    compare(chosen, cache.parent, executor=Executor("serial"), use_cache=False)
    assert cache.read_text() == "mine\n"


def test_compare_twice_and_a_result_edited_in_between(tmp_path: Path, stream: Path) -> None:
    """The README's `bomgraph compare --out compare-results`, twice: the second replaces the
    first's files; a file the user changed since is refused, by content (size and SHA-256),
    even with its old modification time put back."""
    out = tmp_path / "out"
    chosen, _ = compare_experiments(streams=[str(stream)], methods="triangulate")
    compare(chosen, out, executor=Executor("serial"))
    compare(chosen, out, executor=Executor("serial"))
    csv = out / "summary.csv"
    st = csv.stat()
    text = csv.read_text()
    csv.write_text(text.replace("triangulate", "triangulatE"))          # same size
    os.utime(csv, ns=(st.st_atime_ns, st.st_mtime_ns))
    with pytest.raises(OutputPathError, match="summary.csv, which was changed since"):
        compare(chosen, out, executor=Executor("serial"))
    assert "triangulatE" in csv.read_text()


def test_an_interrupted_compare_leaves_its_files_proved(tmp_path: Path, stream: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C while the figures are drawn: the results are written, the final manifest is
    not; the files written so far are in the journal, so a re-run replaces them."""
    out = tmp_path / "out"
    chosen, _ = compare_experiments(streams=[str(stream)], methods="triangulate")
    real = report.write_figure

    def interrupted(fig: object, path: Path, dpi: int, ready: object = None) -> str:
        if "maps" in str(path):
            raise KeyboardInterrupt
        return real(fig, path, dpi, ready=ready)

    monkeypatch.setattr(report, "write_figure", interrupted)
    with pytest.raises(KeyboardInterrupt):
        compare(chosen, out, executor=Executor("serial"))
    assert (out / "streams_error_vs_time.png").exists()
    monkeypatch.undo()
    compare(chosen, out, executor=Executor("serial"))
    listed = json.loads((out / MANIFEST).read_text())["files"]
    assert {e["path"] for e in listed} >= {"results.csv", "streams_s_maps.png"}


#: a compare killed (SIGKILL) the moment its results.json is in place, before anything more
_KILLED_AFTER_RESULTS = """
import os, signal, sys
real = os.replace
def replace(src, dst, **kw):
    real(src, dst, **kw)
    if os.path.basename(dst) == "results.json":
        os.kill(os.getpid(), signal.SIGKILL)
os.replace = replace
from bomgraph.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_a_compare_killed_as_a_file_takes_its_name_leaves_it_proved(tmp_path: Path,
                                                                     stream: Path) -> None:
    """kill -9 (or Ctrl-C) between a file's rename into place and its line in the journal
    left a file that nothing listed: every later compare refused its own folder ("which was
    changed since an earlier compare wrote it"). A file is now listed before it is renamed
    (h67; fails before)."""
    out = tmp_path / "out"
    assert main(_cmd(stream, out, "--no-figures")) == 0
    env = {**os.environ, "PYTHONPATH": str(Path(report.__file__).parents[1])}
    proc = subprocess.run([sys.executable, "-c", _KILLED_AFTER_RESULTS,
                           *_cmd(stream, out, "--no-figures")], env=env, capture_output=True)
    assert proc.returncode == -signal.SIGKILL
    assert main(_cmd(stream, out, "--no-figures")) == 0


@pytest.mark.parametrize("link", ["summary.csv", "estimates"])
def test_a_link_at_a_name_compare_writes_is_refused(tmp_path: Path, stream: Path,
                                                    link: str) -> None:
    """The user keeps a compare's file (or its estimates) elsewhere, linked back: its content
    is what compare wrote, so compare wrote through the link and replaced the user's copy,
    outside the folder (h67; fails before)."""
    out, keep = tmp_path / "out", tmp_path / "keep"
    keep.mkdir()
    chosen, _ = compare_experiments(streams=[str(stream)], methods="triangulate,ekf")
    compare(chosen, out, executor=Executor("serial"), estimates=True)
    (out / link).rename(keep / link)
    (out / link).symlink_to(keep / link)
    before = {p: p.read_bytes() for p in keep.rglob("*") if p.is_file()}
    with pytest.raises(OutputPathError, match="which is a link to .*keep"):
        compare(chosen, out, executor=Executor("serial"), estimates=True)
    assert {p: p.read_bytes() for p in keep.rglob("*") if p.is_file()} == before


def test_a_folder_of_an_older_bomgraph(tmp_path: Path, stream: Path) -> None:
    """Without a manifest nothing proves a file compare's: refused, saying so; with the
    manifest of version 1 (size and modification time) the files it lists are replaced; a
    file of that name that is no manifest is refused."""
    out = tmp_path / "out"
    chosen, _ = compare_experiments(streams=[str(stream)], methods="triangulate")
    compare(chosen, out, executor=Executor("serial"))
    listed = json.loads((out / MANIFEST).read_text())["files"]
    v1 = [{k: e[k] for k in ("path", "size", "mtime_ns")} for e in listed]
    (out / MANIFEST).write_text(json.dumps({"format": "bomgraph-compare-files", "version": 1,
                                            "files": v1}, indent=0))
    compare(chosen, out, executor=Executor("serial"))
    (out / MANIFEST).unlink()
    with pytest.raises(OutputPathError, match=f"has no {MANIFEST}: not compare's, or an older"):
        compare(chosen, out, executor=Executor("serial"))
    (out / MANIFEST).write_text("my notes\n")
    with pytest.raises(OutputPathError, match="is not the list of files bomgraph compare"):
        compare(chosen, out, executor=Executor("serial"))
    assert (out / MANIFEST).read_text() == "my notes\n"


def test_the_designed_experiments_figures_too(tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "example_map.png").write_bytes(b"mine")
    with pytest.raises(OutputPathError, match="example_map.png, which is not listed as compare.s"):
        compare([_exp()], out, executor=Executor("serial"))
    with pytest.raises(OutputPathError, match="example_map.png"):
        report.plan_compare([_exp()], out)
    compare([_exp()], out, executor=Executor("serial"), figures=False)
    assert (out / "example_map.png").read_bytes() == b"mine"


def test_a_users_file_named_as_the_folder_lock_is_not_emptied(tmp_path: Path) -> None:
    """compare truncated OUT/.bomgraph.lock to write its pid, whatever the file held."""
    out = tmp_path / "out"
    out.mkdir()
    (out / ".bomgraph.lock").write_text("my notes\n")
    with pytest.raises(OutputPathError, match="is not a bomgraph lock"):
        compare([_exp()], out, executor=Executor("serial"), figures=False)
    assert (out / ".bomgraph.lock").read_text() == "my notes\n"
    (out / ".bomgraph.lock").write_text("12345\n")                # a lock of an earlier run
    compare([_exp()], out, executor=Executor("serial"), figures=False)


@pytest.mark.parametrize("kind", ["digits first", "fifo", "folder"])
def test_a_lock_that_is_no_pid_file_is_refused_naming_it(tmp_path: Path, kind: str) -> None:
    """Only the first 65 bytes were judged: a file of 70 digits and then notes was emptied;
    a FIFO there was "bomgraph: error: [Errno 29] Illegal seek" (h67; fails before)."""
    out = tmp_path / "out"
    out.mkdir()
    lock = out / ".bomgraph.lock"
    if kind == "fifo":
        os.mkfifo(lock)
    elif kind == "folder":
        lock.mkdir()
    else:
        lock.write_text("1" * 70 + "\nmy notes\n")
    with pytest.raises(OutputPathError, match="bomgraph.lock: is not a bomgraph lock"):
        compare([_exp()], out, executor=Executor("serial"), figures=False)
    if kind == "digits first":
        assert lock.read_text() == "1" * 70 + "\nmy notes\n"


def test_dry_run_refuses_what_compare_would(tmp_path: Path, stream: Path,
                                            capsys: pytest.CaptureFixture) -> None:
    """--dry-run says what compare would refuse; a user's figure is no clash without
    figures."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "streams_s_maps.png").write_bytes(b"mine")
    assert main(_cmd(stream, out, "--dry-run")) == 2
    assert "streams_s_maps.png, which is not listed as compare's" in capsys.readouterr().err
    assert main(_cmd(stream, out, "--dry-run", "--no-figures")) == 0
    assert main(_cmd(stream, out, "--no-figures")) == 0
    assert (out / "streams_s_maps.png").read_bytes() == b"mine"


def _args(stream: Path, out: str, dry_run: bool) -> list[str]:
    """A one-arm compare (or its dry run) writing to ``--out out``."""
    return ["compare", "--streams", str(stream), "--methods", "triangulate", "--jobs", "1",
            "--no-figures", "--out", out] + (["--dry-run"] if dry_run else [])


def _refused(stream: Path, out: str, dry_run: bool, capsys: pytest.CaptureFixture) -> list[str]:
    """:func:`_args` run: exit 2 asserted; its stderr lines."""
    assert main(_args(stream, out, dry_run)) == 2
    return capsys.readouterr().err.strip().splitlines()


@pytest.mark.parametrize("dry_run", [False, True])
@pytest.mark.parametrize("under", ["", "/sub"])
def test_an_out_that_is_or_lies_under_a_file_is_one_line_also_in_a_dry_run(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture, dry_run: bool,
        under: str) -> None:
    """h89: `--dry-run` ("what the same command would run") listed the runs for an `--out`
    that is a file, which compare refuses; and `--out FILE/sub` was `[Errno 20] Not a
    directory: 'FILE/sub'`, naming neither --out nor the file."""
    (tmp_path / "afile").write_text("mine\n")
    out = f"{tmp_path / 'afile'}{under}"
    err = _refused(stream, out, dry_run, capsys)
    named = "is a file" if not under else f"{tmp_path / 'afile'} is a file"
    assert len(err) == 1 and err[0].startswith(f"bomgraph: error: --out {out}: {named}; give "
                                               f"a folder"), err
    assert (tmp_path / "afile").read_text() == "mine\n"


@pytest.mark.parametrize("dry_run", [False, True])
@pytest.mark.parametrize("under", ["", "/sub"])
def test_an_out_through_a_broken_link_is_one_line_also_in_a_dry_run(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture, dry_run: bool,
        under: str) -> None:
    """h94: `--out LINK` (or LINK/sub) where LINK is a symbolic link to a missing folder:
    `--dry-run` listed the runs (exit 0) and compare said `[Errno 17] File exists: 'LINK'`
    (mkdir does not follow a link), naming neither --out nor the link."""
    link = tmp_path / "results"
    link.symlink_to(tmp_path / "gone")
    out = f"{link}{under}"
    err = _refused(stream, out, dry_run, capsys)
    named = "is" if not under else f"{link} is"
    assert len(err) == 1 and err[0].startswith(
        f"bomgraph: error: --out {out}: {named} a link to {tmp_path / 'gone'}, which does not "
        f"exist; create that folder, or give another"), err
    assert link.is_symlink() and not (tmp_path / "gone").exists()
    (tmp_path / "gone").mkdir()   # a link to a folder is a folder
    assert main(_args(stream, out, dry_run)) == 0


@pytest.mark.parametrize("dry_run", [False, True])
def test_an_empty_out_is_refused(tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture,
                                 monkeypatch: pytest.MonkeyPatch, dry_run: bool) -> None:
    """h94: `--out ""` (an unset variable) wrote the results into the current folder (Path('')
    is '.'); the files' --out say "--out is empty" (tests/hostile/test_io_hostile.py)."""
    monkeypatch.chdir(tmp_path)
    err = _refused(stream, "", dry_run, capsys)
    assert err == ["bomgraph: error: --out is empty; give a folder ('.' for this one)"], err
    assert not (tmp_path / "results.json").exists() and not (tmp_path / "cache").exists()
