"""h107: small leads from the 30th session's reviews.

- ``bomgraph --help > /dev/full`` exited 0 and said nothing (argparse ignores an error writing
  its help), where ``bomgraph methods > /dev/full`` says the error in one line and exits 2.
"""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BOMGRAPH = f"{shlex.quote(sys.executable)} -m bomgraph"


def _bash(tmp_path: Path, line: str) -> subprocess.CompletedProcess[bytes]:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    return subprocess.run(["bash", "-c", line], cwd=tmp_path, env=env, capture_output=True,
                          check=False)


@pytest.mark.parametrize("args", ["--help", "--version", "compare --help", "methods"])
def test_help_and_version_on_a_full_device_fail_as_a_commands_output(
        tmp_path: Path, args: str) -> None:
    """Fails before for --help, --version and compare --help: exit 0, nothing said."""
    done = _bash(tmp_path, f"{BOMGRAPH} {args} > /dev/full")
    assert done.returncode == 2, done.stderr[:300]
    assert done.stderr.decode().splitlines() == [
        "bomgraph: error: [Errno 28] No space left on device"]


def test_help_into_a_closed_pipe_or_closed_stdout_stays_quiet(tmp_path: Path) -> None:
    """As before: a closed pipe (``| true``) and a closed stdout (``>&-``, 255f1cc) say
    nothing."""
    done = _bash(tmp_path, f"{BOMGRAPH} --help >&-")
    assert (done.returncode, done.stderr) == (0, b"")
    done = _bash(tmp_path, f"{BOMGRAPH} compare --help | true; echo ${{PIPESTATUS[0]}}")
    assert done.stderr == b"", done.stderr[:300]
    assert done.stdout.decode().strip() in ("0", "141"), done.stdout
