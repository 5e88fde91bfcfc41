"""h75: what interrupted compares leave in their folder. A compare killed while it writes
leaves its writer's temporary file (``.NAME.XXXXXXXX.partial``): the next compare removes
those of the names compare writes, nothing else. Each interrupted compare copied the
manifest's earlier entries into its journal again: it grew with every interruption in a row.
A file compare wrote, edited, then left out of the list was refused as one "which compare did
not write"."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

import _compare_folder
from bomgraph import claims, out_folder, report
from bomgraph.bench import Executor
from bomgraph.cli import main
from bomgraph.experiments import compare_experiments
from bomgraph.out_folder import MANIFEST
from bomgraph.report import compare
from bomgraph.stdio import AtomicOutput, OutputPathError


stream = _compare_folder.stream   # the fixture
_cmd = _compare_folder.compare_cmd


#: a compare killed (SIGKILL) just after its writer created the temporary file of NAME
_KILLED_WRITING = """
import os, signal, sys, tempfile
real = tempfile.mkstemp
def mkstemp(*a, **kw):
    made = real(*a, **kw)
    if kw.get("prefix") == "." + os.environ["KILL_WRITING"] + ".":
        os.kill(os.getpid(), signal.SIGKILL)
    return made
tempfile.mkstemp = mkstemp
from bomgraph.cli import main
sys.exit(main(sys.argv[1:]))
"""


def _killed_writing(name: str, cmd: list[str], out: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(Path(report.__file__).parents[1]),
           "KILL_WRITING": name}
    proc = subprocess.run([sys.executable, "-c", _KILLED_WRITING, *cmd], env=env,
                          capture_output=True)
    assert proc.returncode == -signal.SIGKILL


def _partials(out: Path) -> list[str]:
    return sorted(str(p.relative_to(out)) for p in out.rglob("*.partial"))


def test_a_compare_killed_while_writing_leaves_a_temporary_file_the_next_removes(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture) -> None:
    """kill -9 while results.csv, an estimate, the manifest were written: a
    ``.NAME.XXXXXXXX.partial`` file each that nothing removed, one more per interrupted
    compare (fails before: 1, 2, 3 of them; now the next compare removes the earlier's)."""
    out = tmp_path / "out"
    cmd = _cmd(stream, out, "--no-figures", "--estimates")
    for name, where in (("results.csv", ".results.csv."), ("s.est", "estimates/"),
                        (MANIFEST, f".{MANIFEST}.")):
        _killed_writing(name, cmd, out)
        left = _partials(out)
        assert len(left) == 1 and left[0].startswith(where), left
    capsys.readouterr()
    assert main([*cmd, "-v"]) == 0
    assert _partials(out) == []
    assert [ln for ln in capsys.readouterr().err.splitlines() if "temporary" in ln] == [
        f"bomgraph: INFO: removed 1 temporary file(s) that interrupted compares left in {out}"]


def test_only_the_writers_temporaries_of_compares_names_are_removed(tmp_path: Path,
                                                                     stream: Path) -> None:
    """Not a user's file that looks alike, nor the cache's (a sweep may share it unlocked)."""
    out = tmp_path / "out"
    assert main(_cmd(stream, out, "--no-figures")) == 0
    ours = [out / ".results.csv.a_b1c2d3.partial",
            out / f".{MANIFEST}.zz99_x0q.partial"]
    theirs = [out / ".results.csv.partial", out / ".results.csv.abcdefg.partial",
              out / ".results.csv.abcdefghi.partial", out / ".results.csv.ABCDEFGH.partial",
              out / ".mine.csv.abcdefgh.partial", out / ".results.csv.abcdefgh.partial.bak",
              out / "results.csv.abcdefgh.partial", out / ".results.csv.abcdefgh.part",
              out / "cache" / ".k.json.abcdefgh.partial",
              out / ".example_map.png.abcdefgh.partial"]   # not written: --no-figures
    for p in ours + theirs:
        p.write_text("x")
    (out / ".summary.csv.abcdefgh.partial").mkdir()          # a folder: never
    assert main(_cmd(stream, out, "--no-figures")) == 0
    assert not any(p.exists() for p in ours)
    assert all(p.read_text() == "x" for p in theirs)
    assert (out / ".summary.csv.abcdefgh.partial").is_dir()


def test_the_pattern_is_the_writers(tmp_path: Path) -> None:
    """The temporary name the one writer of bomgraph uses is the one removed."""
    w = AtomicOutput(tmp_path / "results.csv")
    w.open()
    try:
        import re
        name = os.path.basename(w._tmp or "")
        assert re.fullmatch(claims.TEMP_NAME.format(name=re.escape("results.csv")), name)
    finally:
        w.abort()


def _lines(out: Path) -> int:
    return len((out / MANIFEST).read_text().splitlines())


def test_the_journal_stays_bounded_over_interruptions_in_a_row(
        tmp_path: Path, stream: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Interrupted 5 times in a row once every file is written: the journal had 11, 16, 21,
    26, 31 lines (5 files); now 11 each time (fails before). The next compare replaces them."""
    out = tmp_path / "out"
    chosen, _ = compare_experiments(streams=[str(stream)], methods="triangulate")
    compare(chosen, out, executor=Executor("serial"), figures=False)

    def interrupted(*a: object, **kw: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(out_folder, "drop_earlier_outputs", interrupted)
    sizes = []
    for _ in range(5):
        with pytest.raises(KeyboardInterrupt):
            compare(chosen, out, executor=Executor("serial"), figures=False)
        sizes.append(_lines(out))
    assert sizes == [11] * 5
    monkeypatch.undo()
    compare(chosen, out, executor=Executor("serial"), figures=False)


def test_killed_between_a_files_line_and_its_rename_after_interruptions(
        tmp_path: Path, stream: Path) -> None:
    """The journal then lists results.json's new contents, which never took the name: the
    compaction keeps the entry that proves the file as it is, so the next compare goes on."""
    out = tmp_path / "out"
    cmd = _cmd(stream, out, "--no-figures")
    assert main(cmd) == 0
    env = {**os.environ, "PYTHONPATH": str(Path(report.__file__).parents[1])}
    killed = ("import os, signal, sys\nreal = os.replace\n"
              "def replace(src, dst, **kw):\n"
              "    if os.path.basename(dst) == 'results.json':\n"
              "        os.kill(os.getpid(), signal.SIGKILL)\n"
              "    real(src, dst, **kw)\n"
              "os.replace = replace\nfrom bomgraph.cli import main\nsys.exit(main(sys.argv[1:]))\n")
    for _ in range(3):
        proc = subprocess.run([sys.executable, "-c", killed, *cmd], env=env, capture_output=True)
        assert proc.returncode == -signal.SIGKILL
        assert _lines(out) == 1 + 5 + 1  # the 5 files' entries, results.json's new one
    assert main(cmd) == 0
    assert _partials(out) == []


def test_a_file_edited_then_left_out_of_the_list_is_refused_in_true_words(
        tmp_path: Path, stream: Path) -> None:
    """compare --estimates wrote index.csv, the user edited it, a compare without
    --estimates left it (changed) and listed it no more: compare --estimates then refused it
    as one "which compare did not write" (fails before)."""
    out = tmp_path / "out"
    chosen, _ = compare_experiments(streams=[str(stream)], methods="triangulate")
    compare(chosen, out, executor=Executor("serial"), figures=False, estimates=True)
    with open(out / "estimates" / "index.csv", "a") as fh:
        fh.write("# my note\n")
    compare(chosen, out, executor=Executor("serial"), figures=False)
    with pytest.raises(OutputPathError) as err:
        compare(chosen, out, executor=Executor("serial"), figures=False, estimates=True)
    assert (f"index.csv, which is not listed as compare's, unchanged, in {out / MANIFEST};"
            in str(err.value))
    assert "did not write" not in str(err.value)
