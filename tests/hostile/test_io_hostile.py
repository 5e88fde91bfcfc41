"""The hostile battery of issue 13, input/output and command-line items (3-6, 9, 10, 13-23 and
the reader side of 11), each reproduced as a user meets it: ``bomgraph`` in a subprocess,
small inputs written by the test, memory-hungry cases under ``resource.setrlimit``.

Each test asserts the user-facing rule: a result, or exit 2 with one line
``bomgraph: error: ...`` naming the cause; no traceback; inputs intact; no stray files.
"""

from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from hostile_helpers import ENV, HEADER, ROOT, bomgraph, no_traceback, one_error, snapshot

sys.path.insert(0, str(ROOT / "tests" / "datasets"))
from dataset_excerpts import make_mrclam, write_g2o  # noqa: E402

from bomgraph.estimate_file import write_estimate  # noqa: E402
from bomgraph.mapper import Checkpoint, MapEstimate, RunResult  # noqa: E402
from bomgraph.sim import SimConfig, simulate  # noqa: E402
from bomgraph.stream import Step, Stream, StreamHeader, Truth  # noqa: E402
from bomgraph.stream_file import write_stream  # noqa: E402


def _g2o(folder: Path, stream: Stream, name: str = "data.g2o", **kw) -> Path:
    path = folder / name
    write_g2o(path, stream, **kw)
    return path


def _estimate(stream: Stream, path: Path, offset: float = 0.0) -> Path:
    """The truth itself written as an estimate file (a perfect run), shifted by ``offset``."""
    t = stream.truth
    est = MapEstimate(t.landmark_ids, t.landmarks_xy + offset, np.arange(len(t.poses)),
                      t.poses + np.array([offset, offset, 0.0]))
    last = len(stream.steps) - 1
    write_estimate(RunResult("oracle", (Checkpoint(last, est, 0.0),), np.zeros(1), 0.0), path)
    return path


# ---- item 3: estimate files linear in T -----------------------------------------------------

def test_item03_estimate_file_grows_linearly_with_the_run(tmp_path: Path) -> None:
    sizes = []
    for n in (400, 1600):
        s = tmp_path / f"s{n}.jsonl"
        write_stream(simulate(SimConfig(n_steps=n), np.random.default_rng(1)), s)
        e = tmp_path / f"e{n}.jsonl"
        proc = bomgraph("run", s, "--method", "triangulate", "--out", e)
        assert proc.returncode == 0, no_traceback(proc)
        sizes.append(e.stat().st_size)
    assert sizes[1] / sizes[0] < 6, sizes  # linear: ~4; the old O(T^2) files: ~16


# ---- item 4: --out that is a device, a FIFO, a link, /dev/stdout ------------------------------

@pytest.mark.parametrize("command", ["simulate", "import"])
def test_item04_out_symlink_fifo_and_stdout_are_written_not_replaced(
        tmp_path: Path, sim: Stream, command: str) -> None:
    g2o = _g2o(tmp_path, sim)
    args = (["simulate", "--steps", "20"] if command == "simulate"
            else ["import", "g2o", str(g2o)])
    target = tmp_path / "target.jsonl"
    link = tmp_path / "link.jsonl"
    link.symlink_to(target.name)
    proc = bomgraph(*args, "--out", link)
    assert proc.returncode == 0, no_traceback(proc)
    assert link.is_symlink() and target.is_file() and target.read_bytes().startswith(b'{"format"')
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    got: list[bytes] = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_bytes()))
    reader.start()
    proc = bomgraph(*args, "--out", fifo)
    reader.join(60)
    assert proc.returncode == 0, no_traceback(proc)
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode) and got and got[0].startswith(b'{"format"')
    proc = bomgraph(*args, "--out", "/dev/stdout")  # stdout is a pipe here
    assert proc.returncode == 0, no_traceback(proc)
    assert proc.stdout.startswith(b'{"format"') and b"wrote" in proc.stderr
    with open(tmp_path / "redirected", "wb") as fh:  # stdout is a regular file: not renamed over
        before = os.fstat(fh.fileno()).st_ino
        proc = bomgraph(*args, "--out", "/dev/stdout", stdout=fh)
    assert proc.returncode == 0 and (tmp_path / "redirected").stat().st_ino == before
    assert (tmp_path / "redirected").read_bytes().startswith(b'{"format"')
    names = {p.name for p in tmp_path.iterdir()}
    assert names == {"data.g2o", "target.jsonl", "link.jsonl", "pipe", "redirected"}, names


def test_item04_a_character_device_stays_a_device(tmp_path: Path) -> None:
    from bomgraph.stdio import AtomicOutput

    assert AtomicOutput("/dev/null").direct  # checked first: a regression must not hit /dev
    null = tmp_path / "null"
    try:  # a private copy of /dev/null, so a regression replaces only this node
        os.mknod(null, stat.S_IFCHR | 0o666, os.makedev(1, 3))
    except PermissionError:
        null = Path("/dev/null")
    for args in (["simulate", "--steps", "5"], ["run", "-", "--method", "triangulate"]):
        stdin = None
        if args[0] == "run":
            write_stream(simulate(SimConfig(n_steps=5), np.random.default_rng(0)),
                         tmp_path / "s.jsonl")
            stdin = (tmp_path / "s.jsonl").read_bytes()
        proc = bomgraph(*args, "--out", null, stdin=stdin)
        assert proc.returncode == 0, no_traceback(proc)
        assert stat.S_ISCHR(os.stat(null).st_mode)
    assert not list(tmp_path.glob(".*partial"))


def test_item04_out_that_is_a_directory_or_socket_is_refused(tmp_path: Path) -> None:
    import socket

    one_error(bomgraph("simulate", "--out", tmp_path), "is a directory")
    # an empty name was the working folder: simulated, then a rename of .NAME.partial over it
    (tmp_path / "cwd").mkdir()
    one_error(bomgraph("simulate", "--out", "", cwd=tmp_path / "cwd"), "--out is empty")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cwd"]
    sock_path = tmp_path / "sock"
    sock = socket.socket(socket.AF_UNIX)
    sock.bind(str(sock_path))
    try:
        one_error(bomgraph("simulate", "--out", sock_path), "neither a regular file")
    finally:
        sock.close()


# ---- item 5: --out equal to an input --------------------------------------------------------

def test_item05_out_equal_to_an_input_is_refused_and_the_input_kept(work: Path,
                                                                    sim: Stream) -> None:
    g2o = _g2o(work, sim)
    (work / "alias.jsonl").symlink_to("s.jsonl")
    os.link(work / "s.jsonl", work / "hard.jsonl")
    before = snapshot(work)
    for out in ("s.jsonl", "alias.jsonl", "hard.jsonl", "./s.jsonl"):
        one_error(bomgraph("run", "s.jsonl", "--method", "triangulate", "--out", out, cwd=work),
                  "is the input")
    one_error(bomgraph("import", "g2o", g2o, "--out", g2o), "is the input")
    one_error(bomgraph("import", "g2o", g2o, "--truth", work / "s.jsonl", "--out",
                       work / "alias.jsonl"), "is the input")
    one_error(bomgraph("evaluate", "s.jsonl", "s.jsonl", cwd=work), "stream file")
    assert snapshot(work) == before


def test_item05_import_mrclam_refuses_to_overwrite_a_dataset_file(tmp_path: Path) -> None:
    d = tmp_path / "mr"
    make_mrclam(d)
    before = snapshot(d)
    one_error(bomgraph("import", "mrclam", d, "--robot", "1", "--out",
                       d / "Robot1_Odometry.dat"), "is the input")
    assert snapshot(d) == before


# ---- item 6: two sweeps in one folder; results written atomically ----------------------------

def test_item06_a_second_compare_into_a_locked_folder_is_refused_at_once(tmp_path: Path) -> None:
    from bomgraph.stdio import folder_lock

    out = tmp_path / "cmp"
    out.mkdir()
    holder = subprocess.Popen(  # a first sweep holding the folder
        [sys.executable, "-c", "import sys, time; from bomgraph.stdio import folder_lock\n"
         "with folder_lock(sys.argv[1], 'test'):\n    print('held', flush=True)\n"
         "    time.sleep(120)", str(out)], stdout=subprocess.PIPE, env=ENV)
    try:
        assert holder.stdout.readline() == b"held\n"
        before = snapshot(out)
        line = one_error(bomgraph("compare", "--quick", "--experiments", "exp1", "--jobs", "1",
                                  "--no-figures", "--no-progress", "--out", out),
                         "another", "is writing into this folder", str(holder.pid))
        assert "--out" in line
        assert snapshot(out) == before  # nothing run, nothing written
    finally:
        holder.kill()
        holder.wait()
    with folder_lock(out, "test"):  # released when its holder dies
        pass


def test_item06_results_tables_are_written_atomically(tmp_path: Path) -> None:
    from bomgraph.report import write_csv

    path = tmp_path / "results.csv"
    write_csv(path, [{"a": 1, "b": 2}])
    good = path.read_bytes()

    class Bad:
        def __str__(self) -> str:
            raise RuntimeError("boom")

    with pytest.raises(RuntimeError):
        write_csv(path, [{"a": 1, "b": 2}] * 1000 + [{"a": Bad(), "b": 1}])
    assert path.read_bytes() == good and os.listdir(tmp_path) == ["results.csv"]


# ---- item 9: collinear landmarks, huge coordinates -----------------------------------------

def _collinear_stream() -> Stream:
    lm = np.column_stack([np.linspace(0.0, 3.0, 6), np.ones(6)])
    poses = np.column_stack([np.linspace(0.0, 3.0, 12), np.full(12, -0.5), np.zeros(12)])
    steps = [Step(t, None if t == 0 else [3 / 11, 0.0, 0.0], np.arange(6),
                  np.arctan2(lm[:, 1] - poses[t, 1], lm[:, 0] - poses[t, 0]))
             for t in range(12)]
    return Stream(StreamHeader(0.01, (0.01, 0.0, 0.01)), tuple(steps),
                  Truth(np.arange(6), lm, poses))


def test_item09_collinear_landmarks_are_not_scored_mirrored(tmp_path: Path) -> None:
    s = _collinear_stream()
    write_stream(s, tmp_path / "c.jsonl")
    _estimate(s, tmp_path / "e.jsonl")
    proc = bomgraph("evaluate", tmp_path / "e.jsonl", tmp_path / "c.jsonl", "--json")
    assert proc.returncode == 0, no_traceback(proc)
    ev = json.loads(proc.stdout)
    assert ev["robot_last_m"] is not None and ev["robot_last_m"] < 0.01, ev  # the mirror: 3 m
    assert ev["reflected"] is False


def test_item09_huge_coordinates_do_not_print_inf(tmp_path: Path) -> None:
    s = _collinear_stream()
    write_stream(s, tmp_path / "c.jsonl")
    _estimate(s, tmp_path / "e.jsonl", offset=1e200)
    proc = bomgraph("evaluate", tmp_path / "e.jsonl", tmp_path / "c.jsonl")
    err = no_traceback(proc)
    assert proc.returncode in (0, 2), err
    assert "inf" not in proc.stdout.decode().lower() and "nan" not in proc.stdout.decode().lower()


# ---- item 10: deep JSON ------------------------------------------------------------------------

@pytest.mark.parametrize("where", ["meta", "step"])
def test_item10_deeply_nested_json_is_a_format_error(tmp_path: Path, where: str) -> None:
    deep = "[" * 5000 + "]" * 5000
    header = json.dumps(HEADER)[:-1] + (f', "meta": {{"x": {deep}}}}}' if where == "meta" else "}")
    step = '{"t": 0, "bearings": []}' if where == "meta" else f'{{"t": 0, "bearings": {deep}}}'
    (tmp_path / "d.jsonl").write_text(header + "\n" + step + "\n")
    one_error(bomgraph("run", tmp_path / "d.jsonl", "--method", "triangulate", "--out",
                       tmp_path / "e.jsonl"), "d.jsonl", "line")
    assert sorted(os.listdir(tmp_path)) == ["d.jsonl"]


@pytest.mark.parametrize("where", ["mkstemp", "chmod", "fdopen"])
def test_sigterm_as_the_temporary_file_is_created_leaves_nothing(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, where: str) -> None:
    """A SIGTERM that arrives while the ``.partial`` file is being created (CI once saw
    ``[Errno 9] Bad file descriptor`` instead of exit 143): SystemExit comes out, the
    descriptor is closed once, nothing is left beside the target."""
    import tempfile

    import bomgraph.stdio as stdio

    real = {"mkstemp": tempfile.mkstemp, "chmod": os.chmod, "fdopen": os.fdopen}

    def arrives(*a, **kw):  # the real call, then the signal, as if it came during it
        out = real[where](*a, **kw)  # to the main thread, as the CLI (one thread) gets it
        signal.pthread_kill(threading.main_thread().ident, signal.SIGTERM)
        return out

    def raise_exit(signum, frame):
        raise SystemExit(143)

    monkeypatch.setattr({"mkstemp": tempfile, "chmod": stdio.os,
                         "fdopen": stdio.os}[where], where, arrives)
    # (a process-wide signal may go to any thread that does not block it, which then has the
    # main thread run the handler at once: the mask is a guarantee for one-thread processes)
    old = signal.signal(signal.SIGTERM, raise_exit)
    target = tmp_path / "out.txt"
    try:
        with pytest.raises(SystemExit) as exc:
            with stdio.output_file(target) as fh:
                fh.write("never")
    finally:
        signal.signal(signal.SIGTERM, old)
    assert exc.value.code == 143
    assert sorted(p.name for p in tmp_path.iterdir()) == []
