"""h101: refusals raised by library functions named command-line options the caller never
gave: ``report.compare(experiments, out_dir="x")`` from Python said "--out x: is a file".
From Python they now name the library's parameter (``out_dir='x'``); the command line's
messages, which other tests check, still name its options (``--out x``).

Fails before: every library message below named the option (``--out``, ``--allow-truth``,
``--similarity``, ``--reference EST``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bomgraph.cli import main
from bomgraph.errors import BomgraphError, ConfigError, EvaluationError
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.file_evaluation import evaluate_files
from bomgraph.file_run import run_file
from bomgraph.report import compare
from bomgraph.sim import SimConfig, simulate
from bomgraph.stdio import OutputPathError
from bomgraph.stream import Stream
from bomgraph.stream_file import read_stream, write_stream


@pytest.fixture()
def stream(tmp_path: Path) -> Path:
    path = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=20), np.random.default_rng(1)), path)
    return path


def _raised(error: type[BomgraphError], call, *args, **kw) -> str:
    with pytest.raises(error) as info:
        call(*args, **kw)
    return str(info.value)


def test_compare_names_out_dir_from_python_and_out_on_the_command_line(
        tmp_path: Path, stream: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "afile").write_text("x")
    exp = Experiment("e", "e", (Arm("triangulate", "triangulate"),),
                     sources=(FileSource(str(stream)),))
    said = _raised(OutputPathError, compare, [exp], out_dir=tmp_path / "afile")
    assert said == f"out_dir='{tmp_path / 'afile'}': is a file; give a folder (it is created " \
                   f"if missing)", said
    assert _raised(OutputPathError, compare, [exp], out_dir="").startswith("out_dir is empty")
    (tmp_path / "cmp").mkdir()
    (tmp_path / "cmp" / "results.csv").write_text("mine")
    said = _raised(OutputPathError, compare, [exp], out_dir=tmp_path / "cmp")
    assert said.startswith(f"out_dir='{tmp_path / 'cmp'}': compare would replace "), said
    assert main(["compare", "--streams", str(stream), "--methods", "triangulate", "--out",
                 str(tmp_path / "afile")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"bomgraph: error: --out {tmp_path / 'afile'}: is a file"), err


def test_writers_and_runs_name_their_parameters(tmp_path: Path, stream: Path) -> None:
    s: Stream = read_stream(stream)
    assert _raised(OutputPathError, write_stream, s, "") == "path is empty; give a file name"
    said = _raised(OutputPathError, write_stream, s, tmp_path)
    assert said == f"path='{tmp_path}': is a directory; give a file name", said
    said = _raised(ConfigError, run_file, stream, "oracle")
    assert "(pass allow_truth=True to run it anyway)" in said and "--" not in said, said


def test_evaluate_files_names_its_parameters(tmp_path: Path, stream: Path) -> None:
    s = read_stream(stream)
    bare = tmp_path / "bare.jsonl"
    write_stream(Stream(s.header, s.steps, None), bare)
    est = tmp_path / "e.est"
    assert main(["run", str(bare), "--method", "triangulate", "--out", str(est)]) == 0
    said = _raised(EvaluationError, evaluate_files, est, bare, with_scale=True)
    assert "(with_scale, align_on, delta); give reference_path" in said and "--" not in said
