"""Paired CPU time of BOM-STMDS presets, this checkout against another one, in one process.

The other checkout's ``bomgraph`` package is loaded under another name (``--old``: a copy of
its ``bomgraph`` folder renamed, e.g. ``cp -r /work/main/bomgraph /tmp/old/bomgraph_old``;
the package imports itself relatively), and every paper run is mapped by the old and the new
code in turn (the order alternating), a map every 10 steps, CPU seconds per run
(``time.process_time``, single-threaded BLAS). Prints the median CPU per run of each and the
median of the per-run ratios old / new, and checks that both gave the same final map bit
for bit.

With ``--stmds-step`` it times, the same way, the per-step update of ``stmds-smacof``
(paper preset) as ``scripts/bench_speed.py --sections stmds-step`` defines it: ``step()`` over
a run plus the ``flush()`` before each map, ``estimate()`` run but not timed; on the paper
runs and on the same runs with 25 landmarks (about 10 in view); microseconds per step, the
median per-run ratio, and whether the distance stores and final maps are the same bit for bit.

Usage::

    python scripts/bench_stmds_paired.py --old /tmp/old/bomgraph_old --presets window-ba
        window-lsq [--runs 25] [--repeats 1] [--stmds-step]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import importlib  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from bomgraph.mapper import run  # noqa: E402
from bomgraph.sim import SimConfig, paper_design, simulate_run  # noqa: E402
from bomgraph.stmds.mapper import make_stmds_smacof  # noqa: E402


def _as_old(stream, old_pkg: str):
    """``stream`` in the old package's types: written by this checkout, read by the old one."""
    import tempfile

    from bomgraph.stream_file import write_stream

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "s.jsonl"
        write_stream(stream, path)
        return importlib.import_module(f"{old_pkg}.stream_file").read_stream(path)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", type=Path, required=True, help="the old package folder")
    ap.add_argument("--presets", nargs="+", default=["window-ba", "window-lsq"])
    ap.add_argument("--runs", type=int, default=25)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--stmds-step", action="store_true",
                    help="time the per-step update instead of whole runs")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(args.old.resolve().parent))
    old_pkg = args.old.name
    old_make = importlib.import_module(f"{old_pkg}.stmds.mapper").make_stmds_smacof
    old_run = importlib.import_module(f"{old_pkg}.mapper").run
    if args.stmds_step:
        return stmds_step(old_make, args.runs, args.repeats)
    streams = [simulate_run(spec) for spec in paper_design(0)[:args.runs]]
    old_streams = [_as_old(stream, old_pkg) for stream in streams]
    for preset in args.presets:
        opts = {} if preset == "paper" else {"preset": preset}
        cpu: dict[str, list[float]] = {"old": [], "new": []}
        ratios, same = [], True
        for i, (stream, old_stream) in enumerate(list(zip(streams, old_streams))
                                                 * args.repeats):
            finals = {}
            order = ("old", "new") if i % 2 == 0 else ("new", "old")
            per = {}
            for which in order:
                make, go = (old_make, old_run) if which == "old" else (make_stmds_smacof, run)
                # the old package runs on its own Step type (its run() checks the type)
                src = old_stream if which == "old" else stream
                mapper = make(src.header, **opts)
                c0 = time.process_time()
                res = go(mapper, src.steps, checkpoint_every=10, keep_checkpoints=False)
                per[which] = time.process_time() - c0
                finals[which] = res.final
            for k in per:
                cpu[k].append(per[k])
            ratios.append(per["old"] / per["new"])
            same &= (np.array_equal(finals["old"].landmark_ids, finals["new"].landmark_ids)
                     and finals["old"].landmarks_xy.tobytes()
                     == finals["new"].landmarks_xy.tobytes())
        print(f"{preset:12s} old {np.median(cpu['old']):.3f} s/run  new "
              f"{np.median(cpu['new']):.3f} s/run  ratio (median of {len(ratios)} paired) "
              f"{np.median(ratios):.2f}  final maps bit for bit: {same}", flush=True)
    return 0


def step_update(make, stream) -> tuple[float, object]:
    """CPU seconds per step of ``step()`` plus the ``flush()`` before each map (a map every
    10 steps and at the end, ``estimate()`` not timed), and the mapper."""
    mapper = make(stream.header)
    last = stream.steps[-1].t
    update = 0.0
    for st in stream.steps:
        c0 = time.process_time()
        mapper.step(st)
        mapped = (st.t > 0 and st.t % 10 == 0) or st.t == last
        if mapped:
            mapper.flush()
        update += time.process_time() - c0
        if mapped:
            mapper.estimate()
    return update / len(stream.steps), mapper


def stmds_step(old_make, runs: int, repeats: int) -> int:
    """The paired per-step update (see the module docstring)."""
    for label, config in (("paper runs", SimConfig()), ("25 landmarks", SimConfig(n_landmarks=25))):
        streams = [simulate_run(spec, config) for spec in paper_design(0)[:runs]]
        per: dict[str, list[float]] = {"old": [], "new": []}
        ratios, same = [], True
        for i, stream in enumerate(streams * repeats):
            order = ("old", "new") if i % 2 == 0 else ("new", "old")
            mappers = {}
            for which in order:
                t, mappers[which] = step_update(old_make if which == "old" else
                                                 make_stmds_smacof, stream)
                per[which].append(t)
            ratios.append(per["old"][-1] / per["new"][-1])
            a, b = mappers["old"]._store, mappers["new"]._store
            n = len(a)
            same &= n == len(b) and all(np.array_equal(getattr(a, k)[:n], getattr(b, k)[:n])
                                        for k in ("_a", "_b", "_count", "_sw", "_sx"))
            same &= (mappers["old"].estimate().landmarks_xy.tobytes()
                     == mappers["new"].estimate().landmarks_xy.tobytes())
        in_view = np.mean([np.mean([st.landmark_ids.size for st in s.steps]) for s in streams])
        print(f"stmds-step, {label} ({in_view:.1f} in view): old "
              f"{1e6 * np.median(per['old']):.1f} us/step  new {1e6 * np.median(per['new']):.1f}"
              f" us/step  ratio (median of {len(ratios)} paired) {np.median(ratios):.2f}  "
              f"stores and final maps bit for bit: {same}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
