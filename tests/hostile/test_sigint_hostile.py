"""Ctrl-C (and SIGTERM) at any moment of ``bomgraph compare`` (issue 13, item 21, continued):
status 130 (143), exactly one line on stderr saying so and that a rerun resumes, no traceback,
no temporary file, no earlier output truncated, and a rerun gives the same results.

A race hit by chance is no test: each case here makes the signal land at one chosen moment,
either in-process (a patched call sends it to the main thread) or in the command, through a
``sitecustomize`` module put ahead on ``PYTHONPATH`` that patches one call of bomgraph before
``python -m bomgraph`` starts. ``scripts/stress_sigint.py`` sends signals at random moments
(delay sweeps, loaded machine, double signals, SIGTERM) and checks the same contract."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import threading
from pathlib import Path

import pytest

from hostile_helpers import ENV, ctrl_c, group_killed_at_the_end, holds_sigint_and_sigterm

from bomgraph.bench import strip_timings


def _to_main_thread(signum: int = signal.SIGINT) -> None:
    """The signal, to the main thread, as a terminal's Ctrl-C reaches the command."""
    signal.pthread_kill(threading.main_thread().ident, signum)


@pytest.fixture()
def sigint_raises():
    """SIGINT raising KeyboardInterrupt (a runner started in the background has it ignored)."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)


# ---- in-process: the moments inside one output file -----------------------------------------

def test_sigint_during_commit_keeps_the_earlier_file_and_leaves_no_partial(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, sigint_raises) -> None:
    # commit (flush, fsync, close, rename) ran after the try of output_file: a Ctrl-C during
    # its fsync left .NAME.XXXX.partial (seen in compare's cache folder)
    import bomgraph.stdio as stdio

    real = os.fsync

    def fsync(fd: int) -> None:
        real(fd)
        _to_main_thread()

    monkeypatch.setattr(stdio.os, "fsync", fsync)
    target = tmp_path / "results.json"
    target.write_text("earlier")
    with pytest.raises(KeyboardInterrupt):
        with stdio.output_file(target) as fh:
            fh.write("new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.json"]
    assert target.read_text() == "earlier"


def test_a_second_sigint_during_the_cleanup_of_the_first_leaves_no_partial(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, sigint_raises) -> None:
    import bomgraph.stdio as stdio

    real = os.unlink

    def unlink(path: str) -> None:  # the second Ctrl-C, as abort removes the partial file
        _to_main_thread()
        real(path)

    monkeypatch.setattr(stdio.os, "unlink", unlink)
    with pytest.raises(KeyboardInterrupt):
        with stdio.output_file(tmp_path / "out.csv") as fh:
            fh.write("half")
            raise KeyboardInterrupt  # the first
    assert list(tmp_path.iterdir()) == []


def test_an_interrupted_savefig_keeps_the_earlier_figure(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    # compare's figures were saved straight into their names: half a PNG after a Ctrl-C
    import numpy as np

    import bomgraph.report as report

    class HalfFigure:
        def savefig(self, target, **kw) -> None:
            if isinstance(target, (str, os.PathLike)):
                with open(target, "wb") as fh:
                    fh.write(b"\x89PNG half")
            else:
                target.write(b"\x89PNG half")
            raise KeyboardInterrupt

    class Exp:
        name, title, sources, designed = "e", "E", (), False

        @staticmethod
        def n_runs() -> int:
            return 1

    monkeypatch.setattr(report, "error_vs_time_figure", lambda *a, **k: HalfFigure())
    earlier = tmp_path / "e_error_vs_time.png"
    earlier.write_bytes(b"the earlier figure")
    row = {"t": 10, "mpe_m": 0.1, "robot_last_m": np.nan}
    result = {"experiment": "e", "arm": "a", "ok": True, "checkpoints": [row]}
    with pytest.raises(KeyboardInterrupt):
        report.write_compare_figures(tmp_path, [Exp()], [result])
    assert sorted(p.name for p in tmp_path.iterdir()) == [earlier.name]
    assert earlier.read_bytes() == b"the earlier figure"


@pytest.mark.parametrize("interrupt", [KeyboardInterrupt, SystemExit])
def test_an_interrupted_extension_import_is_an_interrupt_not_a_broken_method(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, interrupt: type) -> None:
    # pybind11 (GTSAM) turns a Ctrl-C during its module's initialisation into "ImportError:
    # initialization failed" caused by it; compare then refused gtsam-batch as not loadable
    from bomgraph.plugins import load

    (tmp_path / "h31_ext.py").write_text(
        f"raise ImportError('initialization failed') from {interrupt.__name__}()\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(interrupt):
        load("h31_ext:Mapper", "ext")
    assert "h31_ext" not in sys.modules


# ---- the command: a signal at one chosen moment -----------------------------------------------

@pytest.fixture(scope="module")
def streams(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Two short simulated streams: with two methods, four runs of a second or less."""
    import numpy as np

    from bomgraph.sim import SimConfig, simulate
    from bomgraph.stream_file import write_stream

    folder = tmp_path_factory.mktemp("streams")
    paths = []
    for seed in (1, 2):
        paths.append(folder / f"s{seed}.jsonl")
        write_stream(simulate(SimConfig(n_steps=40), np.random.default_rng(seed)), paths[-1])
    return paths


def _compare(streams: list[Path], out: Path, hook: str = "",
             *extra: str) -> subprocess.CompletedProcess:
    """``python -m bomgraph compare`` of two methods on ``streams`` into ``out``, with ``hook``
    (Python) run in the command's interpreter before it starts."""
    env = dict(ENV)
    if hook:
        site = out.parent / f"site-{out.name}"
        site.mkdir(exist_ok=True)
        (site / "sitecustomize.py").write_text(
            "import os, signal, sys\n" + textwrap.dedent(hook).lstrip("\n"))
        env["PYTHONPATH"] = os.pathsep.join([str(site), env["PYTHONPATH"]])
    args = ["compare", "--streams", *map(str, streams), "--methods", "triangulate,stmds-cs",
            "--jobs", "1", "--no-figures", "--no-progress", "--out", str(out), *extra]
    return subprocess.run([sys.executable, "-m", "bomgraph", *args], stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, env=env, timeout=300,
                          preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def _one_line(proc: subprocess.CompletedProcess, status: int = 130,
              word: str = "interrupted") -> str:
    err = proc.stderr.decode(errors="replace")
    assert proc.returncode == status, (proc.returncode, err)
    for needle in ("Traceback", "KeyboardInterrupt", "Exception ignored"):
        assert needle not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"bomgraph: {word}"), err
    assert "rerun to resume" in lines[0], err
    return lines[0]


def _no_temporary_files(out: Path) -> None:
    stray = [p for p in out.rglob("*") if p.name.endswith((".partial", ".tmp"))]
    assert not stray, stray


#: the first run of the compare, made to send the signal first
_AT_FIRST_RUN = """
import bomgraph.bench as bench
_run_task = bench.run_task
def run_task(task):
    bench.run_task = _run_task
    {signal}
    return _run_task(task)
bench.run_task = run_task
"""


def test_sigint_out_of_exec_d_code_exits_130_not_by_the_signal(tmp_path: Path,
                                                               streams: list[Path]) -> None:
    # dataclasses and namedtuple run their made functions from a string; a Ctrl-C out of
    # such code (a lazy import of GTSAM, of a method) left CPython's flag set, and
    # `python -m` killed itself with SIGINT after printing the line: status -2, not 130
    hook = _AT_FIRST_RUN.format(signal="exec('os.kill(os.getpid(), signal.SIGINT)\\n"
                                       "for _ in range(99): pass')")
    _one_line(_compare(streams, tmp_path / "out", hook))


def test_sigint_in_a_finaliser_still_stops_the_compare(tmp_path: Path,
                                                      streams: list[Path]) -> None:
    # a KeyboardInterrupt raised inside __del__ (or a generator closed by the collector) was
    # printed as "Exception ignored in ..." and dropped: the compare ran to its end
    hook = _AT_FIRST_RUN.format(signal="""class Dying:
        def __del__(self):
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(99): pass
    Dying()
    import time; time.sleep(1)""")
    out = tmp_path / "out"
    _one_line(_compare(streams, out, hook))
    assert not (out / "results.json").exists()
    _no_temporary_files(out)


def test_sigint_before_the_runs_says_a_rerun_resumes(tmp_path: Path,
                                                     streams: list[Path]) -> None:
    hook = """
    import bomgraph.experiments as experiments
    _real = experiments.compare_experiments
    def compare_experiments(**kw):
        os.kill(os.getpid(), signal.SIGINT)
        return _real(**kw)
    experiments.compare_experiments = compare_experiments
    """
    _one_line(_compare(streams, tmp_path / "out", hook))


def test_sigint_while_the_command_is_imported_is_one_line(tmp_path: Path,
                                                          streams: list[Path]) -> None:
    hook = """
    import builtins
    _import = builtins.__import__
    def hooked(name, *a, **kw):
        if name == "cli_parser" or name.endswith(".cli_parser"):
            builtins.__import__ = _import
            os.kill(os.getpid(), signal.SIGINT)
        return _import(name, *a, **kw)
    builtins.__import__ = hooked
    """
    _one_line(_compare(streams, tmp_path / "out", hook))


def test_sigint_after_the_command_ended_is_ignored(tmp_path: Path,
                                                   streams: list[Path]) -> None:
    # during the interpreter's exit (atexit, finalisers) the command has written everything:
    # a late Ctrl-C must not turn it into a traceback or a death by signal
    hook = """
    import atexit
    atexit.register(lambda: (os.kill(os.getpid(), signal.SIGINT), sum(range(9999))))
    """
    proc = _compare(streams, tmp_path / "out", hook)
    assert proc.returncode == 0 and proc.stderr == b"", proc.stderr.decode()


def test_sigterm_and_double_sigint_at_a_cache_write_then_the_rerun_gives_the_same_results(
        tmp_path: Path, streams: list[Path]) -> None:
    reference = tmp_path / "reference"
    assert _compare(streams, reference).returncode == 0

    def results(out: Path) -> list:
        return strip_timings(json.loads((out / "results.json").read_text())["results"])

    # SIGTERM as the second result is renamed into the cache: one line too, status 143
    term = """
    import bomgraph.stdio as stdio
    _replace, _calls = stdio.os.replace, []
    def replace(a, b):
        _replace(a, b)
        _calls.append(b)
        if len(_calls) == 2:
            os.kill(os.getpid(), signal.SIGTERM)
    stdio.os.replace = replace
    """
    out = tmp_path / "out"
    _one_line(_compare(streams, out, term), 143, "terminated")
    _no_temporary_files(out)
    assert len(list((out / "cache").glob("*.json"))) == 2
    # Ctrl-C during a cache file's fsync, and again as its partial file is removed
    double = """
    import bomgraph.stdio as stdio
    _fsync, _unlink = stdio.os.fsync, stdio.os.unlink
    def fsync(fd):
        _fsync(fd)
        os.kill(os.getpid(), signal.SIGINT)
    def unlink(path):
        os.kill(os.getpid(), signal.SIGINT)
        _unlink(path)
    stdio.os.fsync, stdio.os.unlink = fsync, unlink
    """
    _one_line(_compare(streams, out, double))
    _no_temporary_files(out)
    assert len(list((out / "cache").glob("*.json"))) == 2
    rerun = _compare(streams, out)
    assert rerun.returncode == 0, rerun.stderr.decode()
    assert results(out) == results(reference)


def _children(pid: int) -> list[int]:
    kids = []
    for entry in Path("/proc").iterdir():
        try:
            stat = (entry / "stat").read_text()
        except (OSError, ValueError):
            continue
        if int(stat.rpartition(")")[2].split()[1]) == pid:
            kids.append(int(entry.name))
    return kids


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads /proc")
def test_ctrl_c_to_the_process_group_with_worker_processes_is_one_line(
        tmp_path: Path, streams: list[Path]) -> None:
    # a terminal's Ctrl-C reaches the joblib workers too: they printed their own
    # KeyboardInterrupt tracebacks (while starting, or between tasks); they now start with
    # SIGINT and SIGTERM blocked, and the command alone stops, and ends them
    env = dict(ENV)
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(textwrap.dedent("""
        import bomgraph.bench as bench
        _run_task = bench.run_task
        def run_task(task):  # in the workers: long enough runs to signal amid them
            import time
            time.sleep(2)
            return _run_task(task)
        bench.run_task = run_task
        """))
    env["PYTHONPATH"] = os.pathsep.join([str(site), env["PYTHONPATH"]])
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [sys.executable, "-m", "bomgraph", "compare", "--streams", *map(str, streams),
         "--methods", "triangulate,stmds-cs", "--jobs", "2", "--no-figures", "--no-progress",
         "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env,
        start_new_session=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    with group_killed_at_the_end(proc):
        workers: list[int] = []
        for _ in range(1200):
            workers = [k for k in _children(proc.pid)
                       if b"popen_loky_posix" in Path(f"/proc/{k}/cmdline").read_bytes()]
            if len(workers) == 2 or proc.poll() is not None:
                break
            threading.Event().wait(0.05)
        assert len(workers) == 2, proc.communicate()
        assert all(holds_sigint_and_sigterm(k) for k in workers)
        stdout, stderr = ctrl_c(proc)
    _one_line(subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr))
    _no_temporary_files(out)


def test_runs_left_early_by_ctrl_c_close_the_workers_without_joblib_s_warning(
        streams: list[Path], recwarn: pytest.WarningsRecorder) -> None:
    # a Ctrl-C while compare handles a result (writes its cache file) closes joblib's
    # generator from outside, and joblib warned "N tasks which were still being processed by
    # the workers have been cancelled ...": two more lines on stderr, through logging
    from bomgraph.bench import Executor, _dispatch
    from bomgraph.experiments import compare_experiments

    chosen, _ = compare_experiments(streams=[str(s) for s in streams],
                                    methods="triangulate,stmds-cs")
    tasks = [t for e in chosen for t in e.tasks()]
    runs = _dispatch(tasks, list(range(len(tasks))), Executor("processes", n_jobs=2))
    assert next(runs)[1]["ok"]
    runs.close()
    assert not [w for w in recwarn if "cancelled" in str(w.message)
                or "not used" in str(w.message)], [str(w.message) for w in recwarn]


#: loky's manager thread kept from taking tasks off its queue (a loaded machine: it gets no
#: CPU) from the first task of the compare on, until the executor is shut down; the Ctrl-C
#: comes as that task is submitted
_MANAGER_THREAD_LATE = """
import threading, time
from joblib.externals.loky import process_executor as pe
_gate, _held, _thread = threading.Lock(), threading.Event(), pe._ExecutorManagerThread
_add, _submit = _thread.add_call_item_to_queue, pe.ProcessPoolExecutor.submit
def add(self):
    with _gate:
        held = _held.is_set() and not self.executor_flags.shutdown
        if not held:
            return _add(self)
    while not self.executor_flags.shutdown:
        time.sleep(0.005)
def submit(self, fn, *a, **kw):
    if fn is int:  # bomgraph's own, to start the workers
        return _submit(self, fn, *a, **kw)
    with _gate:
        _held.set()
    future = _submit(self, fn, *a, **kw)
    os.kill(os.getpid(), signal.SIGINT)
    return future
_thread.add_call_item_to_queue, pe.ProcessPoolExecutor.submit = add, submit
"""


def test_ctrl_c_before_loky_s_manager_thread_took_the_tasks_is_one_line(
        tmp_path: Path, streams: list[Path]) -> None:
    # h151, once under load: "Exception in thread ExecutorManagerThread: ... KeyError: 1"
    # above the line. joblib's abort shuts loky's executor down with kill_workers=True; its
    # manager thread then empties pending_work_items but not the queue of their ids, and
    # looks the ids still queued up in it (tasks submitted since it last ran)
    out = tmp_path / "out"
    _one_line(_compare(streams, out, _MANAGER_THREAD_LATE, "--jobs", "2"))
    _no_temporary_files(out)
