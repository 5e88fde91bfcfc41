"""The estimate file: exact round trip and a strict reader."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from baselines.triangulate import TriangulateMapper
from bomgraph.errors import StreamFormatError
from bomgraph.estimate_file import estimate_to_json, read_estimate, write_estimate
from bomgraph.mapper import run
from bomgraph.sim import SimConfig, paper_design, simulate_run


def test_estimate_file_round_trip(tmp_path: Path) -> None:
    s = simulate_run(paper_design(0)[1], SimConfig(n_steps=25))
    result = run(TriangulateMapper(s.header), s.steps, method="triangulate")
    write_estimate(result, tmp_path / "e.json")
    back = read_estimate(tmp_path / "e.json")
    assert back.method == "triangulate"
    np.testing.assert_array_equal(back.final.landmark_ids, result.final.landmark_ids)
    np.testing.assert_array_equal(back.final.landmarks_xy, result.final.landmarks_xy)
    np.testing.assert_array_equal(back.final.poses, result.final.poses)
    assert [c.t for c in back.checkpoints] == [10, 20, 25]
    assert estimate_to_json(result)["timing_s"]["total"] == result.total_s
    (tmp_path / "bad.json").write_text('{"format": "bomgraph-estimate", "version": 1, '
                                       '"landmarks": [[1, 2]]}')
    with pytest.raises(StreamFormatError, match="landmarks"):
        read_estimate(tmp_path / "bad.json")


@pytest.mark.parametrize("body,key", [
    ('"landmarks": [[0, 1, 2, 3, 4, 5]]', "landmarks[0]"),
    ('"landmarks": [["3", "1.5", "2.5"]]', "landmarks[0]"),
    ('"landmarks": [[true, 1.5, 2.5]]', "landmarks[0]"),
    ('"landmarks": [[1e30, 1.5, 2.5]]', "landmarks[0]"),
    ('"landmarks": [], "poses": [[2.7, 0, 0, 0]]', "poses[0]"),
    ('"landmarks": [], "poses": [[1, 0, 0, 0], [1, 0, 0, 0]]', "poses[1]"),
    ('"landmarks": [], "checkpionts": []', "checkpionts"),
    ('"landmarks": [], "checkpoints": 5', "checkpoints"),
    ('"landmarks": [], "checkpoints": [{"t": true, "landmarks": []}]', "checkpoints[0].t"),
    ('"landmarks": [], "timing_s": [1, 2]', "timing_s"),
    ('"landmarks": [], "landmarks": []', "landmarks"),
])
def test_estimate_reader_is_strict(tmp_path: Path, body: str, key: str) -> None:
    p = tmp_path / "e.json"
    p.write_text('{"format": "bomgraph-estimate", "version": 1, "method": "m", ' + body + "}")
    with pytest.raises(StreamFormatError) as info:
        read_estimate(p)
    assert f"'{key}'" in str(info.value) and str(p) in str(info.value)


# --------------------------------------------------------------------------------------------
# Version 2
# --------------------------------------------------------------------------------------------

import json
import os
import signal
import subprocess
import sys

from bomgraph.errors import EvaluationError
from bomgraph.estimate_file import EstimateWriter, stream_identity
from bomgraph.evaluate import landmark_nees, pose_nees, score_estimate
from bomgraph.mapper import MapEstimate
from bomgraph.file_evaluation import evaluate_files
from bomgraph.stream_file import write_stream


class _CovMapper:
    """Triangulation with made-up covariances and info (what an EKF or GTSAM gives)."""

    def __init__(self, header):
        self.inner = TriangulateMapper(header)
        self.n = 0

    def step(self, st):
        self.inner.step(st)
        self.n += 1

    def estimate(self):
        e = self.inner.estimate()
        n, m = len(e.landmark_ids), len(e.pose_t)
        a = np.arange(1, n + 1, dtype=float)[:, None, None]
        lc = a * np.array([[0.02, 0.003], [0.003, 0.01]]) / 7
        b = np.arange(1, m + 1, dtype=float)[:, None, None]
        pc = b * np.array([[0.01, 0.001, 0.0], [0.001, 0.02, 0.002], [0.0, 0.002, 0.005]]) / 3
        return MapEstimate(e.landmark_ids, e.landmarks_xy, pose_t=e.pose_t, poses=e.poses,
                           landmark_cov=lc, pose_cov=pc,
                           info={"converged": True, "iterations": self.n, "cost": 0.1 * self.n,
                                 "left_out": {"7": "no parallax"}, "failures": []})


def _stream(n_steps=60, seed=0):
    return simulate_run(paper_design(seed)[1], SimConfig(n_steps=n_steps))


def _same(a: MapEstimate, b: MapEstimate) -> None:
    np.testing.assert_array_equal(a.landmark_ids, b.landmark_ids)
    np.testing.assert_array_equal(a.landmarks_xy, b.landmarks_xy)
    np.testing.assert_array_equal(a.pose_t, b.pose_t)
    np.testing.assert_array_equal(a.poses, b.poses)
    np.testing.assert_array_equal(a.landmark_cov, b.landmark_cov)
    np.testing.assert_array_equal(a.pose_cov, b.pose_cov)
    assert dict(a.info) == dict(b.info)


def test_v2_round_trip_every_checkpoint(tmp_path: Path) -> None:
    s = _stream()
    result = run(_CovMapper(s.header), s.steps, method="cov")
    ident = stream_identity(s.steps)
    write_estimate(result, tmp_path / "e.est", stream=ident, options={"a": 1})
    back = read_estimate(tmp_path / "e.est")
    assert back.version == 2 and back.stream == ident and back.options == {"a": 1}
    assert [c.t for c in back.checkpoints] == [c.t for c in result.checkpoints]
    for c, d in zip(result.checkpoints, back.checkpoints):
        _same(c.estimate, d.estimate)
        assert c.estimate_s == d.estimate_s
    _same(back.final, result.final)
    assert back.timing_s["total"] == result.total_s
    lines = (tmp_path / "e.est").read_text().splitlines()
    assert len(lines) == 1 + len(result.checkpoints) + 1      # header, checkpoints, timings
    assert "poses" in json.loads(lines[-2]) and "new_poses" in json.loads(lines[1])
    # the identity of a bomgraph stream file is the SHA-256 of its step lines
    write_stream(s, tmp_path / "s.jsonl")
    import hashlib
    raw = (tmp_path / "s.jsonl").read_bytes().split(b"\n", 1)[1]
    assert ident.steps_sha256 == hashlib.sha256(raw).hexdigest()
    assert ident.n_steps == len(s.steps)


def test_v2_size_is_linear_in_steps(tmp_path: Path) -> None:
    sizes = []
    for n in (200, 400):
        s = _stream(n)
        write_estimate(run(TriangulateMapper(s.header), s.steps), tmp_path / f"{n}.est")
        sizes.append((tmp_path / f"{n}.est").stat().st_size)
    # the map saturates, so the landmark part is linear in the checkpoints and the poses are
    # written once: doubling T at most a bit more than doubles the file (quadratic: x4)
    assert sizes[1] / sizes[0] < 2.6, sizes


def test_writer_that_raises_leaves_old_file(tmp_path: Path) -> None:
    s = _stream(40)
    result = run(TriangulateMapper(s.header), s.steps)
    target = tmp_path / "e.est"
    target.write_text("the previous good file\n")
    with pytest.raises(RuntimeError, match="midway"):
        with EstimateWriter(target, "m") as w:
            w.add(result.checkpoints[0])
            w.add(result.checkpoints[1])
            raise RuntimeError("midway")
    assert target.read_text() == "the previous good file\n"
    assert sorted(os.listdir(tmp_path)) == ["e.est"]


def test_sigterm_leaves_old_file(tmp_path: Path) -> None:
    target = tmp_path / "e.est"
    target.write_text("old\n")
    code = f"""
import os, signal, numpy as np
from bomgraph.estimate_file import EstimateWriter
from bomgraph.mapper import Checkpoint, MapEstimate
with EstimateWriter({str(target)!r}, "m") as w:
    w.add(Checkpoint(1, MapEstimate(np.array([1]), np.array([[0.0, 1.0]])), 0.0))
    w.add(Checkpoint(2, MapEstimate(np.array([1]), np.array([[0.0, 1.0]])), 0.0))
    os.kill(os.getpid(), signal.SIGTERM)
    import time; time.sleep(10)
"""
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, timeout=60)
    assert proc.returncode == 128 + signal.SIGTERM, proc.stderr
    assert target.read_text() == "old\n"
    assert sorted(os.listdir(tmp_path)) == ["e.est"]


def _v2(tmp_path: Path, lines: list[str]) -> Path:
    p = tmp_path / "e.est"
    p.write_text("\n".join(['{"format": "bomgraph-estimate", "version": 2, "method": "m"}']
                           + lines) + "\n")
    return p


@pytest.mark.parametrize("lines,line,key", [
    (['{"t": 1, "landmarks": [[1, NaN, 2]]}', '{"timing_s": {}}'], 2, "landmarks[0][1]"),
    (['{"t": 1, "landmarks": [[1, 1, 2]], "landmark_cov": [[1, 0, 0]]}', '{"timing_s": {}}'],
     2, "landmark_cov[0]"),
    (['{"t": 1, "landmarks": [], "extra": 1}', '{"timing_s": {}}'], 2, "extra"),
    (['{"t": 1, "landmarks": []}', '{"t": 1, "landmarks": []}', '{"timing_s": {}}'], 3, "t"),
    (['{"t": 1, "landmarks": [], "new_poses": [[3, 0, 0, 0]]}',
      '{"t": 2, "landmarks": [], "new_poses": [[2, 0, 0, 0]]}', '{"timing_s": {}}'],
     3, "new_poses"),
    (['{"t": 1, "landmarks": [], "info": 3}', '{"timing_s": {}}'], 2, "info"),
    (['{"t": 1, "landmarks": [], "landmarks": []}', '{"timing_s": {}}'], 2, "landmarks"),
    (['{"t": 1, "landmarks": []}'], 3, "timing_s"),
    (['{"t": 1, "landmarks": [[1, 0, 0]], "poses": [[1, 0, 0, 0]], "pose_cov": [[1]]}',
      '{"timing_s": {}}'], 2, "pose_cov[0]"),
])
def test_v2_reader_is_strict(tmp_path: Path, lines, line, key) -> None:
    p = _v2(tmp_path, lines)
    with pytest.raises(StreamFormatError) as info:
        read_estimate(p)
    msg = str(info.value)
    assert str(p) in msg and f"line {line}" in msg and f"'{key}'" in msg, msg


_LM = '{"t": 1, "landmarks": [[1, 0, 0], [2, 1, 1]], "landmark_cov": [[1, 0, 0, 1], %s]}'
_PS = ('{"t": 2, "landmarks": [], "new_poses": [[0, 0, 0, 0], [1, 0, 0, 0]], '
       '"new_pose_cov": [[0, 0, 0, 0, 0, 0, 0, 0, 0], %s]}')


@pytest.mark.parametrize("lines,line,key,what", [
    ([_LM % "[-1, 0, 0, -1]"], 2, "landmark_cov[1]", "not positive semi-definite"),
    ([_LM % "[1, 2, 2, 1]"], 2, "landmark_cov[1]", "not positive semi-definite"),
    ([_LM % "[1, 0.5, -0.5, 1]"], 2, "landmark_cov[1]", "not symmetric"),
    ([_LM % "[1, 1e-6, 0, 1]"], 2, "landmark_cov[1]", "not symmetric"),
    ([_LM % "[1e308, 0, 0, 1e308]"], 2, None, None),        # finite and PSD: accepted
    ([_LM % "[1, 0, 0, 0]"], 2, None, None),                # singular is PSD
    (['{"t": 1, "landmarks": []}', _PS % "[1, 0, 0, 0, 1, 0, 0, 0, -1e-3]"], 3,
     "new_pose_cov[1]", "not positive semi-definite"),
    (['{"t": 1, "landmarks": []}', _PS % "[1, 0, 0, 0, 1, 0, 1, 0, 1]"], 3, "new_pose_cov[1]",
     "not symmetric"),
    (['{"t": 1, "landmarks": [], "poses": [[0, 0, 0, 0]], '
      '"pose_cov": [[-1, 0, 0, 0, -1, 0, 0, 0, -1]]}'], 2, "pose_cov[0]",
     "not positive semi-definite"),
])
def test_v2_covariances_must_be_symmetric_positive_semidefinite(tmp_path: Path, lines, line,
                                                                key, what) -> None:
    """h18 item 08: negative or non-symmetric covariances were read (and gave a negative
    NEES); refused with the file, line and entry; round-off-level asymmetry (1e-16) and
    singular or huge finite ones are read."""
    p = _v2(tmp_path, lines + ['{"timing_s": {}}'])
    if key is None:
        read_estimate(p)
        return
    with pytest.raises(StreamFormatError) as info:
        read_estimate(p)
    msg = str(info.value)
    assert (str(p) in msg and f"line {line}" in msg and f"'{key}'" in msg
            and what in msg), msg


def test_v2_covariances_with_round_off_asymmetry_are_read(tmp_path: Path) -> None:
    c = np.array([[0.02, 0.003], [0.003 * (1 + 4e-16), 0.01]])
    p = _v2(tmp_path, ['{"t": 1, "landmarks": [[1, 0, 0]], "landmark_cov": [[%s]]}'
                       % ", ".join(repr(float(v)) for v in c.ravel()), '{"timing_s": {}}'])
    np.testing.assert_array_equal(read_estimate(p).final.landmark_cov[0], c)


_HEAD = '{"format": "bomgraph-estimate", "version": 2, "method": "m"}'


@pytest.mark.parametrize("text,needles", [
    ("", ["empty file"]),
    ("\n\n", ["empty file"]),
    (_HEAD.replace("2", "3") + '\n{"t": 1, "landmarks": []}\n{"timing_s": {}}\n',
     ["line 1", "'version'", "unknown version 3", "versions 1 and 2"]),
    ('{"format": "bomgraph-estimate", "method": "m"}\n{"timing_s": {}}\n',
     ["line 1", "'version'", "missing"]),
    (_HEAD[:-1] + '\n{"t": 1, "landmarks": []}\n{"timing_s": {}}\n',
     ["line 1", "Expecting ',' delimiter at column 60", "header is one JSON object"]),
    (_HEAD[:20] + '\n{"t": 1, "landmarks": []}\n',
     ["line 1", "Invalid control character at column 21"]),
    ('{"format": "bomgraph-estimate", "version": 1,\n "method": "m",\n "landmarks": [[1, 2, ]]}',
     # the decoder's words differ between Pythons (3.13: "Illegal trailing comma ...")
     ["line 3", "not valid JSON (", " at column "]),
])
def test_reader_messages_name_the_line_and_the_reason(tmp_path: Path, text, needles) -> None:
    """h18 item 11: an unknown version, a broken line 1 or an empty file said only
    ``not a JSON estimate file (JSONDecodeError)``."""
    p = tmp_path / "e.json"
    p.write_text(text)
    with pytest.raises(StreamFormatError) as info:
        read_estimate(p)
    msg = str(info.value)
    assert msg.startswith(str(p)) and "JSONDecodeError" not in msg, msg
    for n in needles:
        assert n in msg, (n, msg)


def test_a_multi_line_version_1_file_is_still_read(tmp_path: Path) -> None:
    p = tmp_path / "e.json"
    p.write_text('{"format": "bomgraph-estimate", "version": 1,\n "method": "m",\n'
                 ' "landmarks": [[1, 2, 3]]}\n')
    assert read_estimate(p).final.landmark_ids.tolist() == [1]


def test_v1_files_still_read(tmp_path: Path) -> None:
    s = _stream(25)
    result = run(TriangulateMapper(s.header), s.steps, method="triangulate")
    (tmp_path / "v1.json").write_text(json.dumps(estimate_to_json(result)) + "\n")
    back = read_estimate(tmp_path / "v1.json")
    assert back.version == 1 and back.stream is None
    for c, d in zip(result.checkpoints, back.checkpoints):
        np.testing.assert_array_equal(c.estimate.landmarks_xy, d.estimate.landmarks_xy)
        np.testing.assert_array_equal(c.estimate.poses, d.estimate.poses)
    (tmp_path / "nan.json").write_text('{"format": "bomgraph-estimate", "version": 1, '
                                       '"landmarks": [[1, NaN, 2]]}')
    with pytest.raises(StreamFormatError, match=r"nan\.json.*'landmarks\[0\]\[1\]'.*file"):
        read_estimate(tmp_path / "nan.json")


def test_a_version_1_file_is_read_whole_only_up_to_its_cap(tmp_path: Path, monkeypatch) -> None:
    """A version-1 estimate is parsed as one object (about 12x its bytes in memory), so it has
    its own cap below the 4 GiB of line-read inputs; the refusal names version 2."""
    import bomgraph.estimate_file as ef
    s = _stream(25)
    result = run(TriangulateMapper(s.header), s.steps, method="triangulate")
    text = json.dumps(estimate_to_json(result)) + "\n"
    (tmp_path / "v1.json").write_text(text)
    monkeypatch.setattr(ef, "MAX_V1_BYTES", len(text))
    assert read_estimate(tmp_path / "v1.json").version == 1        # at the cap: read
    monkeypatch.setattr(ef, "MAX_V1_BYTES", len(text) - 1)
    with pytest.raises(StreamFormatError, match=r"v1\.json.*version-1.*at most.*version 2"):
        read_estimate(tmp_path / "v1.json")
    assert ef.MAX_V1_BYTES < 2**30                                   # far below the file cap


def test_evaluate_refuses_other_stream_beyond_and_swapped(tmp_path: Path) -> None:
    s, other = _stream(40, 0), _stream(40, 1)
    write_stream(s, tmp_path / "s.jsonl")
    write_stream(other, tmp_path / "o.jsonl")
    write_stream(type(s)(s.header, s.steps[:30], None), tmp_path / "short.jsonl")
    result = run(TriangulateMapper(s.header), s.steps, method="triangulate")
    write_estimate(result, tmp_path / "e.est", stream=stream_identity(s.steps))
    evaluate_files(tmp_path / "e.est", tmp_path / "s.jsonl")        # the right pair is fine
    with pytest.raises(EvaluationError, match=r"e\.est was computed from another stream.*"
                                              r"o\.jsonl.*SHA-256"):
        evaluate_files(tmp_path / "e.est", tmp_path / "o.jsonl")
    with pytest.raises(EvaluationError, match="41 steps recorded, the stream has 30"):
        evaluate_files(tmp_path / "e.est", tmp_path / "short.jsonl")
    write_estimate(result, tmp_path / "noid.est")                   # no identity recorded
    with pytest.raises(EvaluationError, match="checkpoint t = 30 is beyond the last step "
                                              "t = 29"):
        evaluate_files(tmp_path / "noid.est", tmp_path / "short.jsonl")
    with pytest.raises(EvaluationError, match=r"e\.est is an estimate file.*swapped"):
        evaluate_files(tmp_path / "s.jsonl", tmp_path / "e.est")
    with pytest.raises(StreamFormatError, match=r"stream file, not an estimate.*swapped"):
        evaluate_files(tmp_path / "s.jsonl", tmp_path / "s.jsonl")


def test_nees_from_file_equals_in_memory(tmp_path: Path) -> None:
    s = _stream(60)
    write_stream(s, tmp_path / "s.jsonl")
    result = run(_CovMapper(s.header), s.steps, method="cov")
    write_estimate(result, tmp_path / "e.est", stream=stream_identity(s.steps))
    ev = evaluate_files(tmp_path / "e.est", tmp_path / "s.jsonl")
    al = score_estimate(result.final, s.truth).alignment
    want_l = float(np.mean(landmark_nees(result.final, s.truth, al)))
    want_p = pose_nees(result.final, s.truth, al)
    assert np.isfinite(want_l) and np.isfinite(want_p)
    assert ev.nees_landmark == pytest.approx(want_l, rel=1e-12)
    assert ev.nees_pose == pytest.approx(want_p, rel=1e-12)


def test_nees_under_similarity_is_given_once_for_the_final_map(tmp_path: Path) -> None:
    """``evaluate --similarity``: the headline NEES of the final map is the similarity
    alignment's (as its checkpoint row's), not left out. Before the twenty-first session's
    report audit the headline was NaN (a guard from before the NEES carried the scale, 7ccbf2b)
    while the last row of the same output gave the NEES of the same map."""
    s = _stream(60)
    write_stream(s, tmp_path / "s.jsonl")
    result = run(_CovMapper(s.header), s.steps, method="cov")
    write_estimate(result, tmp_path / "e.est", stream=stream_identity(s.steps))
    ev = evaluate_files(tmp_path / "e.est", tmp_path / "s.jsonl", with_scale=True)
    al = score_estimate(result.final, s.truth, with_scale=True).alignment
    assert al.scale != 1.0
    want_l = float(np.mean(landmark_nees(result.final, s.truth, al)))
    want_p = pose_nees(result.final, s.truth, al)
    assert np.isfinite(want_l) and np.isfinite(want_p)
    assert ev.nees_landmark == pytest.approx(want_l, rel=1e-12)
    assert ev.nees_pose == pytest.approx(want_p, rel=1e-12)
    assert ev.rows[-1].nees_landmark == pytest.approx(ev.nees_landmark, rel=1e-12)
    assert ev.rows[-1].nees_pose == pytest.approx(ev.nees_pose, rel=1e-12)


def test_run_streaming_writer_matches_in_memory(tmp_path: Path) -> None:
    s = _stream(45)
    write_stream(s, tmp_path / "s.jsonl")
    from bomgraph.bench import run_file
    r = run_file(tmp_path / "s.jsonl", "triangulate", out=tmp_path / "e.est")
    assert len(r.checkpoints) == 1
    mem = run(TriangulateMapper(s.header), s.steps, method="triangulate")
    back = read_estimate(tmp_path / "e.est")
    assert back.stream == stream_identity(s.steps)
    assert [c.t for c in back.checkpoints] == [c.t for c in mem.checkpoints]
    for c, d in zip(mem.checkpoints, back.checkpoints):
        _same(c.estimate, d.estimate)


def test_cli_run_writes_v2_and_evaluate_refuses_mismatch(tmp_path: Path, capsys) -> None:
    from bomgraph.cli import main

    write_stream(_stream(30, 0), tmp_path / "s.jsonl")
    write_stream(_stream(30, 1), tmp_path / "o.jsonl")
    est = tmp_path / "e.est"
    assert main(["run", str(tmp_path / "s.jsonl"), "--method", "triangulate",
                 "--out", str(est)]) == 0
    assert read_estimate(est).stream.n_steps == 31
    capsys.readouterr()
    assert main(["evaluate", str(est), str(tmp_path / "o.jsonl")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "computed from another stream" in err
    assert main(["evaluate", str(tmp_path / "s.jsonl"), str(est)]) == 2
    assert "swapped" in capsys.readouterr().err
    assert sorted(os.listdir(tmp_path)) == ["e.est", "o.jsonl", "s.jsonl"]


def test_run_refuses_out_equal_to_the_stream(tmp_path: Path) -> None:
    from bomgraph.bench import run_file
    from bomgraph.errors import ConfigError

    write_stream(_stream(20), tmp_path / "s.jsonl")
    before = (tmp_path / "s.jsonl").read_bytes()
    with pytest.raises(ConfigError, match="is the input stream"):
        run_file(tmp_path / "s.jsonl", "triangulate", out=tmp_path / "s.jsonl")
    assert (tmp_path / "s.jsonl").read_bytes() == before
    assert sorted(os.listdir(tmp_path)) == ["s.jsonl"]


class _Smoother(_CovMapper):
    """Triangulation whose every estimate moves all its poses (as a smoother revises them)."""

    def estimate(self):
        e = self.inner.estimate()
        return MapEstimate(e.landmark_ids, e.landmarks_xy, pose_t=e.pose_t,
                           poses=e.poses + [0.002 * self.n, 0.0, 0.0])


def test_evaluate_gives_no_ape_rpe_of_a_trajectory_the_method_never_had(tmp_path: Path) -> None:
    """An estimate file keeps each pose of an earlier checkpoint as first estimated (the
    format's rule), so for a method that revises its poses the trajectory of an earlier
    checkpoint read back is not the one the method held then. ``evaluate`` printed the APE and
    RPE of that stitched trajectory under "APE"/"RPE" (gtsam-batch on MRCLAM6 robot 3 at
    t = 150: 24.1 cm, where compare, scoring the map the method held, gives 12.6); those
    cells are now left out ('-') before the last checkpoint, and said so. A method that never
    revises (triangulate) keeps them, equal to the scores of the maps held in memory."""
    from bomgraph.evaluate import score_checkpoints
    from bomgraph.file_evaluation import format_evaluation

    s = _stream(40)
    write_stream(s, tmp_path / "s.jsonl")
    for mapper, revised in ((_Smoother(s.header), True), (TriangulateMapper(s.header), False)):
        result = run(mapper, s.steps, method="m")
        write_estimate(result, tmp_path / "e.est", stream=stream_identity(s.steps))
        ev = evaluate_files(tmp_path / "e.est", tmp_path / "s.jsonl")
        live = score_checkpoints(result, s.truth)
        assert len(ev.rows) == len(live) == 4 and ev.poses_revised == revised
        for got, want in zip(ev.rows, live):
            assert got.mpe_m == pytest.approx(want.mpe_m, rel=1e-9)
            assert got.robot_last_m == pytest.approx(want.robot_last_m, rel=1e-9)
            if revised and got is not ev.rows[-1]:
                assert np.isnan(got.ape_trans_rmse_m) and np.isnan(got.rpe_heading_rmse_rad)
            else:
                assert got.ape_trans_rmse_m == pytest.approx(want.ape_trans_rmse_m, rel=1e-9)
                assert got.rpe_trans_rmse_m == pytest.approx(want.rpe_trans_rmse_m, rel=1e-9)
        text = format_evaluation(ev)
        assert ("revised" in text) == revised
        want_mean = [w.robot_mean_m for w in live]
        got_mean = ev.table["robot_mean_m"]           # the library's table, likewise
        assert got_mean[-1] == pytest.approx(want_mean[-1], rel=1e-9)
        if revised:
            assert np.isnan(got_mean[:-1]).all()
        else:
            np.testing.assert_allclose(got_mean, want_mean, rtol=1e-9)


def test_the_revised_poses_note_says_what_each_alignment_leaves_out(tmp_path: Path) -> None:
    """h152: aligned on the trajectory or on both, an earlier checkpoint of a method that
    revises its poses gets no error at all (not only no APE/RPE), and the note says so for
    the alignment used; it read "aligned on the trajectory" under ``--align both``."""
    from bomgraph.file_evaluation import format_evaluation

    s = _stream(40)
    write_stream(s, tmp_path / "s.jsonl")
    write_estimate(run(_Smoother(s.header), s.steps, method="m"), tmp_path / "e.est",
                   stream=stream_identity(s.steps))
    for align_on in ("landmarks", "trajectory", "both"):
        ev = evaluate_files(tmp_path / "e.est", tmp_path / "s.jsonl", align_on=align_on)
        note = [ln for ln in format_evaluation(ev).splitlines() if "revised" in ln]
        assert len(note) == 1, note
        left_out = np.isnan(ev.rows[0].mpe_m)
        assert left_out == (align_on != "landmarks")
        if left_out:
            assert f"no error at all ('-'; aligned on {align_on}" in note[0], note
        else:
            assert "no APE or RPE ('-')" in note[0] and "trajectory" not in note[0], note
