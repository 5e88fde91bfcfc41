"""Shared by the hostile battery (issue 13): run ``bomgraph`` as a user would, in a subprocess
bounded in time and (optionally) in memory, and check the one rule: a result, or exit 2 with
one line ``bomgraph: error: ...`` naming the cause, never a traceback."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import resource
import subprocess
import sys
from pathlib import Path
from typing import Iterable, Iterator

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1", "OMP_NUM_THREADS": "1",
       "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
#: address-space limit of a memory-bounded case (the interpreter with numpy, scipy and GTSAM
#: loaded takes about 1 GiB of address space; a bounded case stays well inside this).
MEMORY_LIMIT_BYTES = 3 * 2**30


def _limit_memory(limit: int):
    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    return apply


def bomgraph(*args: str, stdin: bytes | int | None = None, cwd: str | Path | None = None,
             memory: int | None = None, timeout: float = 300,
             stdout: int | None = None) -> subprocess.CompletedProcess:
    """``python -m bomgraph ARGS`` with stdout and stderr captured (``memory``: bytes of
    address space, via ``resource.setrlimit``)."""
    kw: dict = {"env": ENV, "timeout": timeout, "cwd": cwd}
    if memory is not None:
        kw["preexec_fn"] = _limit_memory(memory)
    if isinstance(stdin, (bytes, type(None))):
        kw["input"] = stdin
    else:
        kw["stdin"] = stdin
    return subprocess.run([sys.executable, "-m", "bomgraph", *map(str, args)],
                          stdout=subprocess.PIPE if stdout is None else stdout,
                          stderr=subprocess.PIPE, **kw)


def no_traceback(proc: subprocess.CompletedProcess) -> str:
    err = proc.stderr.decode(errors="replace")
    assert "Traceback" not in err, err
    assert not re.search(r"^\w*(Error|Exception|Interrupt): ", err, re.M), err  # no bare repr
    return err


def one_error(proc: subprocess.CompletedProcess, *needles: str) -> str:
    """Exit 2, exactly one error line ``bomgraph: error: ...`` containing every needle (warning
    lines may precede it), no traceback; returns the line."""
    err = no_traceback(proc)
    assert proc.returncode == 2, (proc.returncode, err)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    errors = [ln for ln in lines if ln.startswith("bomgraph: error: ")]
    assert len(errors) == 1 and lines[-1] == errors[0], err
    for n in needles:
        assert n.lower() in errors[0].lower(), (n, errors[0])
    return errors[0]


def ok_or_one_error(proc: subprocess.CompletedProcess) -> str:
    """A result (exit 0) or one error line (exit 2); never a traceback or another status."""
    if proc.returncode == 0:
        return no_traceback(proc)
    return one_error(proc)


def snapshot(folder: Path) -> dict[str, str]:
    """Every entry below ``folder``: name -> kind and SHA-256 of its bytes (links as links)."""
    out = {}
    for p in sorted(folder.rglob("*")):
        rel = str(p.relative_to(folder))
        if p.is_symlink():
            out[rel] = "link:" + os.readlink(p)
        elif p.is_file():
            out[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
        else:
            out[rel] = "other"
    return out


def write_jsonl(path: Path, header: dict, steps: Iterable[dict]) -> Path:
    """A stream file from raw JSON objects (the format's keys)."""
    lines = [json.dumps(header)] + [json.dumps(s) for s in steps]
    path.write_text("\n".join(lines) + "\n")
    return path


HEADER = {"format": "bomgraph-stream", "version": 1, "bearing_sigma_rad": 0.05,
          "odometry_sigma": [0.03, 0.0, 0.05]}


def odd_steps(n: int = 8, **at_4) -> list[dict]:
    """``n`` steps seeing three landmarks, step 4's keys updated with ``at_4`` (its line is
    line 6 of a stream file: a method's refusal of a value there names that line)."""
    steps = [{"t": 0, "bearings": [[0, 0.5], [1, -0.5], [2, 2.0]]}] + [
        {"t": t, "odom": [0.1, 0.0, 0.05],
         "bearings": [[0, 0.5 + 0.05 * t], [1, -0.5 - 0.04 * t], [2, 2.0 + 0.03 * t]]}
        for t in range(1, n)]
    steps[4].update(at_4)
    return steps


def refused_in_compare(folder: Path, stream: Path, method: str, where: str) -> None:
    """``compare --streams STREAM --methods METHOD`` fails the run (exit 1) and says ``where``
    on stderr and in results.json."""
    proc = bomgraph("compare", "--streams", stream, "--methods", method, "--out",
                    folder / "cmp", "--jobs", "1", "--no-progress", "--no-figures")
    assert proc.returncode == 1, proc.stderr
    err = proc.stderr.decode()
    assert where in err, err
    assert where in (folder / "cmp" / "results.json").read_text()


def holds_sigint_and_sigterm(pid: int) -> bool:
    """Whether the process ``pid`` has SIGINT and SIGTERM blocked (Linux ``/proc``)."""
    import signal

    blocked = int(Path(f"/proc/{pid}/status").read_text().split("SigBlk:")[1].split()[0], 16)
    return all(blocked & (1 << (s - 1)) for s in (signal.SIGINT, signal.SIGTERM))


def ctrl_c(proc: subprocess.Popen, timeout: float = 120) -> tuple[bytes, bytes]:
    """SIGINT to ``proc``'s process group (a terminal's Ctrl-C; ``proc`` started in a session
    of its own), and its output once it has ended."""
    import signal

    os.killpg(proc.pid, signal.SIGINT)
    return proc.communicate(timeout=timeout)


@contextlib.contextmanager
def group_killed_at_the_end(proc: subprocess.Popen) -> Iterator[subprocess.Popen]:
    """``proc`` (started in a session of its own) and its group killed after the block if it
    is still running then (a failed test)."""
    import signal

    try:
        yield proc
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
