"""The command started with a standard descriptor closed (``<&-``, ``>&-``, ``2>&-``), run as
a user runs it: ``bomgraph`` in a subprocess under a real shell redirect (h92).

The first file the command opened took the free number, so whatever wrote to descriptor 1
or 2 after (a method's C library, as GTSAM's ``std::cout`` does; here a plugin that writes
to the descriptors directly) wrote into that file: ``compare --out D >&-`` put it into
``D/.bomgraph.lock``. Now /dev/null is put on each closed one before anything is opened.
"""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from _plugin_dist import write_dist_info

ROOT = Path(__file__).resolve().parents[1]
BOMGRAPH = f"{shlex.quote(sys.executable)} -m bomgraph"

SHOUTER = textwrap.dedent('''
    import os

    from bomgraph.mapper import MapEstimate


    def _shout(what):
        for fd in (1, 2):
            try:
                os.write(fd, b"STRAY %s fd%d\\n" % (what, fd))
            except OSError:
                pass


    class Shouter:
        """writes to descriptors 1 and 2 directly, as a C library's printf does"""

        def __init__(self, header) -> None:
            pass

        def step(self, step) -> None:
            if step.t == 3:
                _shout(b"step")

        def estimate(self):
            _shout(b"estimate")
            return MapEstimate.empty()
''')


@pytest.fixture()
def shouter_env(tmp_path: Path) -> dict[str, str]:
    """An environment whose PYTHONPATH holds the plugin ``shouter`` (entry point included)."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "shout_plugin.py").write_text(SHOUTER)
    write_dist_info(site, "shout-plugin", {"shouter": "shout_plugin:Shouter"})
    return {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{site}", "OMP_NUM_THREADS": "1"}


def _files_with(folder: Path, text: bytes) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*")
                  if p.is_file() and text in p.read_bytes())


@pytest.mark.parametrize("closed", [">&-", "<&- >&-", "2>&-", ">&- 2>&-", "<&-"])
def test_nothing_written_to_a_closed_descriptor_lands_in_an_output(
        tmp_path: Path, shouter_env: dict[str, str], closed: str) -> None:
    """Fails before h92 with ``>&-``: ``cc/.bomgraph.lock`` held ``STRAY estimate fd1``."""
    work = tmp_path / "work"
    work.mkdir()
    assert subprocess.run(["bash", "-c", f"{BOMGRAPH} simulate --steps 30 --landmarks 8 "
                           f"--out s.jsonl"], cwd=work, env=shouter_env, capture_output=True,
                          check=False).returncode == 0
    script = (f"{BOMGRAPH} simulate --steps 10 --out sim.jsonl {closed} || exit 10; "
              f"{BOMGRAPH} run s.jsonl --method shouter --out r.est {closed} || exit 11; "
              f"{BOMGRAPH} compare --streams s.jsonl --methods shouter,triangulate --out cc "
              f"--jobs 1 --estimates --no-figures {closed} || exit 12")
    done = subprocess.run(["bash", "-c", script], cwd=work, env=shouter_env,
                          capture_output=True, check=False)
    assert done.returncode == 0, done.stderr
    assert b"Traceback" not in done.stderr, done.stderr
    assert _files_with(work, b"STRAY") == []
    assert (work / "r.est").read_bytes().startswith(b'{"format"')
    assert (work / "cc" / "results.json").is_file()


def test_a_closed_stdout_is_still_refused_as_out(tmp_path: Path) -> None:
    """/dev/null on descriptor 1 is no output: ``--out /dev/stdout >&-`` is still refused in
    one line, as ``--out -``; ``--out /dev/stderr 2>&-`` too (before h92 it wrote /dev/null,
    which the logging had put on descriptor 2, and exited 0)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    for out, closed in (("/dev/stdout", ">&-"), ("/dev/fd/1", ">&-"), ("-", ">&-"),
                        ("/dev/stderr", "2>&-")):
        done = subprocess.run(["bash", "-c", f"{BOMGRAPH} simulate --steps 5 --out {out} "
                               f"{closed}"], cwd=tmp_path, env=env, capture_output=True,
                              check=False)
        assert done.returncode == 2, (out, done.stderr)


def test_compare_in_worker_processes_with_stdout_closed(tmp_path: Path,
                                                        shouter_env: dict[str, str]) -> None:
    """loky flushes ``sys.stdout`` and ``sys.stderr`` before it starts each worker: with the
    shell's ``>&-`` (``sys.stdout`` None) ``compare --jobs 2`` ended in a traceback
    (AttributeError: 'NoneType' object has no attribute 'flush'), and the library's
    ``compare`` with ``Executor("processes")`` in a process that had closed its
    ``sys.stdout`` raised ValueError: I/O operation on closed file. Fails before h92."""
    assert subprocess.run(["bash", "-c", f"{BOMGRAPH} simulate --steps 30 --landmarks 8 "
                           f"--out s.jsonl"], cwd=tmp_path, env=shouter_env,
                          capture_output=True, check=False).returncode == 0
    done = subprocess.run(["bash", "-c", f"{BOMGRAPH} compare --streams s.jsonl --methods "
                           f"shouter,triangulate --out cli --jobs 2 --no-figures >&-"],
                          cwd=tmp_path, env=shouter_env, capture_output=True, check=False)
    assert done.returncode == 0 and b"Traceback" not in done.stderr, done.stderr
    assert _files_with(tmp_path / "cli", b"STRAY") == []
    script = textwrap.dedent("""
        import sys
        from bomgraph.bench import Executor
        from bomgraph.experiments import compare_experiments
        from bomgraph.report import compare

        if __name__ == "__main__":
            experiments, _ = compare_experiments(streams=["s.jsonl"],
                                                 methods="shouter,triangulate")
            sys.stdout.close()
            result = compare(experiments, "lib", executor=Executor("processes", n_jobs=2),
                             figures=False)
            assert sys.stdout.closed  # the caller's, as it was
            print(len(result.results), sum(r["ok"] for r in result.results), file=sys.stderr)
        """)
    (tmp_path / "lib.py").write_text(script)
    done = subprocess.run([sys.executable, "lib.py"], cwd=tmp_path, env=shouter_env,
                          capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    assert done.stderr.splitlines()[-1] == "2 2", done.stderr


def test_main_in_a_process_that_closed_its_sys_stdout_or_stderr(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``sys.stdout.close()`` (or ``sys.stderr.close()``) in the caller, then
    :func:`bomgraph.cli.main`: the output was written, then the first line printed raised
    ValueError: I/O operation on closed file out of main(). A closed stream is taken for the
    shell's ``>&-`` now (its lines dropped, ``--out -`` refused as closed) and left as it
    was. Fails before h92."""
    import io

    from bomgraph.cli import main

    simulate = ["simulate", "--steps", "8", "--landmarks", "4", "--out"]
    assert main([*simulate, str(tmp_path / "plain")]) == 0
    closed = io.StringIO()
    closed.close()
    monkeypatch.setattr(sys, "stdout", closed)
    assert main([*simulate, str(tmp_path / "a")]) == 0
    assert main([*simulate, "-"]) == 2
    assert sys.stdout is closed
    data = io.StringIO()
    monkeypatch.setattr(sys, "stdout", data)
    monkeypatch.setattr(sys, "stderr", closed)
    assert main([*simulate, "-"]) == 0  # the line "wrote -: ..." to stderr: dropped
    assert sys.stderr is closed
    monkeypatch.undo()
    assert (tmp_path / "a").read_text() == (tmp_path / "plain").read_text() == data.getvalue()



@pytest.mark.parametrize("args, status", [("--help", 0), ("--version", 0), ("compare --help", 0),
                                          ("methods", 0), ("compare --bogus", 2)])
def test_help_and_version_with_stdout_closed_are_dropped_as_a_commands_lines(
        tmp_path: Path, args: str, status: int) -> None:
    """h101: ``bomgraph --help >&-`` printed the help to stderr (argparse's fallback when
    sys.stdout is None), where every command drops its own lines (``methods >&-``: nothing,
    exit 0). Now the help and the version are dropped too; a usage error still goes to
    stderr. Fails before for --help, --version and compare --help."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    done = subprocess.run(["bash", "-c", f"{BOMGRAPH} {args} >&-"], cwd=tmp_path, env=env,
                          capture_output=True, check=False)
    assert done.returncode == status, done.stderr[:200]
    if status == 0:
        assert done.stderr == b"", done.stderr[:200]
    else:
        assert done.stderr.decode().splitlines() == [
            "bomgraph compare: error: unrecognized arguments: --bogus; see bomgraph compare "
            "--help"], done.stderr
