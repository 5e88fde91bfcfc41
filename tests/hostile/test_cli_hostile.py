"""The hostile battery of issue 13, continued: bounded input (14), option types (15), atomic
estimates and signals (16, 21), g2o ids (17), estimate-file errors (18, 19), plausibility (20
and the reader/simulate side of 11), ``--out`` checked first (22), argparse names and the
``.gz`` hint (23), the corrupt compare cache (13). Same rule and harness as
``test_io_hostile.py``."""

from __future__ import annotations

import gzip
import json
import logging
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from hostile_helpers import (ENV, HEADER, MEMORY_LIMIT_BYTES, ROOT, bomgraph, no_traceback,
                             ok_or_one_error, one_error, snapshot, write_jsonl)

sys.path.insert(0, str(ROOT / "tests" / "datasets"))
sys.path.insert(0, str(ROOT / "tests"))
from _not_writable import not_writable  # noqa: E402  (tests/_not_writable.py)
from dataset_excerpts import make_mrclam, write_g2o  # noqa: E402

from bomgraph.estimate_file import write_estimate  # noqa: E402
from bomgraph.mapper import Checkpoint, MapEstimate, RunResult  # noqa: E402
from bomgraph.sim import SimConfig, simulate  # noqa: E402
from bomgraph.stream import Stream  # noqa: E402
from bomgraph.stream_file import write_stream  # noqa: E402


def _sigint_default() -> None:
    """In the child before exec: SIGINT back to its default, so Python installs its handler
    (a test runner started in the background inherits SIGINT ignored, and so would the
    command)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


# ---- item 13: a corrupt compare cache ---------------------------------------------------------

@pytest.mark.parametrize("content", [b"\xff\xfe not utf-8", b"[1, 2, 3]", b'{"ok": true}',
                                     b"{truncated"])
def test_item13_a_corrupt_cache_file_is_a_named_miss(tmp_path: Path, content: bytes,
                                                     caplog: pytest.LogCaptureFixture) -> None:
    from bomgraph.result_cache import read_cached as _read_cached

    path = tmp_path / "abc123.json"
    path.write_bytes(content)
    with caplog.at_level(logging.WARNING):
        assert _read_cached(path) is None
    assert str(path) in caplog.text


# ---- item 14: input without newlines (/dev/zero), bounded -----------------------------------

ZERO = "/dev/zero"


def test_item14_dev_zero_is_refused_by_every_reader_within_bounded_memory(work: Path) -> None:
    est = work / "e.jsonl"
    assert bomgraph("run", work / "s.jsonl", "--method", "triangulate", "--out", est,
                    ).returncode == 0
    mr = work / "mr"
    make_mrclam(mr)
    (mr / "Barcodes.dat").unlink()
    (mr / "Barcodes.dat").symlink_to(ZERO)
    before = snapshot(work)
    cases = [["run", ZERO, "--method", "triangulate", "--out", work / "x.jsonl"],
             ["run", ZERO, "--method", "triangulate", "--out", work / "x.jsonl", "--progress"],
             ["evaluate", ZERO, work / "s.jsonl"], ["evaluate", est, ZERO],
             ["import", "g2o", ZERO, "--out", work / "x.jsonl"],
             ["import", "victoria", ZERO, "--out", work / "x.jsonl"],
             ["import", "mrclam", mr, "--robot", "1", "--out", work / "x.jsonl"],
             ["export", "--truth", ZERO, "--format", "tum", "--out", work / "x.txt"]]
    for args in cases:
        one_error(bomgraph(*args, memory=MEMORY_LIMIT_BYTES, timeout=120),
                  "without a newline")
    with open(ZERO, "rb") as zero:  # stdin
        one_error(bomgraph("run", "-", "--method", "triangulate", "--out", work / "x.jsonl",
                           stdin=zero, memory=MEMORY_LIMIT_BYTES, timeout=120),
                  "<stdin>", "without a newline")
    assert snapshot(work) == before


def test_item14_an_input_over_the_size_cap_is_refused(work: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    import bomgraph.stdio as stdio
    from bomgraph.stream_file import read_stream

    monkeypatch.setattr(stdio, "MAX_INPUT_BYTES", 10_000)
    with pytest.raises(stdio.InputTooLargeError, match="larger than"):
        read_stream(work / "s.jsonl")



@pytest.mark.parametrize("content", [b"", b"\xef\xbb\xbf{}", b'{"format": "x"}\n'])
def test_item14_a_small_estimate_that_is_not_version_2_is_read_in_bounded_memory(
        work: Path, content: bytes) -> None:
    # the version-1 path read with fh.read(4 GiB + 1), which reserves the whole cap at once:
    # a MemoryError traceback under an address-space limit, for an empty file
    est = work / "e.json"
    est.write_bytes(content)
    one_error(bomgraph("evaluate", est, work / "s.jsonl", memory=MEMORY_LIMIT_BYTES),
              str(est))

# ---- item 15: option values of the wrong type ---------------------------------------------

@pytest.mark.parametrize("method,option", [
    ("stmds-cs", "tri_window=abc"), ("stmds-cs", "tri_window=NaN"),
    ("stmds-cs", "tri_window=Infinity"), ("stmds-smacof", "smacof_max_iter=Infinity"),
    ("ekf", "no_such_option=1")])
def test_item15_a_bad_option_value_is_one_line(work: Path, method: str, option: str) -> None:
    one_error(bomgraph("run", work / "s.jsonl", "--method", method, "--option", option,
                       "--out", work / "e.jsonl"), option.split("=")[0])
    assert sorted(os.listdir(work)) == ["s.jsonl"]


# ---- item 16 and 21: signals leave the previous file and no partial one -----------------------

def _partials(folder: Path) -> list[Path]:
    return list(folder.glob(".*.partial")) + list(folder.glob("*.partial"))


def _sigterm_when_writing(args: list, folder: Path) -> subprocess.CompletedProcess:
    proc = subprocess.Popen([sys.executable, "-m", "bomgraph", *map(str, args)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=ENV)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None and not _partials(folder):
        time.sleep(0.005)
    assert proc.poll() is None, proc.communicate()
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=60)
    return subprocess.CompletedProcess(args, proc.returncode, out, err)


def test_item16_sigterm_during_run_keeps_the_previous_estimate(tmp_path: Path) -> None:
    s = tmp_path / "long.jsonl"
    write_stream(simulate(SimConfig(n_steps=300), np.random.default_rng(3)), s)
    est = tmp_path / "e.jsonl"
    est.write_text("the previous estimate\n")
    proc = _sigterm_when_writing(["run", s, "--method", "gtsam-batch", "--checkpoint-every", "1",
                                  "--out", est], tmp_path)
    assert proc.returncode == 143 and b"Traceback" not in proc.stderr, proc.stderr
    assert est.read_text() == "the previous estimate\n" and not _partials(tmp_path)


@pytest.mark.parametrize("kind", ["simulate", "import"])
def test_item21_sigterm_during_simulate_or_import_leaves_no_partial(tmp_path: Path,
                                                                    kind: str) -> None:
    out = tmp_path / "big.jsonl"
    if kind == "simulate":
        args = ["simulate", "--steps", "150000", "--out", out]
    else:
        big = simulate(SimConfig(n_steps=20000, n_landmarks=5), np.random.default_rng(0))
        write_g2o(tmp_path / "big.g2o", big, with_vertices=False)
        args = ["import", "g2o", tmp_path / "big.g2o", "--out", out]
    proc = _sigterm_when_writing(args, tmp_path)
    assert proc.returncode == 143 and b"Traceback" not in proc.stderr, proc.stderr
    assert not out.exists() and not _partials(tmp_path)


def test_item21_sigint_during_compare_is_one_line(tmp_path: Path) -> None:
    out = tmp_path / "cmp"
    proc = subprocess.Popen([sys.executable, "-m", "bomgraph", "compare", "--quick",
                             "--experiments", "all", "--jobs", "1", "--no-figures",
                             "--no-progress", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=ENV,
                            preexec_fn=_sigint_default)
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline and proc.poll() is None \
            and not any((out / "cache").glob("*.json")):
        time.sleep(0.05)
    assert proc.poll() is None, proc.communicate()
    # ("all": its GTSAM runs keep the sweep busy for seconds after the first result;
    # exp1's quick BOM-STMDS runs now all end within a second, before the signal lands)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    text = err.decode()
    assert proc.returncode == 130 and "Traceback" not in text, text
    lines = text.strip().splitlines()
    assert len(lines) == 1 and "interrupted;" in lines[0] and "rerun to resume" in lines[0]
    assert "KeyboardInterrupt" not in text
    assert not list(out.rglob("*.partial")) and not list(out.rglob("*.tmp"))


# ---- item 17: g2o ids beyond int64 -----------------------------------------------------------

@pytest.mark.parametrize("record", ["VERTEX_XY 9223372036854775808 1 2",
                                    "EDGE_BEARING_SE2_XY 0 18446744073709551616 0.1 400"])
def test_item17_g2o_ids_of_2_to_the_63_are_refused_by_line(tmp_path: Path, record: str) -> None:
    g2o = tmp_path / "big.g2o"
    g2o.write_text("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n"
                   "EDGE_SE2 0 1 1 0 0 100 0 0 100 0 100\n" + record + "\n")
    one_error(bomgraph("import", "g2o", g2o, "--out", tmp_path / "o.jsonl"), "line 4",
              "2^63")
    assert sorted(os.listdir(tmp_path)) == ["big.g2o"]


def test_item17_mrclam_barcodes_beyond_int64_are_refused(tmp_path: Path) -> None:
    mr = tmp_path / "mr"
    make_mrclam(mr)
    with open(mr / "Barcodes.dat", "a") as fh:
        fh.write("13 99999999999999999999999\n")
    one_error(bomgraph("import", "mrclam", mr, "--robot", "1", "--out", tmp_path / "o.jsonl"),
              "Barcodes.dat", "barcode", "2^63")


# ---- items 18, 19: estimate-file errors name the place; a foreign stream is refused ----------

def test_item18_a_nan_in_an_estimate_file_names_file_line_and_key(work: Path) -> None:
    est = work / "e.jsonl"
    assert bomgraph("run", work / "s.jsonl", "--method", "triangulate", "--out",
                    est).returncode == 0
    lines = est.read_text().splitlines()
    k = next(i for i, ln in enumerate(lines) if '"landmarks":[[' in ln)
    obj = json.loads(lines[k])
    obj["landmarks"][0][1] = "NaN-MARK"
    lines[k] = json.dumps(obj).replace('"NaN-MARK"', "NaN")
    est.write_text("\n".join(lines) + "\n")
    one_error(bomgraph("evaluate", est, work / "s.jsonl"), "e.jsonl", f"line {k + 1}",
              "landmarks")
    one_error(bomgraph("evaluate", work / "s.jsonl", est), "swapped")


def test_item19_an_estimate_of_another_stream_is_refused(work: Path) -> None:
    other = work / "other.jsonl"
    write_stream(simulate(SimConfig(n_steps=60), np.random.default_rng(1)), other)
    est = work / "e.jsonl"
    assert bomgraph("run", other, "--method", "triangulate", "--out", est).returncode == 0
    one_error(bomgraph("evaluate", est, work / "s.jsonl"), "another stream")
    beyond = work / "beyond.jsonl"  # no identity recorded, a checkpoint after the last step
    est0 = MapEstimate(np.arange(3), np.eye(3, 2))
    write_estimate(RunResult("x", (Checkpoint(500, est0, 0.0),), np.zeros(1), 0.0), beyond)
    one_error(bomgraph("evaluate", beyond, work / "s.jsonl"), "beyond")


# ---- item 20 and 11 (reader, importers, simulate): implausible values ----------------------

def test_item20_simulate_refuses_absurd_values(tmp_path: Path) -> None:
    out = tmp_path / "s.jsonl"
    one_error(bomgraph("simulate", "--prior-fraction", "-1", "--out", out), "--prior-fraction")
    one_error(bomgraph("simulate", "--prior-fraction", "2", "--out", out), "--prior-fraction")
    one_error(bomgraph("simulate", "--noise-scale", "1e300", "--out", out), "noise_scale",
              "above pi")
    one_error(bomgraph("simulate", "--noise-scale", "1e-300", "--out", out), "bearing sigma",
              "below 1e-09")
    one_error(bomgraph("simulate", "--sensor-range", "1e300", "--out", out), "sensor_range_m")
    one_error(bomgraph("simulate", "--sensor-range", "1e-300", "--out", out), "sensor_range_m")
    assert os.listdir(tmp_path) == []


def test_item20_g2o_refuses_an_absurd_sigma_and_a_reversed_chain(tmp_path: Path,
                                                                 sim: Stream) -> None:
    g2o = tmp_path / "data.g2o"
    write_g2o(g2o, sim)
    truth = tmp_path / "truth.g2o"
    write_g2o(truth, sim)
    out = tmp_path / "o.jsonl"
    assert bomgraph("import", "g2o", g2o, "--truth", truth, "--out", out).returncode == 0
    out.unlink()
    one_error(bomgraph("import", "g2o", g2o, "--bearing-sigma", "1e300", "--out", out),
              "bearing sigma", "[1e-09, pi/sqrt(3)")
    tiny = tmp_path / "tiny_w.g2o"  # bearing information 1e-300: sigma 1e150 rad
    write_g2o(tiny, sim, w=1e-300)
    one_error(bomgraph("import", "g2o", tiny, "--out", out), "bearing_sigma_rad", "above pi")
    one_error(bomgraph("import", "g2o", g2o, "--bearing-sigma", "1e-300", "--out", out),
              "bearing sigma", "[1e-09, pi/sqrt(3)")
    huge_w = tmp_path / "huge_w.g2o"  # bearing information 1e300: sigma 1e-150 rad
    write_g2o(huge_w, sim, w=1e300)
    one_error(bomgraph("import", "g2o", huge_w, "--out", out), "bearing_sigma_rad", "below 1e-09")
    rev = tmp_path / "reversed.g2o"
    lines = []
    for ln in g2o.read_text().splitlines():
        tok = ln.split()
        if tok and tok[0] == "EDGE_SE2":
            tok[1], tok[2] = tok[2], tok[1]
        lines.append(" ".join(tok))
    rev.write_text("\n".join(lines) + "\n")
    one_error(bomgraph("import", "g2o", rev, "--truth", truth, "--out", out),
              "disagrees with the truth", "reversed")
    assert not out.exists() and not _partials(tmp_path)


def _edit_column(path: Path, edit) -> None:
    rows = []
    for ln in path.read_text().splitlines():
        rows.append(ln if ln.startswith("#") else edit(ln.split()))
    path.write_text("\n".join(rows) + "\n")


def test_item20_mrclam_refuses_a_corrupt_velocity_and_a_swapped_truth(tmp_path: Path) -> None:
    out = tmp_path / "o.jsonl"
    fast = tmp_path / "fast"
    make_mrclam(fast)
    n = {"k": 0}

    def corrupt(tok: list[str]) -> str:
        n["k"] += 1
        if n["k"] == 500:
            tok[1] = "2e8"
        return " ".join(tok)

    _edit_column(fast / "Robot1_Odometry.dat", corrupt)
    one_error(bomgraph("import", "mrclam", fast, "--robot", "1", "--out", out),
              "Robot1_Odometry.dat", "field 'v'", "implausible")
    swapped = tmp_path / "swapped"
    make_mrclam(swapped, noise_rad=0.01)
    _edit_column(swapped / "Robot1_Groundtruth.dat",
                 lambda tok: " ".join([tok[0], tok[2], tok[1], tok[3]]))
    one_error(bomgraph("import", "mrclam", swapped, "--robot", "1", "--out", out),
              "x and y swapped", "--no-calibrate")
    assert not out.exists()


@pytest.mark.parametrize("case", ["sigma", "tiny sigma", "range", "step", "degrees", "turn"])
def test_item11_the_reader_warns_about_valid_but_absurd_values(tmp_path: Path,
                                                               case: str) -> None:
    header = dict(HEADER)
    steps = [{"t": 0, "bearings": [[0, 0.1], [1, 0.5]]}]
    steps += [{"t": t, "odom": [0.1, 0.0, 0.05], "bearings": [[0, 0.1 - 0.01 * t],
                                                               [1, 0.5 + 0.02 * t]]}
              for t in range(1, 30)]
    if case == "sigma":
        header["bearing_sigma_rad"] = 1e300
    elif case == "tiny sigma":
        header["bearing_sigma_rad"] = 1e-300
    elif case == "range":
        header["sensor_range_m"] = 1e-300
    elif case == "step":
        steps[15]["odom"] = [1e12, 0.0, 0.0]
    elif case == "degrees":  # a writer's bearings in degrees from step 20 (wrapped, they run)
        for st in steps[20:]:
            st["bearings"] = [[i, float(np.degrees(b))] for i, b in st["bearings"]]
    else:                    # a turn in degrees
        steps[12]["odom"] = [0.1, 0.0, 10.0]
    s = write_jsonl(tmp_path / "x.jsonl", header, steps)
    proc = bomgraph("run", s, "--method", "triangulate", "--out", tmp_path / "e.jsonl")
    ok_or_one_error(proc)     # "step": triangulate refuses the 1e12 m step at its line (h151)
    err = proc.stderr.decode()
    key = {"sigma": "'bearing_sigma_rad'", "tiny sigma": "below 1e-09",
           "range": "'sensor_range_m'", "step": "line 17",
           "degrees": "line 22: 'bearings': step 20: a bearing of 51.5662 is more than a full",
           "turn": "line 14: 'odom': step 12 turns 10 rad"}[case]
    warning = [ln for ln in err.splitlines() if "WARNING" in ln and "x.jsonl" in ln]
    assert len(warning) == 1 and key in warning[0], err  # once, though the file is read twice


# ---- item 22: --out is checked before anything is computed ----------------------------------

def test_item22_out_is_checked_before_the_stream_is_read(work: Path) -> None:
    bad = work / "bad.jsonl"  # the stream breaks on its last line: reading it would say so
    bad.write_text((work / "s.jsonl").read_text() + '{"t": 999}\n')
    for out, needle in [(work / "nowhere" / "e.jsonl", "does not exist"),
                        (work, "is a directory")]:
        one_error(bomgraph("run", bad, "--method", "gtsam-batch", "--out", out), "--out",
                  needle)
    locked = work / "locked"
    locked.mkdir()
    with not_writable(locked):  # root too (it ran only where os.access said so: never in CI)
        one_error(bomgraph("simulate", "--out", locked / "s.jsonl"), "not writable")
    assert list(locked.iterdir()) == []


# ---- item 23: argparse names and the .gz hint -------------------------------------------------

def test_item23_argparse_shows_no_internal_names(tmp_path: Path) -> None:
    for args, needle in [(["simulate", "--landmarks", "0"], "--landmarks: must be >= 1"),
                         (["simulate", "--landmarks", "abc"], "invalid positive integer value"),
                         (["simulate", "--steps", "abc"], "invalid integer value"),
                         (["run", "x", "--method", "ekf", "--out", "y",
                           "--checkpoint-every", "abc"], "invalid positive integer value"),
                         (["compare", "--jobs", "0"], "number of processes")]:
        proc = bomgraph(*args, "--out", tmp_path / "o.jsonl") if args[0] == "simulate" \
            else bomgraph(*args)
        err = no_traceback(proc)
        assert proc.returncode == 2 and needle in err and "_positive_int" not in err \
            and "_int" not in err and "_jobs" not in err, err


def test_item23_the_gz_hint_only_for_gzip_data(tmp_path: Path) -> None:
    mr = tmp_path / "mr"
    make_mrclam(mr)
    (mr / "Barcodes.dat").write_bytes(b"1 5\n\xff\xfe\n")  # not UTF-8, not gzip
    line = one_error(bomgraph("import", "mrclam", mr, "--robot", "1", "--out",
                              tmp_path / "o.jsonl"), "Barcodes.dat", "not UTF-8")
    assert "gz" not in line.split("Barcodes.dat", 1)[1]
    (mr / "Barcodes.dat").write_bytes(gzip.compress(b"1 5\n"))  # gzip without the suffix
    one_error(bomgraph("import", "mrclam", mr, "--robot", "1", "--out", tmp_path / "o.jsonl"),
              "gzip data", ".gz suffix")
