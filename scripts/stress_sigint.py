"""Stress ``bomgraph compare`` with signals at many moments, and check the contract of each run.

The contract (the CLI's docstring): an interrupt exits with status 130 (SIGTERM: 143), writes
exactly one line on stderr that says so and that a rerun resumes, never a traceback; leaves no
temporary file (``*.partial``, ``*.tmp``) in the output folder, and no earlier output file
truncated or lost; and a rerun afterwards completes with the same ``results.json`` (timings
aside) as an uninterrupted run.

Each trial starts the command, waits ``delay`` seconds, sends the signal (to the process, or
with ``--group`` to its process group as Ctrl-C in a terminal does; with ``--double`` a second
SIGINT ``--gap`` seconds later), then checks all of the above; ``--warm`` starts each trial
from a copy of a complete earlier output folder (cache included), so that the signal lands
while results.json, the CSVs, figures and the manifest are written over the earlier ones.
``--burn N`` runs N CPU burners beside it. Prints one line per trial and a count of the
outcomes per delay band; the violations with their stderr in full.

    python scripts/stress_sigint.py --delays 0:9:0.25 --jobs 1 --no-figures
    python scripts/stress_sigint.py --delays 1:4:0.1 --jobs 2 --warm --burn 2
"""

from __future__ import annotations

import argparse
import collections
import csv
import json
import multiprocessing
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from bomgraph.bench import strip_timings  # noqa: E402

ENV = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1",
       "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def _command(out: Path, a: argparse.Namespace) -> list[str]:
    cmd = [sys.executable, "-m", "bomgraph", "compare", "--quick", "--experiments",
           a.experiments, "--jobs", str(a.jobs), "--no-progress", "--out", str(out)]
    return cmd + (["--no-figures"] if a.no_figures else [])


def _default_sigint() -> None:  # a shell's background job inherits SIGINT ignored
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _results(folder: Path) -> list[dict[str, Any]]:
    """The results without timings, nor the cache keys (which hash the code: they change
    when the code is edited between the reference and a trial)."""
    with open(folder / "results.json", encoding="utf-8") as fh:
        return [{k: v for k, v in r.items() if k != "key"}
                for r in strip_timings(json.load(fh)["results"])]


def _complete(path: Path) -> str:
    """Why ``path`` (an output of compare) is not a complete file ("" when it is)."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        return f"unreadable: {exc}"
    name = path.name
    try:
        if name.endswith(".png"):
            return "" if data.endswith(b"IEND\xaeB`\x82") else "PNG without its end"
        if name.endswith(".json") or name == ".bomgraph-compare-files":
            json.loads(data)
        elif name.endswith(".csv"):
            rows = list(csv.reader(data.decode().splitlines()))
            if not rows or any(len(r) != len(rows[0]) for r in rows):
                return "CSV with rows of other lengths"
            if not data.endswith(b"\n"):
                return "CSV without its last line end"
    except ValueError as exc:
        return f"not parseable: {exc}"
    return ""


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*")
            if p.is_file() and p.name != ".bomgraph.lock"}


def _burn(stop) -> None:
    while not stop.is_set():
        sum(i * i for i in range(10000))


def trial(delay: float, a: argparse.Namespace, reference: list, warm_from: Path | None,
          work: Path) -> tuple[str, list[str], str]:
    out = work / "out"
    shutil.rmtree(out, ignore_errors=True)
    if warm_from is not None:
        shutil.copytree(warm_from, out)
    before = _snapshot(out) if out.exists() else {}
    sig = signal.SIGTERM if a.sigterm else signal.SIGINT
    proc = subprocess.Popen(_command(out, a), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            env=ENV, preexec_fn=_default_sigint, start_new_session=a.group)
    time.sleep(delay)
    send = (lambda s: os.killpg(proc.pid, s)) if a.group else proc.send_signal
    finished_first = proc.poll() is not None
    if not finished_first:
        send(sig)
        if a.double:
            time.sleep(a.gap)
            if proc.poll() is None:
                send(signal.SIGINT)
    try:
        _, err_b = proc.communicate(timeout=300)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL) if a.group else proc.kill()
        _, err_b = proc.communicate()
        return "HUNG", ["did not end within 300 s of the signal"], err_b.decode(errors="replace")
    err = err_b.decode(errors="replace")
    bad: list[str] = []
    lines = [ln for ln in err.splitlines() if ln.strip()]
    want_rc = 143 if a.sigterm else 130
    if finished_first or proc.returncode == 0:
        outcome = "finished"
        if proc.returncode != 0:
            bad.append(f"status {proc.returncode}")
        if lines:
            bad.append("stderr not empty")
    else:
        outcome = "interrupted"
        if proc.returncode != want_rc:
            bad.append(f"status {proc.returncode}, not {want_rc}")
        if len(lines) != 1:
            bad.append(f"{len(lines)} lines on stderr")
        if not any("interrupted" in ln or "terminated" in ln for ln in lines):
            bad.append("no line says it was interrupted")
        if not any("rerun" in ln for ln in lines):
            bad.append("no line says a rerun resumes")
    for needle in ("Traceback", "KeyboardInterrupt", "Exception ignored"):
        if needle in err:
            bad.append(f"{needle!r} on stderr")
    if out.exists():
        stray = [str(p.relative_to(out)) for p in out.rglob("*")
                 if p.name.endswith((".partial", ".tmp")) or p.name.startswith("tmp")]
        if stray:
            bad.append(f"temporary files left: {stray[:3]}")
        for rel in before:
            p = out / rel
            if not p.exists():
                bad.append(f"earlier output lost: {rel}")
            elif (why := _complete(p)):
                bad.append(f"earlier output {rel}: {why}")
        for p in out.rglob("*"):
            if p.is_file() and str(p.relative_to(out)) not in before and (why := _complete(p)):
                bad.append(f"new output {p.relative_to(out)}: {why}")
        if (out / "results.json").exists() and "results.json" in before:
            try:
                if _results(out) != reference:
                    bad.append("results.json differs from the reference after the interrupt")
            except ValueError:
                pass  # reported above
    # the rerun completes and gives the reference results
    if not a.no_rerun:
        re = subprocess.run(_command(out, a), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            env=ENV, preexec_fn=_default_sigint, timeout=600)
        if re.returncode != 0:
            bad.append(f"rerun status {re.returncode}: {re.stderr.decode()[-300:]}")
        elif _results(out) != reference:
            bad.append("rerun results.json differs from an uninterrupted run's")
    return outcome, bad, err


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--delays", default="0:9:0.25", help="START:STOP:STEP seconds")
    p.add_argument("--repeat", type=int, default=1, help="trials per delay")
    p.add_argument("--jobs", type=int, default=1)
    p.add_argument("--experiments", default="all")
    p.add_argument("--no-figures", action="store_true")
    p.add_argument("--warm", action="store_true", help="start from a complete earlier output")
    p.add_argument("--sigterm", action="store_true", help="send SIGTERM, not SIGINT")
    p.add_argument("--double", action="store_true", help="a second SIGINT --gap s later")
    p.add_argument("--gap", type=float, default=0.05)
    p.add_argument("--group", action="store_true", help="signal the process group (Ctrl-C)")
    p.add_argument("--burn", type=int, default=0, help="CPU burners beside it")
    p.add_argument("--no-rerun", action="store_true")
    p.add_argument("--work", default=None, help="folder for the trials (default: a temp one)")
    a = p.parse_args()
    start, stop, step = map(float, a.delays.split(":"))
    delays = [round(start + k * step, 4) for k in range(int(round((stop - start) / step)) + 1)]
    work = Path(a.work or tempfile.mkdtemp(prefix="bomgraph-stress-"))
    work.mkdir(parents=True, exist_ok=True)
    ref_dir = work / "reference"
    if not (ref_dir / "results.json").exists():
        shutil.rmtree(ref_dir, ignore_errors=True)
        subprocess.run(_command(ref_dir, a), check=True, env=ENV, stdout=subprocess.DEVNULL)
    reference = _results(ref_dir)
    stop_burn = multiprocessing.Event()
    burners = [multiprocessing.Process(target=_burn, args=(stop_burn,), daemon=True)
               for _ in range(a.burn)]
    for b in burners:
        b.start()
    counts: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    violations = []
    try:
        for delay in delays:
            for _ in range(a.repeat):
                outcome, bad, err = trial(delay, a, reference, ref_dir if a.warm else None,
                                          work)
                band = f"{int(delay)}-{int(delay) + 1}s"
                counts[band][outcome + (" BAD" if bad else " ok")] += 1
                print(f"delay {delay:6.3f} s: {outcome:11s} {'; '.join(bad) or 'ok'}",
                      flush=True)
                if bad:
                    violations.append((delay, bad, err))
    finally:
        stop_burn.set()
        for b in burners:
            b.join()
    print("\nper delay band:")
    for band, c in counts.items():
        print(f"  {band:7s} " + ", ".join(f"{k}: {v}" for k, v in sorted(c.items())))
    for delay, bad, err in violations:
        print(f"\n--- delay {delay} s: {'; '.join(bad)}\n{err.rstrip()}")
    print(f"\n{len(violations)} violation(s); trials in {work}")
    return 1 if violations else 0


if __name__ == "__main__":
    sys.exit(main())
