"""Ctrl-C during a ``--dask-local`` compare (h110).

* A terminal's Ctrl-C reaches the whole process group: the local cluster's workers took it too,
  and one logged "Async instruction ... ended with CancelledError" on the user's stderr beside
  the command's one line (4 of 5 Ctrl-Cs, ``scripts/time_ctrl_c.py --group``). They start with
  SIGINT and SIGTERM held now, as ``--jobs``'s do.
* Closing the cluster waited up to 4 s for each worker's unfinished run (Dask's nanny: "Worker
  process still alive after 4.0 seconds, killing"), so Ctrl-C took 4.3 s to stop the command
  where ``--jobs 2`` took 0.25 s. The runs left are nobody's: their workers are killed at once.
  How long it takes is measured by ``scripts/time_ctrl_c.py``, not here; here, what it leaves.
"""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from hostile_helpers import ENV, ctrl_c, group_killed_at_the_end, holds_sigint_and_sigterm

pytestmark = pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="reads /proc")


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (not gone, not a zombie)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[0] != "Z"
    except OSError:
        return False


def _wait_for(folder: Path, pattern: str, n: int) -> list[Path]:
    deadline = time.monotonic() + 120   # liveness only: the runs start within seconds
    while len(found := sorted(folder.glob(pattern))) < n:
        assert time.monotonic() < deadline, f"{n} of {pattern} not there in 120 s: {found}"
        time.sleep(0.05)
    return found


def _first_returns_the_rest_sleep(k: int, folder: str) -> tuple[int, dict]:
    """In a worker: the first run to start returns; the others note their worker's pid and
    sleep an hour (busy, as a long run: the compare is left amid them)."""
    try:
        os.close(os.open(os.path.join(folder, "first"), os.O_CREAT | os.O_EXCL))
        return k, {"ok": True}
    except FileExistsError:
        pass
    with open(os.path.join(folder, f"tmp{k}"), "w") as fh:
        fh.write(str(os.getpid()))
    os.replace(os.path.join(folder, f"tmp{k}"), os.path.join(folder, f"sleeping{k}"))
    time.sleep(3600)
    return k, {"ok": True}


class _Records(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


def test_runs_left_early_end_their_local_workers_at_once(tmp_path: Path) -> None:
    """The runs left (the caller stopped reading, as Ctrl-C does): the workers running them
    are killed, not waited for. Before, Dask's nanny waited 4 s for each unfinished run, then
    said so and killed its worker. Fails before (that warning)."""
    from bomgraph.cluster import dispatch

    records = _Records()
    nanny = logging.getLogger("distributed.nanny")
    nanny.addHandler(records)
    try:
        runs = dispatch(_first_returns_the_rest_sleep, [0, 1, 2], [str(tmp_path)] * 3,
                        scheduler=None, n_local=2,
                        failed=lambda k, why: {"ok": False, "error": why})
        assert next(runs)[1] == {"ok": True}
        pids = [int(p.read_text()) for p in _wait_for(tmp_path, "sleeping*", 2)]
        assert len(set(pids)) == 2 and all(_alive(p) for p in pids)
        runs.close()
    finally:
        nanny.removeHandler(records)
    assert not [p for p in pids if _alive(p)]
    assert not [m for m in records.messages if "still alive" in m], records.messages


_SLEEPING_RUNS = """
import os, time
import bomgraph.bench as bench
def run_task(task):  # in a worker: say so, with its pid, then run an hour
    folder = os.environ["H110_MARKS"]
    with open(os.path.join(folder, f"tmp{os.getpid()}"), "w") as fh:
        fh.write(str(os.getpid()))
    os.replace(os.path.join(folder, f"tmp{os.getpid()}"),
               os.path.join(folder, f"running{os.getpid()}"))
    time.sleep(3600)
bench.run_task = run_task
"""


def test_ctrl_c_to_the_process_group_of_a_dask_local_compare(tmp_path: Path, work: Path
                                                             ) -> None:
    """A terminal's Ctrl-C amid the runs of ``compare --dask-local 2``: the workers hold
    SIGINT and SIGTERM (the command alone takes it), status 130 and the one line, none of
    the workers left, the folder's lock file there (it stays: removing it would race) and
    no temporary file. The workers' mask fails before."""
    site, marks, out = tmp_path / "site", tmp_path / "marks", tmp_path / "out"
    site.mkdir()
    marks.mkdir()
    (site / "sitecustomize.py").write_text(textwrap.dedent(_SLEEPING_RUNS))
    env = {**ENV, "PYTHONPATH": os.pathsep.join([str(site), ENV["PYTHONPATH"]]),
           "H110_MARKS": str(marks), "DASK_TEMPORARY_DIRECTORY": str(tmp_path / "scratch")}
    streams = [work / "s.jsonl", tmp_path / "t.jsonl"]
    streams[1].write_bytes(streams[0].read_bytes())
    proc = subprocess.Popen(
        [sys.executable, "-m", "bomgraph", "compare", "--streams", *map(str, streams),
         "--methods", "triangulate,stmds-cs", "--dask-local", "2", "--no-figures",
         "--no-progress", "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        env=env, start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    with group_killed_at_the_end(proc):
        workers = [int(p.read_text()) for p in _wait_for(marks, "running*", 2)]
        assert all(holds_sigint_and_sigterm(pid) for pid in workers)
        _, err = ctrl_c(proc)
    lines = err.decode(errors="replace").strip().splitlines()
    assert proc.returncode == 130, lines
    assert lines == ["bomgraph: interrupted; 0 runs cached, rerun to resume"], lines
    assert not [p for p in workers if _alive(p)]
    assert (out / ".bomgraph.lock").read_text().strip() == str(proc.pid)
    assert not [p for p in out.rglob("*") if p.name.endswith((".partial", ".tmp"))]
    assert not (out / "results.json").exists()
