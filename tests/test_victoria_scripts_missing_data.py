"""The Victoria Park scripts without the data file (``BOMGRAPH_DATA`` unset or pointing
elsewhere), or with a file that is not the dataset: one line saying what is missing or wrong,
exit 2, as ``scripts/bench_real.py`` does. Before (h41) both printed the importer's
``DatasetError`` traceback and exited 1."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _run(script: str, *args: str, data: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "BOMGRAPH_DATA": data, "OMP_NUM_THREADS": "1",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, str(ROOT / "scripts" / f"{script}.py"), *args],
                          env=env, capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("script", ["victoria_ekf_diagnosis", "victoria_map"])
def test_no_data_file_is_one_line_and_exit_2(script: str, tmp_path: Path) -> None:
    proc = _run(script, data=str(tmp_path / "elsewhere"))
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    missing = tmp_path / "elsewhere" / "victoria_park" / "victoria_park.txt"
    assert lines[0].startswith(f"{script}.py: error: {missing}: file not found"), lines[0]
    assert "set BOMGRAPH_DATA" in lines[0] and "--data FILE" in lines[0]


def test_a_file_that_is_not_the_dataset_names_its_line(tmp_path: Path) -> None:
    bad = tmp_path / "not_victoria.txt"
    bad.write_text("hello\n")
    proc = _run("victoria_ekf_diagnosis", "--data", str(bad), data=str(tmp_path))
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert lines[0].startswith(f"victoria_ekf_diagnosis.py: error: {bad}, line 1:"), lines[0]
