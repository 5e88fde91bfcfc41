"""h107: small leads from the 30th session's reviews.

- ``bomgraph --help > /dev/full`` exited 0 and said nothing (argparse ignores an error writing
  its help), where ``bomgraph methods > /dev/full`` says the error in one line and exits 2.
- ``plugins._disk_digest`` and ``_code_entries`` (now ``source_files``'s, with the rule in
  ``file_digest``) judged a status racy against the clock after the read (or the listing), as
  ``file_digest`` did before c675047: a read taking seconds kept a digest (a listing) whose
  status a write in the same tick, during it, leaves unchanged. A fake clock here (no
  timing), as tests/test_h105_review.py's: the read "takes" 3 s.
- Library refusals that named command-line options (``Executor.choose(scheduler="")``:
  "--scheduler is empty") name the parameters from Python, the options while a command runs
  (``checks.option_named``, as 053e51f).
- Without ``fcntl`` (Windows) ``stdio.folder_lock`` took no lock and said nothing; now a
  warning says so, once a process.
"""

from __future__ import annotations

import logging
import os
import shlex
import subprocess
import sys
import types
from pathlib import Path
from typing import Callable

import pytest

from bomgraph import (bench, cluster, experiments, file_digest, jsonio, source_files,
                      stdio)
from bomgraph.checks import command_line
from bomgraph.errors import ConfigError

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
        "bomgraph: error: the standard output: No space left on device"]


def test_help_into_a_closed_pipe_or_closed_stdout_stays_quiet(tmp_path: Path) -> None:
    """As before: a closed pipe (``| true``) and a closed stdout (``>&-``, 255f1cc) say
    nothing."""
    done = _bash(tmp_path, f"{BOMGRAPH} --help >&-")
    assert (done.returncode, done.stderr) == (0, b"")
    done = _bash(tmp_path, f"{BOMGRAPH} compare --help | true; echo ${{PIPESTATUS[0]}}")
    assert done.stderr == b"", done.stderr[:300]
    assert done.stdout.decode().strip() in ("0", "141"), done.stdout


def _fake_clock(monkeypatch: pytest.MonkeyPatch, path: Path) -> list[int]:
    """A clock 0.5 s after ``path``'s last change, for ``file_digest`` (the rule)."""
    st = path.stat()
    clock = [max(st.st_mtime_ns, st.st_ctime_ns) + 500_000_000]
    monkeypatch.setattr(file_digest, "time", types.SimpleNamespace(time_ns=lambda: clock[0]))
    monkeypatch.setattr(file_digest, "RACY_NS", 2_000_000_000)
    return clock


def test_a_source_digest_is_not_kept_when_its_status_was_racy_when_taken(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Fails before: the status, taken 0.5 s after the file's change, was judged after the
    3 s read (3.5 s: aged) and kept."""
    path = tmp_path / "m.py"
    path.write_bytes(b"x = 1\n")
    clock = _fake_clock(monkeypatch, path)
    read = source_files.read

    def slow_read(p: Path) -> bytes:
        clock[0] += 3_000_000_000
        return read(p)

    monkeypatch.setattr(source_files, "read", slow_read)
    monkeypatch.setattr(source_files, "_DISK", {})
    assert source_files.disk_digest(path) == source_files.digest(b"x = 1\n")
    assert path not in source_files._DISK
    source_files.disk_digest(path)  # now 3.5 s after its change: aged, kept
    assert path in source_files._DISK


def test_a_folder_listing_is_not_kept_when_its_status_was_racy_when_taken(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Fails before, as the digest: the folder's status judged after a 3 s listing."""
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "m.py").write_text("x = 1\n")
    folder = str(tmp_path / "pkg")
    clock = _fake_clock(monkeypatch, tmp_path / "pkg")
    scandir = os.scandir

    def slow_scandir(p: str):  # noqa: ANN202
        clock[0] += 3_000_000_000
        return scandir(p)

    monkeypatch.setattr(source_files.os, "scandir", slow_scandir)
    monkeypatch.setattr(source_files, "_FOLDERS", {})
    monkeypatch.setattr(source_files, "_LISTED", {})
    assert [rel for rel, _ in source_files.py_files(folder)] == ["m.py"]
    assert folder not in source_files._FOLDERS and folder not in source_files._LISTED
    assert [rel for rel, _ in source_files.py_files(folder)] == ["m.py"]  # 3.5 s after: aged
    assert folder in source_files._FOLDERS and folder in source_files._LISTED


LIBRARY_REFUSALS = [
    (lambda: bench.Executor.choose(scheduler=""),
     "scheduler is empty; give the address",
     "--scheduler is empty; give the address"),
    (lambda: bench.Executor("dask", scheduler="http://x:1"),
     "scheduler='http://x:1': not a Dask scheduler address",
     "--scheduler http://x:1: not a Dask scheduler address"),
    (lambda: experiments.compare_experiments(config="paper", streams=["a"]),
     "compare_experiments(): give one of config, streams, real, not config and streams",
     "compare: give one of --config, --streams, --real, not --config and --streams"),
    (lambda: experiments.compare_experiments(methods="ekf"),
     "compare_experiments(): methods goes with streams or real (in a sweep file: [[methods]]",
     "compare: --methods goes with --streams FILE... or --real DIR (in a sweep file: "),
    (lambda: experiments.compare_experiments(checkpoint_every=3),
     "compare_experiments(): checkpoint_every goes with streams (in a sweep file: ",
     "compare: --checkpoint-every goes with --streams FILE... (in a sweep file: "),
    (lambda: experiments.compare_experiments(options=["a:b=1"]),
     "compare_experiments(): options goes with streams (in",
     "compare: --option goes with --streams FILE... (in"),
    (lambda: experiments.compare_experiments(real="x", methods="ekf@fast"),
     "compare_experiments(): methods with real: give names without a preset ('ekf@fast')",
     "compare --real --methods: give names without a preset ('ekf@fast')"),
    (lambda: experiments.compare_experiments(real="x", methods=" , "),
     "compare_experiments(): methods with real: give at least one method",
     "compare --real --methods: give at least one method"),
    (lambda: experiments.compare_experiments(streams=["nofile"], methods="ekf"),
     "streams: no such file nofile", "--streams: no such file nofile"),
    (lambda: experiments.compare_experiments(streams=["nofile"], methods=""),
     "methods: give at least one method", "--methods: give at least one method"),
    (lambda: experiments.compare_experiments(streams=["nofile"], methods="ekf,x@",
                                             options=["bad"]),
     "methods='x@': 'x@' is not NAME or NAME@PRESET", "--methods x@: 'x@' is not NAME or"),
    (lambda: experiments.compare_experiments(streams=["nofile"], methods="ekf",
                                             options=["ukf:a=1"]),
     "options ukf:a=1: 'ukf' is not one of methods ekf",
     "--option ukf:a=1: 'ukf' is not one of --methods ekf"),
    (lambda: jsonio.options_to_json({"a": "Infinity"}),
     "option value 'Infinity': a record writes an infinity so (it would read back as inf); "
     "give the number (float('inf')) or another string",
     "option value 'Infinity': a record writes an infinity so (it would read back as inf); "
     "give the number (--option KEY=inf) or another string"),
]


@pytest.mark.parametrize("call, library, command", LIBRARY_REFUSALS, ids=[
    "empty-scheduler", "bad-scheduler", "two-sources", "methods", "checkpoint-every", "options",
    "real-preset", "real-none", "streams-missing", "methods-none", "method-token",
    "option-target", "infinity-string"])
def test_library_refusals_name_the_parameters_and_the_options_on_the_command_line(
        call: Callable[[], object], library: str, command: str) -> None:
    """Fails before for the library wording: ``Executor.choose(scheduler="")`` said
    "--scheduler is empty", ``compare_experiments(methods=...)`` "compare: --methods goes
    with --streams FILE...". While a command runs (``checks.command_line``), the options."""
    with pytest.raises(ConfigError) as exc:
        call()
    assert str(exc.value).startswith(library), str(exc.value)
    with command_line(), pytest.raises(ConfigError) as exc:
        call()
    assert str(exc.value).startswith(command), str(exc.value)


def test_check_scheduler_names_its_address_parameter(tmp_path: Path) -> None:
    """Fails before: ``check_scheduler(address)`` from Python said "--scheduler ADDRESS"
    (port 1: nothing listens there, refused at once)."""
    address = "tcp://127.0.0.1:1"
    with pytest.raises(ConfigError) as exc:
        cluster.check_scheduler(address, 5)
    assert str(exc.value).startswith(f"address={address!r}: no Dask scheduler"), exc.value
    with command_line(), pytest.raises(ConfigError) as exc:
        cluster.check_scheduler(address, 5)
    assert str(exc.value).startswith(f"--scheduler {address}: no Dask scheduler"), exc.value


def test_without_flock_a_compare_folder_is_not_locked_and_a_warning_says_so_once(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        caplog: pytest.LogCaptureFixture) -> None:
    """No ``fcntl`` (Windows, simulated as tests/test_h83_leftovers_review.py does): no lock
    is taken (two holders at once), and one warning per process says so. Fails before:
    nothing was said."""
    monkeypatch.setitem(sys.modules, "fcntl", None)
    monkeypatch.setattr(stdio, "_NO_LOCK_SAID", [], raising=False)
    caplog.set_level(logging.WARNING, logger="bomgraph")
    with stdio.folder_lock(tmp_path, "compare"), stdio.folder_lock(tmp_path, "compare"):
        pass
    with stdio.folder_lock(tmp_path / "other", "compare", shared=True):
        pass
    said = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert said == [f"{tmp_path} is not locked: this platform has no flock, so two compares "
                    f"into one folder at once are not kept apart; run one at a time"]
    assert not (tmp_path / ".bomgraph.lock").exists()
