"""``compare --scheduler ADDRESS`` on a cluster started by hand: ``dask scheduler`` and
``dask worker`` as separate processes (the workers in another folder, finding bomgraph and a
plugin through their PYTHONPATH), as a user runs one. What goes wrong there is one line and
an exit status, never a traceback, and the runs that finished are cached:

* a run that kills every worker that takes it (a crash in native code, the OOM killer) was a
  ``KilledWorker`` traceback that dropped the runs still going; now it is a failed run;
* a worker without the plugin raised ``unknown method`` through the whole compare (exit 2,
  the plugin being listed by ``bomgraph methods`` on the client); now failed runs say what
  the workers need;
* an address where something else listens hung forever (a port that never answers, such as
  a dashboard's) or printed a traceback (a service answering another protocol); ``http://``
  passed the address check.

The plugin is a package folder with a hand-written ``.dist-info`` (its entry point), put on
the PYTHONPATH: what ``pip install --target`` makes.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Iterator

import pytest
from _plugin_dist import write_dist_info

from bomgraph.cli import main

ROOT = Path(__file__).resolve().parents[1]

MAPPER = '''\
import os
import time
import shutil

import numpy as np

from bomgraph.mapper import MapEstimate


class Crashy:
    """first bearings at 1 m; crash=True ends its process (a crash in native code)"""

    def __init__(self, header, *, crash: bool = False, slow_s: float = 0.0) -> None:
        self.crash = crash
        self.slow_s = slow_s
        self.seen = {}

    def step(self, step) -> None:
        if self.crash and step.t == 3:
            os._exit(3)
        time.sleep(self.slow_s)
        for lid, b in zip(step.landmark_ids.tolist(), step.bearings_rad.tolist()):
            self.seen.setdefault(lid, (np.cos(b), np.sin(b)))

    def estimate(self) -> MapEstimate:
        ids = np.array(sorted(self.seen), dtype=np.int64)
        return MapEstimate(ids, np.array([self.seen[i] for i in ids.tolist()]).reshape(-1, 2))
'''


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def setup(tmp_path_factory: pytest.TempPathFactory) -> dict:
    root = tmp_path_factory.mktemp("cluster")
    plug = root / "plug"
    (plug / "crashy").mkdir(parents=True)
    (plug / "crashy" / "__init__.py").write_text("")
    (plug / "crashy" / "mapper.py").write_text(MAPPER)
    write_dist_info(plug, "crashy", {"crashy": "crashy.mapper:Crashy"})
    streams = []
    for seed in (1, 2):
        path = root / f"s{seed}.jsonl"
        assert main(["simulate", "--seed", str(seed), "--steps", "20", "--landmarks", "15",
                     "--out", str(path)]) == 0
        streams.append(str(path))
    base = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
            "DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES": "0",
            "DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "3s"}
    with_plugin = {**base, "PYTHONPATH": os.pathsep.join([str(ROOT), str(plug)])}
    without = {**base, "PYTHONPATH": str(ROOT)}
    elsewhere = root / "worker-cwd"
    elsewhere.mkdir()
    return {"root": root, "streams": streams, "env": with_plugin, "bare": without,
            "cwd": elsewhere}


def _stop(p: subprocess.Popen) -> None:
    p.terminate()
    try:
        p.wait(timeout=20)
    except subprocess.TimeoutExpired:
        p.kill()
        p.wait()


@contextlib.contextmanager
def _cluster(setup: dict, worker_env: dict, workers: int = 1) -> Iterator[str]:
    """``dask scheduler`` and ``workers`` ``dask worker`` (1 thread, in another folder):
    the scheduler's address, all stopped at the end (``setup["cluster"]``: the processes)."""
    address = f"tcp://127.0.0.1:{_free_port()}"
    procs: list[subprocess.Popen] = []
    setup["cluster"] = procs
    try:
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
             "--port", address.rsplit(":", 1)[1], "--dashboard-address", "127.0.0.1:0", "--no-show"],
            env=setup["env"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        for _ in range(workers):
            procs.append(subprocess.Popen(
                [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads",
                 "1", "--no-dashboard"], env=worker_env, cwd=setup["cwd"],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        from distributed import Client

        with Client(address, timeout=60) as client:  # the workers have registered
            if workers:
                client.wait_for_workers(workers, timeout=60)
        yield address
    finally:
        for p in reversed(procs):
            _stop(p)


def _compare(setup: dict, address: str, methods: str, out: Path, *more: str,
             timeout: float = 180) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bomgraph", "compare", "--streams",
                           *setup["streams"], "--methods", methods, "--scheduler", address,
                           "--no-figures", "--out", str(out), *more], env=setup["env"],
                          capture_output=True, text=True, timeout=timeout)


def _one_line(proc: subprocess.CompletedProcess) -> str:
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert len(lines) == 1, proc.stderr[-3000:]
    return lines[0]


def _ok_runs(out: Path) -> dict[tuple[str, str], bool]:
    data = json.loads((out / "results.json").read_text())
    return {(r["arm"], r["run"]): r["ok"] for r in data["results"]}


def test_a_run_that_kills_its_workers_fails_alone_and_the_rest_is_cached(setup: dict) -> None:
    out = setup["root"] / "killed"
    with _cluster(setup, setup["env"]) as address:
        proc = _compare(setup, address, "triangulate,crashy", out,
                        "--option", "crashy:crash=true")
        line = _one_line(proc)
        assert proc.returncode == 1, proc.stderr
        assert "KilledWorker: every Dask worker that ran it died" in line
        # its warnings were kept for its result, and died with it: how to see them (h106)
        assert "run it alone with --jobs 1 (without --dask-local or --scheduler) to see its " \
               "warnings" in line, line
        assert _ok_runs(out) == {("triangulate", "s1"): True, ("triangulate", "s2"): True,
                                 ("crashy", "s1"): False, ("crashy", "s2"): False}
        assert len(list((out / "cache").glob("*.json"))) == 2  # the finished runs


def test_a_worker_without_the_plugin_gives_failed_runs_saying_what_it_needs(
        setup: dict) -> None:
    out = setup["root"] / "bare"
    with _cluster(setup, setup["bare"]) as address:
        proc = _compare(setup, address, "triangulate,crashy", out)
    line = _one_line(proc)
    assert proc.returncode == 1, proc.stderr
    assert "UnknownMethodError: unknown method 'crashy', in the process " in line
    assert "every worker needs bomgraph and your plugins importable" in line
    assert _ok_runs(out)[("triangulate", "s1")] is True
    assert len(list((out / "cache").glob("*.json"))) == 2


@contextlib.contextmanager
def _listener(answer: bytes | None) -> Iterator[str]:
    """A local port that accepts connections and answers ``answer`` (None: never answers)."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)
    stop = threading.Event()
    held = []

    def serve() -> None:
        srv.settimeout(0.2)
        while not stop.is_set():
            try:
                conn, _ = srv.accept()
            except OSError:
                continue
            if answer is None:
                held.append(conn)
            else:
                conn.sendall(answer)
                conn.close()

    th = threading.Thread(target=serve, daemon=True)
    th.start()
    try:
        yield f"tcp://127.0.0.1:{srv.getsockname()[1]}"
    finally:
        stop.set()
        th.join()
        for c in held:
            c.close()
        srv.close()


@pytest.mark.parametrize("answer, expected", [
    (None, "no Dask scheduler answered within 3 s"),
    (b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n" * 4,
     "no Dask scheduler there (what answers speaks no Dask)")])
def test_an_address_where_no_scheduler_answers_is_one_line_exit_2(
        setup: dict, answer: bytes | None, expected: str) -> None:
    with _listener(answer) as address:
        proc = _compare(setup, address, "triangulate", setup["root"] / "nobody", timeout=60)
    line = _one_line(proc)
    assert proc.returncode == 2, proc.stderr
    assert line.startswith(f"bomgraph: error: --scheduler {address}: {expected}")


def test_a_sweep_files_scheduler_is_named_by_the_file_and_key(setup: dict) -> None:
    """The address came from ``[executor] scheduler`` of the sweep file, not from a flag:
    the refusal names the file and the key (it said ``--scheduler ADDRESS``, a flag the
    user did not give). Nothing listens at the port (Dask's connect timeout, 3 s here)."""
    address = f"tcp://127.0.0.1:{_free_port()}"
    sweep = setup["root"] / "remote.toml"
    sweep.write_text(f"name = \"remote\"\nstreams = {json.dumps(setup['streams'])}\n"
                     f"methods = [\"triangulate\"]\n\n[executor]\n"
                     f"scheduler = \"{address}\"\n")
    proc = subprocess.run([sys.executable, "-m", "bomgraph", "compare", "--config", str(sweep),
                           "--no-figures", "--out", str(setup["root"] / "remote")],
                          env=setup["env"], capture_output=True, text=True, timeout=120)
    line = _one_line(proc)
    assert proc.returncode == 2, proc.stderr
    assert line.startswith(f"bomgraph: error: {sweep}: executor.scheduler = \"{address}\": "
                           f"no Dask scheduler "), line     # "there (...)" or "answered ..."
    assert "--scheduler" not in line


def test_an_http_address_is_refused_before_connecting(setup: dict) -> None:
    proc = _compare(setup, "http://127.0.0.1:8787", "triangulate", setup["root"] / "http")
    line = _one_line(proc)
    assert proc.returncode == 2
    assert "not a Dask scheduler address (unknown address scheme 'http'" in line


def test_a_stale_worker_is_one_line_and_nothing_is_cached(setup: dict) -> None:
    """After an edit of the plugin while the workers run, each run fails saying to restart
    the workers: one line (it was also one warning a run about its key), nothing cached."""
    out = setup["root"] / "stale"
    source = Path(setup["env"]["PYTHONPATH"].split(os.pathsep)[1]) / "crashy" / "mapper.py"
    text = source.read_text()
    with _cluster(setup, setup["env"]) as address:
        assert _compare(setup, address, "crashy", out).returncode == 0
        try:
            source.write_text(text + "\n# edited while the workers run\n")
            proc = _compare(setup, address, "crashy", out)
        finally:
            source.write_text(text)
    line = _one_line(proc)
    assert proc.returncode == 1
    assert "stale worker: restart the workers and run again" in line
    assert len(list((out / "cache").glob("*.json"))) == 2  # the first compare's only


def test_workers_with_other_bomgraph_code_log_one_line_and_cache_nothing(
        setup: dict, tmp_path: Path) -> None:
    """A worker importing another copy of bomgraph (another checkout, other library versions:
    another code fingerprint) keys every run otherwise: its results are reported, not cached,
    and said so in one line (it was one a run)."""
    other = tmp_path / "other"
    for pkg in ("bomgraph", "baselines"):
        shutil.copytree(ROOT / pkg, other / pkg,
                        ignore=shutil.ignore_patterns("__pycache__"))
    with open(other / "bomgraph" / "angles.py", "a") as fh:
        fh.write("\n# another checkout\n")
    env = {**setup["env"], "PYTHONPATH": os.pathsep.join(
        [str(other), setup["env"]["PYTHONPATH"].split(os.pathsep)[1]])}
    out = tmp_path / "out"
    with _cluster(setup, env) as address:
        proc = _compare(setup, address, "triangulate,crashy", out)
    line = _one_line(proc)
    assert proc.returncode == 0
    assert "WARNING: 4 runs not cached (first: " in line
    assert "the workers keyed them otherwise than this process" in line
    assert list((out / "cache").glob("*.json")) == []
    assert all(_ok_runs(out).values())


def test_a_lost_scheduler_fails_the_runs_in_flight_in_one_line_and_keeps_the_rest(
        setup: dict) -> None:
    """The scheduler stopped mid-compare: a FuturesCancelledError traceback, with Dask's
    reconnect traceback; now the runs it dropped are failed runs (exit 1, one line), the ones
    that finished are cached, and a compare started on a scheduler without workers says so
    (it waits for them)."""
    out = setup["root"] / "lost"
    with _cluster(setup, setup["env"]) as address:
        procs = subprocess.Popen(  # a slow run for the scheduler to drop
            [sys.executable, "-m", "bomgraph", "compare", "--streams", *setup["streams"],
             "--methods", "triangulate,crashy", "--option", "crashy:slow_s=0.5",
             "--scheduler", address, "--no-figures", "--out", str(out)], env=setup["env"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 60
        while len(list((out / "cache").glob("*.json"))) < 2:  # triangulate's runs are done
            assert time.monotonic() < deadline and procs.poll() is None
            time.sleep(0.2)
        _stop(setup["cluster"][0])  # the scheduler
        stdout, stderr = procs.communicate(timeout=60)
    proc = subprocess.CompletedProcess(procs.args, procs.returncode, stdout, stderr)
    line = _one_line(proc)
    assert proc.returncode == 1
    assert "the Dask scheduler dropped it (scheduler-connection-lost" in line
    assert _ok_runs(out) == {("triangulate", "s1"): True, ("triangulate", "s2"): True,
                             ("crashy", "s1"): False, ("crashy", "s2"): False}


def test_a_scheduler_without_workers_is_said_once(setup: dict) -> None:
    with _cluster(setup, setup["env"], workers=0) as address:
        procs = subprocess.Popen(
            [sys.executable, "-m", "bomgraph", "compare", "--streams", *setup["streams"],
             "--methods", "triangulate", "--scheduler", address, "--no-figures", "--out",
             str(setup["root"] / "alone")], env=setup["env"],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        try:
            first = procs.stderr.readline()
        finally:
            procs.kill()
            procs.communicate(timeout=30)
    assert first.startswith(f"bomgraph: WARNING: the Dask scheduler at {address} has no "
                            f"workers: the runs wait for one (start `dask worker {address}`)")


def test_the_library_leaves_dasks_loggers_alone(tmp_path: Path) -> None:
    """Quieting Dask's own log lines is the command line's choice (without ``-v``), and it is
    not undone: the library's ``execute`` on a cluster must not change them for its caller."""
    import importlib
    import logging

    import numpy as np

    from bomgraph.bench import Executor, execute
    from bomgraph.experiments import Arm, Experiment, FileSource
    from bomgraph.sim import SimConfig, simulate
    from bomgraph.stream_file import write_stream

    s = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=20, n_landmarks=8), np.random.default_rng(2)), s)
    exp = Experiment("e", "e", (Arm("tri", "triangulate"),), sources=(FileSource(str(s)),))
    importlib.import_module("distributed")  # Dask sets its own levels when imported
    levels = {n: logging.getLogger(n).level for n in ("distributed", "distributed.client")}
    out = execute(exp.tasks(), Executor("dask", dask_local=1))
    assert out[0]["ok"]
    assert {n: logging.getLogger(n).level for n in levels} == levels


def test_jobs_beside_a_cluster_is_noted_not_silently_dropped(tmp_path: Path, capsys) -> None:
    s = tmp_path / "s.jsonl"
    assert main(["simulate", "--seed", "1", "--steps", "20", "--out", str(s), "-q"]) == 0
    args = ["compare", "--streams", str(s), "--methods", "triangulate", "--dask-local", "1",
            "--jobs", "3", "--no-figures", "--no-progress", "--out", str(tmp_path / "o")]
    assert main(args) == 0
    assert "--jobs 3 is not used" in capsys.readouterr().err
    assert main(args + ["-q"]) == 0
    assert "--jobs" not in capsys.readouterr().err
