"""Time how long ``bomgraph compare`` takes to exit after Ctrl-C while its runs run, and check
what it leaves: no process of its own alive, status 130 and one line on stderr, the output
folder's lock file and cache of finished runs (no temporary file).

Each trial writes a few short streams into a fresh ``mktemp -d`` folder, starts the compare in
a new session (``--jobs N`` or ``--dask-local N``) with every run made to sleep (``--sleep``
s; with ``--gil`` in C loops that hold the GIL a second each, as GTSAM's optimiser) through a
``sitecustomize`` ahead on ``PYTHONPATH`` (the workers import it too), waits until that many runs are running, sends SIGINT (to the command, or with
``--group`` to its process group as a terminal's Ctrl-C does), and times until the command
exits. Then any process of its session still alive is listed (and killed), and the Dask
workers' scratch left (a worker killed, not ended, leaves its own; kept in the trial's folder).
Prints one line per trial and the minimum, median and maximum.

    python scripts/time_ctrl_c.py --dask-local 2 --trials 5 --group
    python scripts/time_ctrl_c.py --jobs 2 --trials 5 --group
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_HOOK = """
import os, time
import bomgraph.bench as bench
_run_task = bench.run_task
def run_task(task):  # in a worker: say it runs, then run long enough to be interrupted
    open(os.path.join(os.environ["BOMGRAPH_TIME_MARKS"], str(os.getpid())), "w").close()
    end = time.monotonic() + float(os.environ["BOMGRAPH_TIME_SLEEP"])
    while os.environ["BOMGRAPH_TIME_GIL"] and time.monotonic() < end:
        sum(range(10**8))  # a C loop holding the GIL about a second, as GTSAM's optimiser
    time.sleep(max(end - time.monotonic(), 0))
    return _run_task(task)
bench.run_task = run_task
"""


def _session(sid: int) -> list[tuple[int, str]]:
    """The processes of session ``sid`` still alive (pid, command line), zombies aside."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rpartition(")")[2].split()
            cmd = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if int(fields[3]) == sid and fields[0] != "Z":
            found.append((int(entry.name), cmd.strip()[:120]))
    return found


def _streams(folder: Path, n: int) -> list[Path]:
    import numpy as np

    sys.path.insert(0, str(ROOT))
    from bomgraph.sim import SimConfig, simulate
    from bomgraph.stream_file import write_stream

    paths = []
    for seed in range(1, n + 1):
        paths.append(folder / f"s{seed}.jsonl")
        write_stream(simulate(SimConfig(n_steps=40), np.random.default_rng(seed)), paths[-1])
    return paths


def trial(a: argparse.Namespace, base: Path, streams: list[Path]) -> dict:
    marks, out = Path(tempfile.mkdtemp(dir=base)), Path(tempfile.mkdtemp(dir=base)) / "out"
    site, scratch = Path(tempfile.mkdtemp(dir=base)), Path(tempfile.mkdtemp(dir=base))
    (site / "sitecustomize.py").write_text(textwrap.dedent(_HOOK))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(ROOT)]),
           "OMP_NUM_THREADS": "1", "BOMGRAPH_TIME_MARKS": str(marks),
           "BOMGRAPH_TIME_SLEEP": str(a.sleep), "BOMGRAPH_TIME_GIL": "1" if a.gil else "",
           "DASK_TEMPORARY_DIRECTORY": str(scratch)}
    how = ["--dask-local", str(a.dask_local)] if a.dask_local else ["--jobs", str(a.jobs)]
    cmd = [sys.executable, "-m", "bomgraph", "compare", "--streams", *map(str, streams),
           "--methods", "triangulate", *how, "--no-figures", "--no-progress", "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env,
                            start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    running = a.dask_local or a.jobs
    deadline = time.monotonic() + 120
    while len(list(marks.iterdir())) < running and proc.poll() is None:
        if time.monotonic() > deadline:
            break
        time.sleep(0.02)
    time.sleep(a.settle)
    sent = time.monotonic()
    (os.killpg if a.group else os.kill)(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=300)
    took = time.monotonic() - sent
    time.sleep(0.5)  # a straggler that outlives the command by a moment is no survivor
    left = _session(proc.pid)
    for pid, _ in left:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    lines = err.decode(errors="replace").strip().splitlines()
    partial = [p.name for p in out.rglob("*") if p.name.endswith((".partial", ".tmp"))]
    return {"s": took, "status": proc.returncode, "stderr": lines, "left": left,
            "lock": (out / ".bomgraph.lock").is_file(),
            "cached": len(list((out / "cache").glob("*.json"))) if out.is_dir() else 0,
            "partial": partial,  # Dask's scratch of workers killed, not ended: left there
            "scratch": len(list(scratch.glob("*/worker-*")))}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dask-local", type=int, default=0)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--trials", type=int, default=5)
    p.add_argument("--streams", type=int, default=4, help="streams (one run each)")
    p.add_argument("--sleep", type=float, default=60.0, help="seconds each run sleeps")
    p.add_argument("--settle", type=float, default=0.5, help="seconds to wait once running")
    p.add_argument("--group", action="store_true", help="SIGINT to the process group")
    p.add_argument("--gil", action="store_true",
                   help="each run holds the GIL (a long C loop) instead of sleeping")
    a = p.parse_args()
    base = Path(tempfile.mkdtemp(prefix="bomgraph-ctrl-c-"))
    try:
        streams = _streams(base, a.streams)
        times, bad = [], 0
        for i in range(a.trials):
            r = trial(a, base, streams)
            times.append(r["s"])
            ok = (r["status"] == 130 and len(r["stderr"]) == 1
                  and r["stderr"][0].startswith("bomgraph: interrupted") and not r["left"]
                  and r["lock"] and not r["partial"])
            bad += not ok
            print(f"trial {i}: {r['s']:.2f} s, status {r['status']}, cached {r['cached']}, "
                  f"lock {r['lock']}, left {len(r['left'])}, partial {r['partial']}, "
                  f"worker scratch left {r['scratch']}, "
                  f"stderr {r['stderr'] if not ok else r['stderr'][0][:60]}"
                  + "".join(f"\n    left: {pid} {c}" for pid, c in r["left"]), flush=True)
        print(f"exit after SIGINT: min {min(times):.2f} s, median "
              f"{statistics.median(times):.2f} s, max {max(times):.2f} s over {a.trials}; "
              f"{bad} trial(s) broke the contract")
        return 1 if bad else 0
    finally:
        shutil.rmtree(base, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
