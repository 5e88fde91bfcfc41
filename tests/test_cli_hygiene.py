"""The command line behaves like a Unix tool (issue 17, point 5; issue 13, items 15, 21-23).

Every test runs ``bomgraph`` as a subprocess, as a user or a script would.
"""

from __future__ import annotations

import fcntl
import json
import os
import pty
import struct
import subprocess
import sys
import termios
from importlib.metadata import version
from pathlib import Path

import numpy as np
import pytest

from _not_writable import not_writable  # tests/_not_writable.py

from bomgraph.estimate_file import read_estimate

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1"}


def bomgraph(*args: str, stdin: bytes | None = None, timeout: float = 300,
             **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bomgraph", *args], input=stdin,
                          capture_output=True, env=ENV, timeout=timeout, **kw)


def one_error_line(proc: subprocess.CompletedProcess, *needles: str) -> str:
    err = proc.stderr.decode()
    assert proc.returncode == 2, err
    assert "Traceback" not in err
    last = err.strip().splitlines()[-1]
    assert last.startswith("bomgraph"), err
    for n in needles:
        assert n in last, last
    return last


@pytest.fixture(scope="module")
def stream(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("cli") / "s.jsonl"
    assert bomgraph("simulate", "--seed", "0", "--steps", "60", "--out", str(path)).returncode == 0
    return path


def test_version_comes_from_the_package_metadata() -> None:
    proc = bomgraph("--version")
    assert proc.returncode == 0
    assert proc.stdout.decode().strip() == f"bomgraph {version('bomgraph')}"


def test_python_dash_m_bomgraph_runs_the_command() -> None:
    proc = bomgraph("methods")
    assert proc.returncode == 0 and b"stmds-smacof" in proc.stdout


def test_verbose_logs_info_and_quiet_silences_warnings(tmp_path: Path, stream: Path) -> None:
    est = str(tmp_path / "e.json")
    loud = bomgraph("-v", "run", str(stream), "--method", "triangulate", "--out", est)
    assert loud.returncode == 0 and b"INFO: running triangulate" in loud.stderr
    plain = bomgraph("run", str(stream), "--method", "triangulate", "--out", est)
    assert plain.returncode == 0 and plain.stderr == b""
    short = tmp_path / "short.jsonl"  # 3 steps: no landmark is mapped, a warning says so
    assert bomgraph("simulate", "--steps", "3", "--out", str(short)).returncode == 0
    warned = bomgraph("run", str(short), "--method", "stmds-cs", "--out", est)
    assert warned.returncode == 0 and b"WARNING: stmds-cs mapped no landmark" in warned.stderr
    quiet = bomgraph("run", "-q", str(short), "--method", "stmds-cs", "--out", est)
    assert quiet.returncode == 0 and quiet.stderr == b""


def test_dash_is_stdin_and_stdout_on_run_and_evaluate(tmp_path: Path, stream: Path) -> None:
    by_file = tmp_path / "e.json"
    assert bomgraph("run", str(stream), "--method", "triangulate", "--out",
                    str(by_file)).returncode == 0
    piped = bomgraph("run", "-", "--method", "triangulate", "--out", "-",
                     stdin=stream.read_bytes())
    assert piped.returncode == 0, piped.stderr
    (tmp_path / "piped.est").write_bytes(piped.stdout)
    a, b = read_estimate(tmp_path / "piped.est"), read_estimate(by_file)
    assert [c.t for c in a.checkpoints] == [c.t for c in b.checkpoints]
    for ca, cb in zip(a.checkpoints, b.checkpoints):  # the estimate itself went to stdout
        np.testing.assert_array_equal(ca.estimate.landmarks_xy, cb.estimate.landmarks_xy)
        np.testing.assert_array_equal(ca.estimate.poses, cb.estimate.poses)
    assert a.stream == b.stream  # the same stream identity through stdin
    assert b"wrote -" in piped.stderr
    ev_file = bomgraph("evaluate", str(by_file), str(stream), "--json")
    ev_est = bomgraph("evaluate", "-", str(stream), "--json", stdin=by_file.read_bytes())
    ev_str = bomgraph("evaluate", str(by_file), "-", "--json", stdin=stream.read_bytes())
    assert ev_file.stdout == ev_est.stdout == ev_str.stdout and ev_file.returncode == 0
    one_error_line(bomgraph("evaluate", "-", "-", stdin=b""), "only one of")
    bad = one_error_line(bomgraph("run", "-", "--method", "triangulate", "--out", "-",
                                  stdin=b"garbage\n"), "<stdin>, line 1")
    assert "/tmp" not in bad


def _feed_fifo(path: Path, data: bytes) -> None:
    import threading

    os.mkfifo(path)
    threading.Thread(target=path.write_bytes, args=(data,), daemon=True).start()


def test_a_named_pipe_as_the_stream_is_read_once(tmp_path: Path, stream: Path) -> None:
    # `run` reads its stream twice (the run and the stream's identity; three times with
    # --progress): a named pipe gives its bytes once, and the second open waited forever
    _feed_fifo(tmp_path / "s.fifo", stream.read_bytes())
    proc = bomgraph("run", str(tmp_path / "s.fifo"), "--method", "triangulate", "--progress",
                    "--out", str(tmp_path / "e.json"), timeout=60)
    assert proc.returncode == 0, proc.stderr
    by_file = tmp_path / "f.json"
    assert bomgraph("run", str(stream), "--method", "triangulate", "--out",
                    str(by_file)).returncode == 0
    assert read_estimate(tmp_path / "e.json").stream == read_estimate(by_file).stream
    _feed_fifo(tmp_path / "bad.fifo", b"garbage\n")
    bad = one_error_line(bomgraph("run", str(tmp_path / "bad.fifo"), "--method", "triangulate",
                                  "--out", str(tmp_path / "x.json"), timeout=60),
                         f"{tmp_path / 'bad.fifo'}, line 1")
    assert "bomgraph-stdin" not in bad


@pytest.mark.parametrize("args", [["methods"], ["methods", "stmds-smacof"], ["--help"]])
def test_a_closed_pipe_ends_quietly(args: list[str]) -> None:
    cmd = f"{sys.executable} -m bomgraph {' '.join(args)} | head -c 1 >/dev/null; " \
          f"echo ${{PIPESTATUS[0]}}"
    proc = subprocess.run(["bash", "-c", cmd], capture_output=True, env=ENV, timeout=60)
    assert proc.stdout.decode().strip() in ("0", "141"), proc.stderr
    assert proc.stderr == b""


def test_a_closed_pipe_mid_estimate_ends_quietly(tmp_path: Path) -> None:
    """An estimate far larger than a pipe's buffer, read one byte of: the write really fails."""
    long = tmp_path / "long.jsonl"
    assert bomgraph("simulate", "--steps", "1500", "--landmarks", "30", "--out",
                    str(long)).returncode == 0
    cmd = f"{sys.executable} -m bomgraph run {long} --method triangulate --checkpoint-every 1 " \
          f"--out - | head -c 1 >/dev/null; echo ${{PIPESTATUS[0]}}"
    proc = subprocess.run(["bash", "-c", cmd], capture_output=True, env=ENV, timeout=300)
    assert proc.stdout.decode().strip() in ("0", "141"), proc.stderr
    assert proc.stderr == b""


def test_json_on_methods_and_run(tmp_path: Path, stream: Path) -> None:
    listed = json.loads(bomgraph("methods", "--json").stdout)
    assert {m["name"] for m in listed} >= {"triangulate", "stmds-smacof", "oracle"}
    assert [m["needs_truth"] for m in listed if m["name"] == "oracle"] == [True]
    one = json.loads(bomgraph("methods", "gtsam-batch", "--json").stdout)
    assert one["config"] == "FactorGraphConfig" and "robust" in one["presets"]
    proc = bomgraph("run", str(stream), "--method", "triangulate", "--json", "--out",
                    str(tmp_path / "e.json"))
    lines = proc.stdout.decode().splitlines()
    assert proc.returncode == 0 and len(lines) == 1
    summary = json.loads(lines[0])
    assert summary["method"] == "triangulate" and summary["t"] == 60
    assert summary["landmarks"] == len(read_estimate(tmp_path / "e.json").final)


def test_methods_name_lists_options_with_type_default_and_doc_and_presets() -> None:
    out = bomgraph("methods", "stmds-smacof").stdout.decode()
    line = next(ln for ln in out.splitlines() if ln.strip().startswith("smacof_max_iter"))
    assert "int, default 300" in line and "SMACOF iterations" in line
    assert "tri_window" in out and "int | None, default None" in out
    assert "presets" in out and "window-ba:" in out and "paper: the defaults" in out
    for name in json.loads(bomgraph("methods", "--json").stdout):
        if name["origin"] != "builtin":  # an installed plugin need not declare a config
            continue
        described = json.loads(bomgraph("methods", name["name"], "--json").stdout)
        assert described["options"], name  # every built-in method declares its config
        assert all(o["type"] for o in described["options"])
    one_error_line(bomgraph("methods", "no-such-method"), "unknown method")


def _all_parsers():
    from bomgraph.cli import build_parser

    todo = [build_parser()]
    while todo:
        p = todo.pop()
        yield p
        for action in p._actions:
            if action.choices and hasattr(action, "_name_parser_map"):
                todo.extend(action._name_parser_map.values())


def test_every_flag_has_help_text() -> None:
    import argparse

    missing = [f"{p.prog} {a.dest}" for p in _all_parsers() for a in p._actions
               if not a.help and not isinstance(a, argparse._SubParsersAction)]
    assert missing == []
    helped = bomgraph("run", "--help").stdout.decode()
    assert "--checkpoint-every" in helped and "--progress" in helped


def test_argparse_messages_show_no_internal_names() -> None:
    for args in (["simulate", "--landmarks", "x", "--out", "o"],
                 ["compare", "--jobs", "x"], ["simulate", "--seed", "-3", "--out", "o"]):
        err = bomgraph(*args).stderr.decode()
        assert "_int" not in err and "_jobs" not in err and "error:" in err
    err = bomgraph("simulate", "--landmarks", "x", "--out", "o").stderr.decode()
    assert "invalid positive integer value: 'x'" in err



def test_compare_jobs_below_minus_one_is_refused(capsys: pytest.CaptureFixture) -> None:
    # as a sweep file's executor.jobs is; joblib read -5 as "cores - 4"
    from bomgraph.cli import build_parser

    with pytest.raises(SystemExit):
        build_parser().parse_args(["compare", "--jobs", "-5"])
    assert "or -1 for one per core" in capsys.readouterr().err


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
@pytest.mark.parametrize("command", ["simulate", "run"])
def test_a_full_disk_names_the_output(stream: Path, command: str) -> None:
    # "[Errno 28] No space left on device" named no file (session 12)
    args = (["simulate", "--steps", "5"] if command == "simulate" else
            ["run", str(stream), "--method", "triangulate"])
    one_error_line(bomgraph(*args, "--out", "/dev/full"), "--out /dev/full: No space left")

def test_progress_bar_on_a_terminal_for_long_streams_only(tmp_path: Path) -> None:
    long = tmp_path / "long.jsonl"
    assert bomgraph("simulate", "--steps", "1200", "--landmarks", "5", "--out",
                    str(long)).returncode == 0
    est = str(tmp_path / "e.json")
    piped = bomgraph("run", str(long), "--method", "triangulate", "--out", est)
    assert piped.returncode == 0 and piped.stderr == b""  # not a terminal: no bar

    def on_terminal(path: Path) -> str:
        master, slave = pty.openpty()
        fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
        proc = subprocess.run([sys.executable, "-m", "bomgraph", "run", str(path), "--method",
                               "triangulate", "--out", est], stderr=slave,
                              stdout=subprocess.DEVNULL, env=ENV, timeout=300)
        os.close(slave)
        chunks = []
        try:
            while data := os.read(master, 65536):
                chunks.append(data)
        except OSError:
            pass
        os.close(master)
        assert proc.returncode == 0
        return b"".join(chunks).decode(errors="replace")

    assert "1201/1201" in on_terminal(long)
    short = tmp_path / "short.jsonl"
    assert bomgraph("simulate", "--steps", "50", "--out", str(short)).returncode == 0
    assert on_terminal(short) == ""


# -- issue 13 ---------------------------------------------------------------------------------

@pytest.mark.parametrize("option", ["tri_window=abc", "tri_window=NaN", "tri_window=Infinity",
                                    "smacof_max_iter=Infinity", "smacof_max_iter=2.5",
                                    "smacof_tol=abc", "map_unobserved=1"])
def test_wrong_option_types_give_one_line_and_exit_2(tmp_path: Path, stream: Path,
                                                     option: str) -> None:
    out = tmp_path / "e.json"
    one_error_line(bomgraph("run", str(stream), "--method", "stmds-smacof", "--option", option,
                            "--out", str(out)), option.split("=")[0])
    assert not out.exists()


def test_every_method_checks_its_option_types() -> None:
    """In-process over every field of every method's config: a value of the wrong kind is a
    ConfigError naming the field (a string for numbers and flags, a float for ints, NaN)."""
    import typing

    from bomgraph.errors import ConfigError
    from bomgraph.mapper import available_methods, method_config_class

    for info in available_methods():
        if info.origin != "builtin":  # plugins: tests/test_plugins.py
            continue
        cls = method_config_class(info.name)
        for name, hint in typing.get_type_hints(cls).items():
            if name == "PRESETS":
                continue
            kinds = {hint, *typing.get_args(hint)}
            bad = ([1] if bool in kinds else ["abc", float("nan")] if float in kinds
                   else ["abc", 2.5, float("inf")] if int in kinds else [])
            for value in bad:
                with pytest.raises(ConfigError, match=name):
                    cls.preset(**{name: value})


def test_run_checks_out_before_computing(tmp_path: Path, stream: Path) -> None:
    before = stream.read_bytes()
    one_error_line(bomgraph("run", str(stream), "--method", "gtsam-batch", "--out",
                            str(stream)), "is the input")
    assert stream.read_bytes() == before
    one_error_line(bomgraph("run", str(stream), "--method", "gtsam-batch", "--out",
                            str(tmp_path)), "is a directory")
    one_error_line(bomgraph("run", str(stream), "--method", "gtsam-batch", "--out",
                            str(tmp_path / "nowhere" / "e.json")), "does not exist")
    locked = tmp_path / "locked"
    locked.mkdir()
    with not_writable(locked):  # root too (it ran only where os.access said so: never in CI)
        one_error_line(bomgraph("run", str(stream), "--method", "gtsam-batch", "--out",
                                str(locked / "e.json")), "not writable")
    assert list(locked.iterdir()) == []


def test_gz_hint_only_where_the_bytes_say_gzip(tmp_path: Path) -> None:
    import gzip

    from bomgraph.datasets._text import read_lines

    def read_text(path):
        return list(read_lines(path))
    from bomgraph.errors import DatasetError

    fake = tmp_path / "plain.dat.gz"
    fake.write_text("1 2 3\n")
    with pytest.raises(DatasetError, match="named .gz but not gzip data"):
        read_text(fake)
    hidden = tmp_path / "hidden.dat"  # gzip bytes under a plain name
    hidden.write_bytes(gzip.compress(b"1 2 3\n"))
    with pytest.raises(DatasetError, match="it is gzip data"):
        read_text(hidden)
    junk = tmp_path / "junk.dat"  # not UTF-8 and not gzip: no word about .gz
    junk.write_bytes(b"\xff\xfe\x00 1 2 3\n")
    with pytest.raises(DatasetError) as exc:
        read_text(junk)
    assert "gz" not in str(exc.value).replace(str(junk), "")
    with pytest.raises(DatasetError) as exc:
        read_text(tmp_path)  # a directory
    assert "gz" not in str(exc.value).replace(str(tmp_path), "")
    proc = bomgraph("import", "mrclam", str(tmp_path), "--robot", "1", "--out",
                    str(tmp_path / "o.jsonl"))
    assert proc.returncode == 2 and b"Traceback" not in proc.stderr


def test_dash_is_stdin_and_stdout_on_export(tmp_path: Path, stream: Path) -> None:
    est = tmp_path / "e.est"
    assert bomgraph("run", str(stream), "--method", "ekf", "--out", str(est)).returncode == 0
    by_file = tmp_path / "e.tum"
    assert bomgraph("export", str(est), "--stream", str(stream), "--format", "tum", "--out",
                    str(by_file)).returncode == 0
    piped = bomgraph("export", "-", "--stream", str(stream), "--format", "tum", "--out", "-",
                     stdin=est.read_bytes())
    assert piped.returncode == 0 and piped.stdout == by_file.read_bytes()
    truth = bomgraph("export", "--truth", "-", "--format", "csv", "--out", "-",
                     stdin=stream.read_bytes())
    assert truth.returncode == 0 and truth.stdout.startswith(b"kind,id,x_m,y_m,psi_rad,time_s")
    one_error_line(bomgraph("export", "-", "--stream", "-", "--format", "tum", "--out", "x"),
                   "only one of")


def test_compare_out_that_is_a_file_is_named_and_kept(tmp_path: Path) -> None:
    """`compare --out` naming an existing file: one line saying so, the file untouched (it
    was the bare "[Errno 17] File exists")."""
    target = tmp_path / "results"
    target.write_text("keep me")
    one_error_line(bomgraph("compare", "--quick", "--no-progress", "--no-figures", "--out",
                            str(target)), "--out", "is a file; give a folder")
    assert target.read_text() == "keep me"


def test_bomgraphs_own_memory_error_is_one_line_exit_1(monkeypatch: pytest.MonkeyPatch,
                                                       capsys: pytest.CaptureFixture) -> None:
    """Running out of memory in bomgraph's own code (h91: an importer at its size cap under a
    memory limit) is one line saying so and what to try, exit 1: before, a traceback."""
    import bomgraph.cli as cli

    def exhausted(args: object) -> int:
        raise MemoryError("Unable to allocate 1.2 GiB for an array")

    monkeypatch.setitem(cli._COMMANDS, "cmd_methods", exhausted)
    assert cli.main(["methods"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("bomgraph: error: out of memory (Unable to allocate 1.2 GiB"), err
    assert "smaller input or fewer --jobs" in err
