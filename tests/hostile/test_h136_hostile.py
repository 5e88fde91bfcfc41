"""Hostile-input faults helper h136 fixed (noticed by the session before and left): each
test failed before its fix. The rule: bad input gets one line naming the file, the line and
the field, exit status 2; never a traceback; nothing overwritten or lost; memory bounded."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from hostile_helpers import (HEADER, bomgraph, odd_steps, one_error, refused_in_compare,
                              write_jsonl)


@pytest.mark.parametrize("header,at_4,where", [
    ({}, {"odom_sigma": [1e8, 0.0, 0.1]}, "line 6: 'odom_sigma': step 4: stmds-smacof cannot use"),
    ({}, {"odom": [1e10, 0.0, 0.1]}, "line 6: 'odom': step 4: stmds-smacof cannot use a move"),
    ({"odometry_sigma": [1e8, 0.0, 0.1]}, {}, "line 1: 'odometry_sigma': stmds-smacof cannot use"),
    ({"bearing_sigma_rad": 1e7}, {}, "line 1: 'bearing_sigma_rad': stmds-smacof cannot use"),
])
@pytest.mark.parametrize("out", ["file", "stdout"])
def test_an_stmds_refusal_names_the_file_and_line(tmp_path: Path, header: dict, at_4: dict,
                                                  where: str, out: str) -> None:
    """``bomgraph run --method stmds-smacof`` on a stream whose odometry the reader accepts
    (with a warning) but STMDS refuses said "STMDS cannot use step 4's odom_sigma ...",
    naming the step, not the file and the line; an estimate already at --out is kept."""
    stream = write_jsonl(tmp_path / "odd.jsonl", {**HEADER, **header}, odd_steps(**at_4))
    est = tmp_path / "e.json"
    est.write_text("kept\n")
    proc = bomgraph("run", stream, "--method", "stmds-smacof", "--out",
                    est if out == "file" else "-")
    one_error(proc, f"{stream}, {where}", "fix the stream's")
    assert est.read_text() == "kept\n"
    assert not proc.stdout


def test_an_stmds_refusal_in_compare_names_the_file_and_line(tmp_path: Path) -> None:
    """``compare --streams`` gave the same refusal naming the step only."""
    stream = write_jsonl(tmp_path / "odd.jsonl", HEADER, odd_steps(odom_sigma=[1e8, 0.0, 0.1]))
    refused_in_compare(tmp_path, stream, "stmds-smacof",
                       f"{stream}, line 6: 'odom_sigma': step 4: stmds-smacof cannot use")


def _estimate(folder: Path, name: str, keep=lambda i: True, scale: float = 1.0,
              method: str = "stmds-smacof") -> Path:
    """``METHOD.json`` (``method`` on ``s.jsonl``) rewritten: its landmarks filtered by
    ``keep``, and its landmarks and robot positions multiplied by ``scale``, in every
    checkpoint (covariances, if any, as they were)."""
    est = folder / f"{method}.json"
    if not est.exists():
        assert bomgraph("run", folder / "s.jsonl", "--method", method, "--out",
                        est).returncode == 0
    lines = [json.loads(ln) for ln in est.read_text().splitlines()]
    for obj in lines:
        if "landmarks" in obj:
            obj["landmarks"] = [[i, x * scale, y * scale] for i, x, y in obj["landmarks"]
                                if keep(i)]
        for key in ("poses", "new_poses"):
            if obj.get(key):
                obj[key] = [[t, x * scale, y * scale, h] for t, x, y, h in obj[key]]
    out = folder / name
    out.write_text("".join(json.dumps(obj) + "\n" for obj in lines))
    return out


def test_a_failed_alignment_to_a_reference_names_the_reference(work: Path) -> None:
    """``evaluate --reference REF EST STREAM`` whose maps share 2 landmarks said "EST: the
    final map (t = 60): the estimate shares 2 landmark(s) with the reference estimate",
    naming EST but not REF."""
    ref = _estimate(work, "two-landmarks.json", lambda i: i < 2)
    est = work / "stmds-smacof.json"
    for align in ("landmarks", "trajectory"):
        proc = bomgraph("evaluate", "--reference", ref, "--align", align, est,
                        work / "s.jsonl")
        one_error(proc, f"{est}: the final map", f"--reference {ref}")


@pytest.mark.parametrize("method", ["stmds-smacof", "ekf"])
@pytest.mark.parametrize("fmt", ["text", "markdown", "json"])
def test_a_map_near_1e300_is_scored_in_exponent_form_without_warnings(work: Path, method: str,
                                                                       fmt: str) -> None:
    """``evaluate`` of an estimate whose coordinates are near 1e300 m printed each landmark
    error as 300 digits of cm; at 1e305 numpy's overflow warnings too, and "MPE -"."""
    for scale in (1e300, 1e305):
        est = _estimate(work, "huge.json", scale=scale, method=method)
        proc = bomgraph("evaluate", "--format", fmt, est, work / "s.jsonl")
        out = proc.stdout.decode()
        assert proc.returncode == 0 and not proc.stderr, proc.stderr
        assert not re.search(r"\d{20}", out), out
        assert "inf" not in out.lower(), out
        if fmt == "text":
            assert re.search(rf"landmark MPE \d\.\d{{3}}e\+{301 if scale == 1e300 else 306} cm",
                             out), out
        if fmt == "text" and method == "ekf":
            assert "NEES from the file's covariances: landmark (mean) beyond the " \
                   "floating-point range" in out, out


@pytest.mark.parametrize("scale,needle", [
    (1e307, "the estimate's landmark coordinates reach"),
    (1e-320, "the scale between the source and the target points leaves the floating-point")])
def test_a_map_beyond_the_scored_range_is_refused_in_one_line(work: Path, scale: float,
                                                              needle: str) -> None:
    """Coordinates near 1e307 m gave "inf" errors with overflow warnings; subnormal ones a
    traceback (an OverflowError in the alignment's rescaling)."""
    est = _estimate(work, "extreme.json", scale=scale)
    for args in (["--similarity"], ["--similarity", "--align", "both"]):
        one_error(bomgraph("evaluate", *args, est, work / "s.jsonl"), f"{est}: the final map",
                  needle)


def _sweep(folder: Path, pattern: str) -> Path:
    sweep = folder / "sweep.toml"
    sweep.write_text(f'streams = ["{pattern}"]\n[[methods]]\nname = "triangulate"\n')
    return sweep


def test_a_stream_glob_through_a_link_loop_is_refused(tmp_path: Path) -> None:
    """``streams = ["loop/**/*.jsonl"]`` with two links in ``loop`` to itself searched 2^40
    paths (a glob follows links to folders), without end in practice, as ``/**/*.jsonl``
    searched the whole file system (over 90 s)."""
    (tmp_path / "loop").mkdir()
    for name in ("a", "b"):
        (tmp_path / "loop" / name).symlink_to(".")
    proc = bomgraph("compare", "--config", _sweep(tmp_path, "loop/**/*.jsonl"), "--out",
                    tmp_path / "out", "--dry-run", timeout=60)
    one_error(proc, "sweep.toml: streams[0]: 'loop/**/*.jsonl': '**' would search more than "
                    "10,000 folders below", "start the pattern at the folder the streams are in")


def test_a_stream_glob_over_a_wide_tree_is_refused_and_a_narrow_one_runs(tmp_path: Path,
                                                                        work: Path) -> None:
    """A tree of 10,100 folders is refused by its '**' (the bound, not the file system's
    size, decides); the same streams found through a narrower '**' run."""
    from bomgraph.stream_globs import MAX_GLOB_FOLDERS

    wide = tmp_path / "wide"
    for i in range(101):
        for j in range(100):
            (wide / str(i) / str(j)).mkdir(parents=True)
    assert 101 * 101 > MAX_GLOB_FOLDERS
    (wide / "7" / "s.jsonl").write_bytes((work / "s.jsonl").read_bytes())
    proc = bomgraph("compare", "--config", _sweep(tmp_path, "wide/**/*.jsonl"), "--out",
                    tmp_path / "out", "--dry-run")
    one_error(proc, "'**' would search more than 10,000 folders below")
    assert not (tmp_path / "out").exists()
    proc = bomgraph("compare", "--config", _sweep(tmp_path, "wide/7/**/*.jsonl"), "--out",
                    tmp_path / "out", "--dry-run")
    assert proc.returncode == 0 and b"1 run: " in proc.stdout, proc.stderr


def test_bounded_glob_matches_glob_below_its_bound(tmp_path: Path) -> None:
    import glob

    from bomgraph.stream_globs import GlobTooWideError, bounded_glob

    for rel in ("a/x.jsonl", "a/b/y.jsonl", "c/.hidden/z.jsonl", "c/d/e/w.jsonl"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text("")
    pattern = f"{tmp_path}/**/*.jsonl"
    assert bounded_glob(pattern, limit=6) == sorted(glob.glob(pattern, recursive=True))
    with pytest.raises(GlobTooWideError, match="more than 5 folders below"):  # 6: the top,
        bounded_glob(pattern, limit=5)         # a, a/b, c, c/d, c/d/e (not c/.hidden)
    assert bounded_glob(f"{tmp_path}/*/*.jsonl", limit=3) == [str(tmp_path / "a/x.jsonl")]
    with pytest.raises(GlobTooWideError, match="more than 2 folders"):   # h146: the top, a
        bounded_glob(f"{tmp_path}/*/*.jsonl", limit=2)                   # and c


NL = "a\nb"   # a file name with a newline: shown as 'a\nb' (errors.shown_path)


@pytest.mark.parametrize("case", ["run-bad-line", "run-missing", "run-out-folder",
                                  "evaluate-bad-reference", "evaluate-bad-estimate", "plot",
                                  "compare-streams", "compare-config", "simulate-out",
                                  "export-out", "run-stmds-refusal", "unknown-method",
                                  "import-missing", "compare-real"])
def test_a_file_name_with_a_newline_keeps_the_error_on_one_line(work: Path, case: str) -> None:
    """A file name holding a newline split a one-line error in two (``bomgraph: error: a`` /
    ``b.jsonl, line 4: ...``); each message now shows such a name as a Python string
    literal, in every command's error, and so does a warning naming it."""
    s = work / "s.jsonl"
    bad_stream = work / f"{NL}.jsonl"
    lines = s.read_text().splitlines(keepends=True)
    bad_stream.write_text("".join(lines[:3]) + '{"t": 2, "odom": [1, 0]}\n')
    junk = work / f"{NL}.bad"
    junk.write_text("garbage\n")
    odd = work / f"{NL}.odd.jsonl"
    step = json.loads(lines[5])
    step["odom_sigma"] = [1e8, 0.0, 0.1]
    odd.write_text("".join(lines[:5]) + json.dumps(step) + "\n" + "".join(lines[6:]))
    est = _estimate(work, "e.json")
    args, shown = {
        "run-bad-line": (["run", bad_stream, "--method", "triangulate", "--out", "o.json"],
                         repr(str(bad_stream)) + ", line 4: 'odom'"),
        "run-missing": (["run", work / f"{NL}.none", "--method", "triangulate", "--out",
                         "o.json"], repr(str(work / f"{NL}.none")) + ": cannot open"),
        "run-out-folder": (["run", s, "--method", "triangulate", "--out", f"{NL}/o.json"],
                           f"--out {NL + '/o.json'!r}: the folder"),
        "evaluate-bad-reference": (["evaluate", est, s, "--reference", junk],
                                   repr(str(junk)) + ", line 1: not valid JSON"),
        "evaluate-bad-estimate": (["evaluate", junk, s], repr(str(junk)) + ", line 1"),
        "plot": (["plot", junk, s, "--out", "x.png"], repr(str(junk)) + ", line 1"),
        "compare-streams": (["compare", "--streams", bad_stream, "--methods", "triangulate",
                             "--out", "cmp", "--jobs", "1", "--no-progress", "--no-figures"],
                            repr(str(bad_stream)) + ", line 4: 'odom'"),
        "compare-config": (["compare", "--config", junk, "--out", "cmp", "--jobs", "1"],
                           repr(str(junk)) + ": not valid TOML"),
        "simulate-out": (["simulate", "--steps", "5", "--out", f"{NL}/x.jsonl"],
                         f"--out {NL + '/x.jsonl'!r}: the folder"),
        "export-out": (["export", "--format", "csv", "--out", f"{NL}/o.csv", est],
                       f"--out {NL + '/o.csv'!r}: the folder"),
        "run-stmds-refusal": (["run", odd, "--method", "stmds-smacof", "--out", "o.json"],
                              repr(str(odd)) + ", line 6: 'odom_sigma': step 4"),
        "unknown-method": (["run", s, "--method", f"x{NL}", "--out", "o.json"],
                           "unknown method 'xa\\nb'"),
        "import-missing": (["import", "g2o", f"{NL}.g2o", "--out", "o.json"],
                           f"{NL + '.g2o'!r}: file not found"),
        "compare-real": (["compare", "--real", NL, "--out", "cmp", "--dry-run"],
                         f"no dataset folders (mrclam6, bearing_only_sim_g2o) under {NL!r}"),
    }[case]
    proc = bomgraph(*args, cwd=work)
    line = one_error(proc, shown)
    err = proc.stderr.decode()
    assert err.count("\n") == len([ln for ln in err.splitlines() if ln.startswith(
        "bomgraph: ")]), err     # every line of stderr is one of bomgraph's: none split
    if case == "run-stmds-refusal":
        assert f"bomgraph: WARNING: {str(odd)!r}, line 6" in err, err
    assert not (work / "o.json").exists(), line


def test_shown_path_quotes_only_what_needs_it() -> None:
    from bomgraph.errors import one_line, shown_path

    assert shown_path("runs/s 1.jsonl") == "runs/s 1.jsonl"
    assert shown_path(Path("a\nb.jsonl")) == "'a\\nb.jsonl'"
    assert shown_path(b"x\xff.jsonl") == "'x\\udcff.jsonl'"   # undecodable: never an encode
    assert shown_path("tab\there\\") == "'tab\\there\\\\'"      # error on stderr
    assert shown_path("") == "'' (an empty file name)"
    assert one_line("ok: a\nb\x1b[2J") == "ok: a\\nb\\x1b[2J"
    assert one_line("plain") == "plain"


def test_a_warning_about_stdin_names_it_stdin(work: Path) -> None:
    """A warning about a stream read from stdin named the temporary file it was spooled to
    (``/tmp/bomgraph-stdin-XXXX/stdin, line 6``), where the error line says ``<stdin>``."""
    lines = (work / "s.jsonl").read_text().splitlines(keepends=True)
    step = json.loads(lines[5])
    step["odom_sigma"] = [1e8, 0.0, 0.1]
    data = ("".join(lines[:5]) + json.dumps(step) + "\n" + "".join(lines[6:])).encode()
    proc = bomgraph("run", "-", "--method", "stmds-smacof", "--out", work / "o.json",
                    stdin=data)
    err = one_error(proc, "<stdin>, line 6: 'odom_sigma': step 4")
    assert "bomgraph: WARNING: <stdin>, line 6: 'odom_sigma'" in proc.stderr.decode(), err
    assert "bomgraph-stdin" not in proc.stderr.decode()


def test_a_method_refusal_crosses_a_process_boundary() -> None:
    """A worker's refusal is pickled to the process that reports it: keyword-only arguments
    and notes survive (a plain Exception reduce called StreamValueError(text) and failed)."""
    import pickle

    from bomgraph.errors import StreamValueError

    exc = StreamValueError("STMDS cannot use 1e8", t=4, key="odom_sigma")
    exc.add_note("raised in StmdsMapper.step() at t = 4")
    for e in (exc, exc.in_file("s.jsonl", 6)):
        back = pickle.loads(pickle.dumps(e))
        assert (str(back), back.t, back.key, back.line, back.__notes__) == (
            str(e), 4, "odom_sigma", e.line, ["raised in StmdsMapper.step() at t = 4"])
    assert str(exc.in_file("s.jsonl", 6)) == ("s.jsonl, line 6: 'odom_sigma': step 4: STMDS "
                                              "cannot use 1e8")
