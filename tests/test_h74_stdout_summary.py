"""``--out /dev/stdout`` with stdout redirected to a file (``run``, before h71 and after, and
``export``): the output was written into the file from its start and then the summary line,
over the start of the output. The summary goes to stderr, as with ``--out -`` (h74)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from bomgraph.estimate_file import read_estimate, stream_file_identity

from _run_once import simulated

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def stream(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return simulated(tmp_path_factory, 30, 12)


def _to_file(argv: list[str], stdout: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    with open(stdout, "wb") as fh:
        return subprocess.run([sys.executable, "-m", "bomgraph", *argv], stdout=fh,
                              stderr=subprocess.PIPE, text=True, env=env, check=False)


def test_run_out_dev_stdout_into_a_file_is_the_estimate(stream: Path, tmp_path: Path) -> None:
    """``run --out /dev/stdout > f``: f is the estimate, the summary on stderr. Fails before
    h74: the summary line was written over the start of the estimate's header."""
    est = tmp_path / "f.est"
    done = _to_file(["run", str(stream), "--method", "triangulate", "--out", "/dev/stdout"],
                    est)
    assert done.returncode == 0, done.stderr
    assert read_estimate(est).stream == stream_file_identity(stream)
    assert "wrote /dev/stdout" in done.stderr
    done = _to_file(["run", str(stream), "--method", "triangulate", "--out", "/dev/stdout",
                     "--json"], est)
    assert done.returncode == 0 and json.loads(done.stderr)["out"] == "/dev/stdout"
    assert read_estimate(est).stream == stream_file_identity(stream)
    csv = tmp_path / "f.csv"  # export the same
    done = _to_file(["export", str(est), "--format", "csv", "--out", "/dev/stdout"], csv)
    assert done.returncode == 0 and "wrote /dev/stdout (csv)" in done.stderr, done.stderr
    assert "wrote" not in csv.read_text()
