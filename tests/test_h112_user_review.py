"""h112: a new user's walk through the README (fresh venv, own plugin, own streams, hostile
input). Each test failed before its fix.

* ``compare --out`` a folder this user cannot write printed Python's
  ``[Errno 13] Permission denied: 'ro/.bomgraph.lock'`` (``--out ro/new``:
  ``[Errno 13] Permission denied: 'ro/new'``): no ``--out``, nothing on what to do.
* ``run --out`` (and every other writer) over an existing file in such a folder passed the
  check and failed when it made its temporary file beside it.
* ``compare --streams DIR`` said "no such file DIR", ``--config DIR`` "no such sweep file";
  a quoted pattern (``--streams "runs/*.jsonl"``) "no such file runs/*.jsonl".
* A stream or estimate cut short in its last line: ``not valid JSON (Unterminated string
  starting at)``, no column, nothing on the cause; one saved with a byte-order mark (Windows
  Notepad's UTF-8) ``(Unexpected UTF-8 BOM (decode using utf-8-sig) at column 1)``, and a
  dataset text file (g2o, Victoria Park) ``unsupported record '\\ufeff#'``, a sweep file
  ``not valid TOML: Invalid statement (at line 1, column 1)``.
* ``landmark_nees`` of an estimate without covariances did not say which methods give them.
* ``compare(..., executor=Executor("processes", ...))`` refusing a method registered in this
  process left the output folder behind, with its lock file.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from _not_writable import not_writable  # tests/_not_writable.py

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}


def bomgraph(*args: object, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bomgraph", *map(str, args)], cwd=cwd,
                          env=ENV, capture_output=True, text=True, timeout=300)


def one_error(proc: subprocess.CompletedProcess, *needles: str) -> str:
    """Exit 2 and one line ``bomgraph: error: ...`` holding every needle, no traceback."""
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("bomgraph: error: "), proc.stderr
    assert "Traceback" not in proc.stderr and "[Errno" not in proc.stderr, proc.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


@pytest.fixture(scope="module")
def work(tmp_path_factory: pytest.TempPathFactory) -> Path:
    work = tmp_path_factory.mktemp("h112")
    assert bomgraph("simulate", "--seed", "1", "--steps", "40", "--out", "s.jsonl",
                    cwd=work).returncode == 0
    assert bomgraph("run", "s.jsonl", "--method", "triangulate", "--out", "e.est",
                    cwd=work).returncode == 0
    return work


def test_compare_out_a_folder_it_cannot_write(work: Path) -> None:
    locked = work / "locked"
    locked.mkdir()
    compare = ("compare", "--streams", "s.jsonl", "--methods", "triangulate", "--jobs", "1")
    with not_writable(locked):
        one_error(bomgraph(*compare, "--out", "locked", cwd=work),
                  "--out locked: is not writable; choose another folder")
        one_error(bomgraph(*compare, "--out", "locked/new", cwd=work),
                  "--out locked/new: locked, where it would be made, is not writable")
        one_error(bomgraph(*compare, "--dry-run", "--out", "locked", cwd=work),
                  "is not writable")  # what compare refuses, its plan refuses
    assert list(locked.iterdir()) == []


@pytest.mark.parametrize("command", [
    ("run", "s.jsonl", "--method", "triangulate"),
    ("export", "e.est", "--stream", "s.jsonl", "--format", "tum"),
    ("simulate", "--seed", "2", "--steps", "10")])
def test_a_file_in_a_folder_it_cannot_write_is_refused_before_anything(
        work: Path, command: tuple[str, ...]) -> None:
    locked = work / f"locked-{command[0]}"
    locked.mkdir()
    old = locked / "old.out"
    old.write_text("keep\n")
    with not_writable(locked):
        one_error(bomgraph(*command, "--out", old, cwd=work),
                  f"--out {old}: the folder {locked} is not writable")
    assert old.read_text() == "keep\n" and [p.name for p in locked.iterdir()] == ["old.out"]


def test_a_folder_given_as_a_stream_or_sweep_file_is_called_a_folder(work: Path) -> None:
    """``compare --streams DIR`` said "no such file DIR" and ``--config DIR`` "no such sweep
    file", of a folder that is there."""
    (work / "runs").mkdir(exist_ok=True)
    one_error(bomgraph("compare", "--streams", "runs", "--methods", "triangulate", "--out", "o",
                       cwd=work),
              "--streams: runs is a folder, not a file; give the files in it (runs/*.jsonl")
    one_error(bomgraph("compare", "--streams", "nothing.jsonl", "--methods", "triangulate",
                       "--out", "o", cwd=work), "--streams: no such file nothing.jsonl")
    one_error(bomgraph("compare", "--streams", "runs/*.jsonl", "--methods", "triangulate",
                       "--out", "o", cwd=work),
              "--streams: no such file runs/*.jsonl (a pattern? the command line takes files: "
              "leave the pattern unquoted for the shell to expand, or put it in a sweep file's "
              "streams)")
    one_error(bomgraph("compare", "--config", "runs", "--out", "o", cwd=work),
              "runs: is a folder, not a sweep file (a path, or a shipped one: ")
    one_error(bomgraph("compare", "--config", "none.toml", "--out", "o", cwd=work),
              "none.toml: no such sweep file (a path, or a shipped one: ")
    assert not (work / "o").exists()


def test_a_file_cut_short_in_its_last_line_is_called_so(work: Path) -> None:
    """A stream or estimate whose last line was cut (a recording or a copy interrupted) said
    ``line 42: not valid JSON (Expecting ',' delimiter)`` or ``(Unterminated string starting
    at)``: no column, nothing on the cause."""
    stream = (work / "s.jsonl").read_bytes()
    (work / "cut.jsonl").write_bytes(stream[:-40])
    n = stream.count(b"\n")
    one_error(bomgraph("run", "cut.jsonl", "--method", "triangulate", "--out", "x.est",
                       cwd=work),
              f"cut.jsonl, line {n}: not valid JSON (", " at column ",
              "the file ends in this line, without a newline: cut short? complete the line "
              "or remove it")
    est = (work / "e.est").read_bytes()
    (work / "cut.est").write_bytes(est[:-30])
    n = est.count(b"\n")
    one_error(bomgraph("evaluate", "cut.est", "s.jsonl", cwd=work),
              f"cut.est, line {n}: not valid JSON (", " at column ", "cut short?")
    (work / "typo.jsonl").write_bytes(stream.replace(b'{"t": 3,', b'{"t": 3', 1))
    line = one_error(bomgraph("run", "typo.jsonl", "--method", "triangulate", "--out", "x.est",
                              cwd=work), "typo.jsonl, line 5: not valid JSON (", " at column ")
    assert "cut short" not in line  # a line with its newline was not cut
    assert not (work / "x.est").exists()


def test_landmark_nees_without_covariances_says_which_methods_give_them() -> None:
    """It said only "the estimate has no landmark covariances"."""
    import numpy as np

    from bomgraph import create_mapper, run
    from bomgraph.errors import EvaluationError
    from bomgraph.evaluate import landmark_nees, score_estimate
    from bomgraph.sim import SimConfig, simulate

    stream = simulate(SimConfig(n_steps=60), np.random.default_rng(0))
    final = run(create_mapper("triangulate", stream.header), stream.steps).final
    with pytest.raises(EvaluationError, match=r"no landmark covariances \(landmark_cov\): use "
                                              r"a method that gives them, ekf, ekf-invdepth, "
                                              r"or a GTSAM method with covariances=True"):
        landmark_nees(final, stream.truth, score_estimate(final, stream.truth).alignment)


def test_a_runtime_method_refused_for_worker_processes_leaves_no_folder(
        work: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """docs/USAGE.md, "A sweep from Python", with ``Executor("processes", n_jobs=2)``: the refusal
    (workers cannot see a method registered in this process) came after compare had made the
    output folder and its lock file, which stayed behind, empty but for ``.bomgraph.lock``."""
    from bomgraph.bench import Executor
    from bomgraph.errors import ConfigError
    from bomgraph.experiments import compare_experiments
    from bomgraph.report import compare

    from _runtime_method import runtime_method  # tests/_runtime_method.py

    source = ("from bomgraph.mapper import MapEstimate\nimport numpy as np\n"
              "class Nothing:\n    def __init__(self, header):\n        pass\n"
              "    def step(self, step):\n        pass\n    def estimate(self):\n"
              "        return MapEstimate(np.zeros(0, dtype=np.int64), np.zeros((0, 2)))\n")
    for _ in runtime_method(tmp_path, monkeypatch, "h112-nothing", "h112_nothing", source,
                            "Nothing"):
        experiments, _ = compare_experiments(streams=[str(work / "s.jsonl")],
                                             methods="h112-nothing,triangulate")
        with pytest.raises(ConfigError, match="registered at run time"):
            compare(experiments, tmp_path / "out", executor=Executor("processes", n_jobs=2),
                    figures=False)
        assert not (tmp_path / "out").exists()


def test_a_file_with_a_byte_order_mark_says_how_to_save_it(work: Path) -> None:
    bom = b"\xef\xbb\xbf"
    (work / "bom.jsonl").write_bytes(bom + (work / "s.jsonl").read_bytes())
    (work / "bom.est").write_bytes(bom + (work / "e.est").read_bytes())
    says = ("line 1: not valid JSON (the file starts with a UTF-8 byte-order mark (BOM): save it "
            "as UTF-8 without one)")
    one_error(bomgraph("run", "bom.jsonl", "--method", "triangulate", "--out", "x.est",
                       cwd=work), f"bom.jsonl, {says}")
    one_error(bomgraph("evaluate", "bom.est", "s.jsonl", cwd=work), f"bom.est, {says}")


def test_a_dataset_file_with_a_byte_order_mark_says_how_to_save_it(work: Path) -> None:
    """g2o and Victoria Park text saved with a byte-order mark said "unsupported record
    '\\ufeff#'" / "unknown record '\\ufeffODOMETRY'"."""
    assert bomgraph("export", "e.est", "--stream", "s.jsonl", "--format", "g2o", "--out",
                    "e.g2o", cwd=work).returncode == 0
    (work / "bom.g2o").write_bytes(b"\xef\xbb\xbf" + (work / "e.g2o").read_bytes())
    (work / "bom.txt").write_bytes(b"\xef\xbb\xbfODOMETRY 0.0 0.1 0.2 0.0\n")
    says = ("line 1: the file starts with a UTF-8 byte-order mark (BOM): save it as UTF-8 "
            "without one")
    one_error(bomgraph("import", "g2o", "bom.g2o", "--out", "x.jsonl", cwd=work),
              f"bom.g2o, {says}")
    one_error(bomgraph("import", "victoria", "bom.txt", "--out", "x.jsonl", cwd=work),
              f"bom.txt, {says}")


def test_a_sweep_file_with_a_byte_order_mark_says_how_to_save_it(work: Path) -> None:
    """It said "not valid TOML: Invalid statement (at line 1, column 1)"."""
    (work / "bom.toml").write_bytes(b'\xef\xbb\xbfstreams = ["s.jsonl"]\nmethods = ["ekf"]\n')
    one_error(bomgraph("compare", "--config", "bom.toml", "--dry-run", "--out", "o", cwd=work),
              "bom.toml: the file starts with a UTF-8 byte-order mark (BOM): save it as UTF-8 "
              "without one")
