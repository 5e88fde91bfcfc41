"""A sweep called from a daemonic process (a ``multiprocessing.Pool`` worker, which may have
no children) with local worker processes asked for: joblib ran every task in that process,
one at a time, printing "Loky-backed parallel loops cannot be called in a multiprocessing,
setting n_jobs=1" after bomgraph's log line that it was starting 2 workers, and a method
registered at run time was refused ("the workers ... cannot see it") though it would have
run there. Now one log line says so and the runs are serial (h64)."""

from __future__ import annotations

import logging
import multiprocessing
import os
import warnings

import numpy as np

from bomgraph import mapper
from bomgraph.bench import Executor, execute
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.report import plan_compare
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream


def _sweep(stream: str) -> tuple[list[tuple[bool, str]], list[str], list[str], int]:
    """In the Pool worker: the sweep's (ok, error) per run, its log lines, its warnings."""
    records: list[logging.LogRecord] = []
    handler = logging.Handler()
    handler.emit = records.append  # type: ignore[method-assign]
    logging.getLogger("bomgraph").addHandler(handler)
    logging.getLogger("bomgraph").setLevel(logging.INFO)
    mapper.register_method("h64-rt", "baselines.triangulate:TriangulateMapper")
    exp = Experiment("e", "e", (Arm("triangulate", "triangulate"), Arm("h64-rt", "h64-rt")),
                     sources=(FileSource(stream),))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            plan = plan_compare([exp], stream + ".out", executor=Executor("processes", n_jobs=2))
            assert len(plan) == 2, plan
            res = [(r["ok"], r.get("error", "")) for r in
                   execute(exp.tasks(), Executor("processes", n_jobs=2))]
        except Exception as exc:  # noqa: BLE001 - reported to the test
            res = [(False, f"{type(exc).__name__}: {exc}")]
    return (res, [r.getMessage() for r in records], [str(w.message) for w in caught],
            os.getpid())


def test_a_sweep_in_a_pool_worker_runs_serially_saying_so_once(tmp_path) -> None:
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=20), np.random.default_rng(3)), stream)
    # spawn, not fork: the test process runs threads (fork may deadlock the child; Python 3.13
    # warns of it), and the worker registers its method itself
    with multiprocessing.get_context("spawn").Pool(1) as pool:
        res, logs, caught, pid = pool.apply(_sweep, (str(stream),))
    assert pid != os.getpid()
    assert res == [(True, ""), (True, "")], res
    assert caught == [], caught
    daemonic = [m for m in logs if "daemonic" in m]
    assert len(daemonic) == 1 and "running the 2 runs here" in daemonic[0], logs
    assert not any("worker processes asked for" in m for m in logs), logs
