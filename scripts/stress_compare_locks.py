"""Start two ``bomgraph compare`` at the same moment on the same or overlapping folders, many
times, and count the outcomes: one runs and the other is refused (as it should be), both are
refused (neither runs: each saw the other's lock), or both run.

Each trial builds the folders of a scenario in a fresh ``mktemp -d`` folder (``--warm``: after
one compare of each, so every lock file is there from the start), starts both compares, which
import everything and then wait on one pipe (with ``--at-lock``: as each is about to take its
folder locks, its checks of the folder done), and closes the pipe: both go within a moment of
each other. Each run sleeps ``--run-s`` first, so the first to lock holds its locks while the
other starts; two that both ran are told apart by when each held its locks: at once (never
right), or one after the other (right: the second took its locks once the first was done). A compare's outcome is its status: 0 ran, 2 refused ("another ... is writing").

Scenarios (A and B):
  same      A --out X, B --out X
  symlink   A --out X, B --out L, a link to X
  nested    A --out X --estimates, B --out X/estimates
  linked    A --out X --estimates, B --out W whose estimates/ is a link to X/estimates
  crossed   A --out X, X/estimates a link to W/e; B --out W, W/estimates a link to X/e

    python scripts/stress_compare_locks.py --trials 50 linked
    python scripts/stress_compare_locks.py --trials 50 --warm same symlink nested linked
"""

from __future__ import annotations

import argparse
import collections
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_CHILD = """
import contextlib, os, sys, time
import bomgraph.bench, bomgraph.experiments, bomgraph.report  # imported before the start
from bomgraph.cli import main
_run_task = bomgraph.bench.run_task
def run_task(task):  # long enough that the two overlap: the first holds its locks meanwhile
    time.sleep(float(os.environ["BOMGRAPH_LOCKS_RUN_S"]))
    return _run_task(task)
bomgraph.bench.run_task = run_task
go, ready = int(sys.argv[1]), int(sys.argv[2])
at_lock = bool(os.environ["BOMGRAPH_LOCKS_AT_LOCK"])
_locks = bomgraph.report.compare_locks
@contextlib.contextmanager
def compare_locks(*args, **kwargs):
    if at_lock:  # the start: as it takes its locks
        os.write(ready, b"r")
        os.read(go, 1)
    with _locks(*args, **kwargs):
        start = time.monotonic()  # the system's clock: the other process's too
        try:
            yield
        finally:
            print(f"held {start} {time.monotonic()}", file=sys.stderr)
bomgraph.report.compare_locks = compare_locks
if not at_lock:  # the start: as the command starts
    os.write(ready, b"r")
    os.read(go, 1)
sys.exit(main(sys.argv[3:]))
"""


def _stream(folder: Path) -> Path:
    import numpy as np

    sys.path.insert(0, str(ROOT))
    from bomgraph.sim import SimConfig, simulate
    from bomgraph.stream_file import write_stream

    path = folder / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=30), np.random.default_rng(1)), path)
    return path


def _folders(scenario: str, base: Path) -> tuple[Path, Path]:
    """The --out of A and of B, made as the scenario has them."""
    x = base / "x"
    x.mkdir()
    if scenario == "same":
        return x, x
    if scenario == "symlink":
        (base / "l").symlink_to(x)
        return x, base / "l"
    if scenario == "nested":
        (x / "estimates").mkdir()
        return x, x / "estimates"
    if scenario == "linked":
        (x / "estimates").mkdir()
        (base / "w").mkdir()
        (base / "w" / "estimates").symlink_to(x / "estimates")
        return x, base / "w"
    if scenario == "crossed":
        (w := base / "w").mkdir()
        (x / "e").mkdir()
        (w / "e").mkdir()
        (x / "estimates").symlink_to(w / "e")
        (w / "estimates").symlink_to(x / "e")
        return x, w
    raise SystemExit(f"unknown scenario {scenario!r}")


def _args(stream: Path, out: Path) -> list[str]:
    return ["compare", "--streams", str(stream), "--methods", "triangulate", "--jobs", "1",
            "--no-figures", "--no-progress", "--estimates", "--out", str(out)]


def trial(scenario: str, stream: Path, base: Path, warm: bool, run_s: float,
          at_lock: bool) -> tuple[str, list[str]]:
    folder = Path(tempfile.mkdtemp(dir=base))
    outs = _folders(scenario, folder)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1",
           "BOMGRAPH_LOCKS_RUN_S": str(run_s)}
    if warm:  # every lock file there from the start
        for out in outs:
            subprocess.run([sys.executable, "-m", "bomgraph", *_args(stream, out)], env=env,
                           check=True, capture_output=True)
    go_r, go_w = os.pipe()
    ready_r, ready_w = os.pipe()
    env["BOMGRAPH_LOCKS_AT_LOCK"] = "1" if at_lock else ""
    procs = [subprocess.Popen([sys.executable, "-c", _CHILD, str(go_r), str(ready_w),
                               *_args(stream, out)], env=env, pass_fds=(go_r, ready_w),
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
             for out in outs]
    os.close(go_r)
    os.close(ready_w)
    for _ in procs:  # each ready (or gone: its error is its outcome)
        os.read(ready_r, 1)
    os.close(ready_r)
    os.close(go_w)  # both go
    errs = [p.communicate(timeout=300)[1].decode(errors="replace").strip() for p in procs]
    codes = [p.returncode for p in procs]
    shutil.rmtree(folder, ignore_errors=True)
    held = [[float(t) for t in line.split()[1:]] for e in errs for line in e.splitlines()
            if line.startswith("held ")]
    if codes == [0, 0] and len(held) == 2:
        (a0, a1), (b0, b1) = held
        return ("BOTH RAN, AT ONCE" if a0 < b1 and b0 < a1 else
                "both ran, one after the other"), errs
    if sorted(codes) == [0, 2]:
        return "one ran, one refused", errs
    if codes == [2, 2]:
        return "BOTH REFUSED", errs
    if codes == [0, 0]:
        return "both ran", errs
    return f"other {codes}", errs


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scenarios", nargs="+")
    p.add_argument("--trials", type=int, default=50)
    p.add_argument("--warm", action="store_true", help="every lock file there from the start")
    p.add_argument("--run-s", type=float, default=1.0,
                   help="seconds each run sleeps first, so that the compares overlap")
    p.add_argument("--at-lock", action="store_true",
                   help="both start as they take their locks (not as the command starts)")
    p.add_argument("--show", type=int, default=1, help="stderr of this many of each outcome")
    a = p.parse_args()
    base = Path(tempfile.mkdtemp(prefix="bomgraph-locks-"))
    try:
        stream = _stream(base)
        for scenario in a.scenarios:
            counts: collections.Counter[str] = collections.Counter()
            for _ in range(a.trials):
                outcome, errs = trial(scenario, stream, base, a.warm, a.run_s, a.at_lock)
                counts[outcome] += 1
                if counts[outcome] <= a.show and outcome != "one ran, one refused":
                    print(f"  {scenario}: {outcome}:", *errs, sep="\n    ", flush=True)
            print(f"{scenario}{' (warm)' if a.warm else ''}: "
                  + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())), flush=True)
    finally:
        shutil.rmtree(base, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
