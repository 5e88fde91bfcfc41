"""The hostile battery of audit h18 (the file-reading and ``--out`` items 07-11 and 13-16),
each reproduced as a user meets it: ``bomgraph`` in a subprocess on small inputs written by
the test. Same rule and harness as ``test_io_hostile.py``: a result, or exit 2 with one line
``bomgraph: error: ...`` naming the file, the line and what to fix; no traceback."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hostile_helpers import bomgraph, one_error


def _run(work: Path, method: str = "triangulate") -> Path:
    est = work / "e.json"
    proc = bomgraph("run", work / "s.jsonl", "--method", method, "--out", est)
    assert proc.returncode == 0, proc.stderr.decode()
    return est


# ---- item 07: export refuses an estimate of another stream, as evaluate does ---------------

def test_h18_07_export_refuses_an_estimate_of_another_stream(work: Path) -> None:
    est = _run(work)
    lines = (work / "s.jsonl").read_text().splitlines()
    steps = [json.loads(ln) for ln in lines[1:]]
    other = work / "other.jsonl"  # the same steps, each with a time stamp
    other.write_text("\n".join([lines[0]] + [json.dumps({**s, "time_s": 1000.0 + s["t"]})
                                             for s in steps]) + "\n")
    one_error(bomgraph("evaluate", est, other), "another stream")
    for fmt in ("tum", "csv", "g2o"):
        out = work / f"e.{fmt}"
        one_error(bomgraph("export", est, "--stream", other, "--format", fmt, "--out", out),
                  "e.json", "another stream", "other.jsonl")
        assert not out.exists()
    ok = bomgraph("export", est, "--stream", work / "s.jsonl", "--format", "csv", "--out",
                  work / "ok.csv")
    assert ok.returncode == 0, ok.stderr.decode()


# ---- item 08: a negative covariance is refused, not scored as a negative NEES ---------------

def test_h18_08_a_negative_covariance_is_refused_by_line_and_key(work: Path) -> None:
    est = work / "e.json"
    proc = bomgraph("run", work / "s.jsonl", "--method", "ekf", "--out", est)
    assert proc.returncode == 0, proc.stderr.decode()
    lines = est.read_text().splitlines()
    k = len(lines) - 2  # the last checkpoint
    obj = json.loads(lines[k])
    assert "landmark_cov" in obj
    obj["landmark_cov"] = [[-1, 0, 0, -1]] * len(obj["landmarks"])
    lines[k] = json.dumps(obj)
    est.write_text("\n".join(lines) + "\n")
    one_error(bomgraph("evaluate", "--json", est, work / "s.jsonl"), "e.json", f"line {k + 1}",
              "'landmark_cov[0]'", "positive semi-definite")


# ---- item 11: estimate-file messages name the line, the key and the reason -----------------

def test_h18_11_unknown_version_broken_header_and_empty_file(work: Path) -> None:
    lines = _run(work).read_text().splitlines()
    v3, broken, empty = work / "v3.json", work / "broken.json", work / "empty.json"
    v3.write_text("\n".join([lines[0].replace('"version":2', '"version":3')] + lines[1:]))
    broken.write_text("\n".join([lines[0].rstrip("}")] + lines[1:]))
    empty.write_text("")
    for f, needles in ((v3, ["line 1", "'version'", "unknown version 3"]),
                       (broken, ["line 1", "not valid JSON", "Expecting ',' delimiter"]),
                       (empty, ["empty.json", "empty file"])):
        err = one_error(bomgraph("evaluate", f, work / "s.jsonl"), f.name, *needles)
        assert "JSONDecodeError" not in err


# ---- item 15: a g2o pose vertex cut off the odometry chain is refused, not dropped ------------

def test_h18_15_g2o_pose_off_the_chain_is_refused(tmp_path: Path) -> None:
    from _shared_data import DATA, missing  # tests/_shared_data.py

    data = DATA / "bearing_only_sim_g2o"
    src = data / "slam2D_bearing_only_initial_guess.g2o"
    if not src.exists():
        pytest.skip(missing("bearing_only_sim_g2o", src.name))
    cut = tmp_path / "cut.g2o"
    cut.write_text("".join(ln for ln in src.read_text().splitlines(keepends=True)
                           if not ln.startswith("EDGE_SE2 1200 1201 ")))
    out = tmp_path / "c.jsonl"
    one_error(bomgraph("import", "g2o", cut, "--truth",
                       data / "slam2D_bearing_only_ground_truth.g2o", "--out", out),
              "cut.g2o", "line", "VERTEX_SE2 1200", "not on the odometry chain")
    assert not out.exists()


# ---- item 10: a step's size is bounded by a bearing count ------------------------------------

def test_h18_10_a_step_of_too_many_bearings_is_one_line(tmp_path: Path) -> None:
    s = tmp_path / "big.jsonl"
    head = {"format": "bomgraph-stream", "version": 1, "bearing_sigma_rad": 0.05,
            "odometry_sigma": [0.03, 0, 0.05]}
    s.write_text(json.dumps(head) + '\n{"t": 0, "bearings": ['
                 + ",".join(f"[{i},0]" for i in range(100_001)) + "]}\n")
    one_error(bomgraph("run", "--method", "triangulate", "--out", tmp_path / "e.json", s),
              "big.jsonl", "line 2", "'bearings'", "more than 100,000 bearings")


# ---- item 13: --out that cannot be created names --out, not the temporary file ----------------

def test_h18_13_an_uncreatable_out_names_the_path_given(work: Path, monkeypatch) -> None:
    from bomgraph.stdio import AtomicOutput, OutputPathError

    ro = work / "ro"
    ro.mkdir()
    out = ro / "x.json"
    monkeypatch.setattr("tempfile.mkstemp", lambda **kw: (_ for _ in ()).throw(
        PermissionError(13, "Permission denied")))
    with pytest.raises(OutputPathError, match=rf"^{out}: cannot create a file in {ro} "
                                              rf"\(Permission denied\); choose another path$"):
        AtomicOutput(out).open()   # Python, its parameter; the command line's --out (h101)
    assert not list(ro.iterdir())
    if Path("/proc/self").is_dir():  # a folder that passes access() but takes no file (root)
        for args in (["run", "--method", "triangulate", "--out", "/proc/x.json",
                      work / "s.jsonl"], ["simulate", "--steps", "5", "--out", "/proc/x.jsonl"]):
            proc = bomgraph(*args)
            if proc.returncode == 2:
                err = one_error(proc, "/proc/x.json")
                assert ".partial" not in err, err


# ---- item 14: a MRCLAM file that is a directory or a looping link is named as such ------------

def test_h18_14_mrclam_directory_or_looping_link_is_named(tmp_path: Path) -> None:
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "datasets"))
    from dataset_excerpts import make_mrclam

    for kind, needle in (("dir", "is a directory"), ("loop", "broken or looping link")):
        mr = tmp_path / kind
        make_mrclam(mr)
        meas = mr / "Robot1_Measurement.dat"
        meas.unlink()
        meas.mkdir() if kind == "dir" else meas.symlink_to(meas.name)
        one_error(bomgraph("import", "mrclam", mr, "--robot", "1", "--out",
                           tmp_path / f"{kind}.jsonl"), "Robot1_Measurement.dat", needle)


# ---- item 16: every --out help says an existing file is replaced -----------------------------

def _parsers(parser):
    import argparse

    yield parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                yield from _parsers(sub)


def test_h18_16_every_out_help_says_an_existing_file_is_replaced(tmp_path: Path) -> None:
    from bomgraph.cli_parser import build_parser

    outs = [(p.prog, a) for p in _parsers(build_parser()) for a in p._actions
            if "--out" in a.option_strings]
    assert len(outs) >= 8, [p for p, _ in outs]
    for prog, action in outs:
        assert "replaced" in action.help, (prog, action.help)
    proc = bomgraph("run", "--help")  # wrapped at the terminal's width ($COLUMNS): unwrapped
    assert proc.returncode == 0 and b"existing file of that name is" in b" ".join(
        proc.stdout.split())
