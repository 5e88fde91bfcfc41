"""bomgraph.export: TUM, KITTI, CSV and g2o files read back to the numbers written."""

from __future__ import annotations

import dataclasses
import math
import os
import re
from pathlib import Path

import numpy as np
import pytest

from bomgraph.angles import angle_residual
from bomgraph.cli import main
from bomgraph.datasets import import_g2o
from bomgraph.datasets.g2o import _G2oFile
from bomgraph.export import (CSV_HEADER, ZERO_SIGMA_FLOOR, ExportError, export_text,
                             truth_estimate, write_text_atomic)
from bomgraph.mapper import MapEstimate
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream import Stream
from bomgraph.stream_file import write_stream


@pytest.fixture(scope="module")
def stream() -> Stream:
    return simulate(SimConfig(n_landmarks=15, n_steps=40), np.random.default_rng(7))


@pytest.fixture(scope="module")
def estimate(stream: Stream) -> MapEstimate:
    """The truth, perturbed and rotated (a made-up estimate with every pose and a few
    landmarks left out), headings beyond (-pi, pi] included."""
    rng = np.random.default_rng(1)
    tr = stream.truth
    keep = np.arange(len(tr.landmark_ids)) % 4 != 0
    poses = tr.poses + rng.normal(0, 0.02, tr.poses.shape)
    poses[::7, 2] += 2 * math.pi
    return MapEstimate(tr.landmark_ids[keep], tr.landmarks_xy[keep] + 0.01,
                       pose_t=np.arange(len(poses)), poses=poses)


def _with_times(stream: Stream) -> Stream:
    steps = tuple(dataclasses.replace(s, time_s=1000.0 + 0.37 * s.t) for s in stream.steps)
    return Stream(stream.header, steps, stream.truth)


def _parse_tum(text: str) -> np.ndarray:
    rows = [[float(v) for v in ln.split()] for ln in text.splitlines()
            if ln.strip() and not ln.startswith("#")]
    return np.array(rows)


def _yaw(q_xyzw: np.ndarray) -> np.ndarray:
    return 2.0 * np.arctan2(q_xyzw[:, 2], q_xyzw[:, 3])


def test_tum_parses_back_to_the_poses(stream: Stream, estimate: MapEstimate) -> None:
    timed = _with_times(stream)
    for s, times in ((stream, np.arange(len(stream.steps), dtype=float)),
                     (timed, 1000.0 + 0.37 * np.arange(len(stream.steps)))):
        rows = _parse_tum(export_text(estimate, "tum", s))
        assert rows.shape == (len(estimate.poses), 8)
        np.testing.assert_allclose(rows[:, 0], times, rtol=0, atol=1e-9)
        np.testing.assert_allclose(rows[:, 1:3], estimate.poses[:, :2], rtol=0, atol=1e-9)
        assert np.all(rows[:, 3:6] == 0.0)  # z, qx, qy
        np.testing.assert_allclose(np.linalg.norm(rows[:, 4:8], axis=1), 1.0, atol=1e-12)
        dyaw = angle_residual(_yaw(rows[:, 4:8]), estimate.poses[:, 2])
        assert np.max(np.abs(dyaw)) < 1e-9


def test_tum_is_what_evo_reads(tmp_path: Path, stream: Stream, estimate: MapEstimate) -> None:
    path = tmp_path / "est.tum"
    path.write_text(export_text(estimate, "tum", _with_times(stream)))
    try:
        from evo.tools.file_interface import read_tum_trajectory_file
    except ImportError:  # the TUM spec: '#' comments, 8 numbers a line, unit quaternion
        lines = [ln for ln in path.read_text().splitlines() if not ln.startswith("#")]
        rows = np.array([[float(v) for v in ln.split(" ")] for ln in lines])
        assert rows.shape[1] == 8 and np.all(np.diff(rows[:, 0]) > 0)
        np.testing.assert_allclose(np.linalg.norm(rows[:, 4:], axis=1), 1.0, atol=1e-12)
        return
    traj = read_tum_trajectory_file(str(path))
    np.testing.assert_allclose(traj.timestamps, 1000.0 + 0.37 * np.arange(len(stream.steps)),
                               atol=1e-9, rtol=0)
    np.testing.assert_allclose(traj.positions_xyz[:, :2], estimate.poses[:, :2], atol=1e-9,
                               rtol=0)
    np.testing.assert_allclose(traj.positions_xyz[:, 2], 0.0, atol=0)
    wxyz = traj.orientations_quat_wxyz
    yaw = 2.0 * np.arctan2(wxyz[:, 3], wxyz[:, 0])
    assert np.max(np.abs(angle_residual(yaw, estimate.poses[:, 2]))) < 1e-9


def test_kitti_round_trip(estimate: MapEstimate) -> None:
    text = export_text(estimate, "kitti")
    m = np.array([[float(v) for v in ln.split()] for ln in text.splitlines()]).reshape(-1, 3, 4)
    np.testing.assert_allclose(m[:, :2, 3], estimate.poses[:, :2], rtol=0, atol=1e-12)
    assert np.all(m[:, 2] == [0.0, 0.0, 1.0, 0.0])
    np.testing.assert_allclose(m[:, :3, :3] @ m[:, :3, :3].transpose(0, 2, 1),
                               np.broadcast_to(np.eye(3), m[:, :3, :3].shape), atol=1e-12)
    yaw = np.arctan2(m[:, 1, 0], m[:, 0, 0])
    assert np.max(np.abs(angle_residual(yaw, estimate.poses[:, 2]))) < 1e-12


def test_csv_round_trip(stream: Stream, estimate: MapEstimate) -> None:
    import csv
    import io

    text = export_text(estimate, "csv", _with_times(stream))
    rows = list(csv.DictReader(io.StringIO(text)))
    assert text.splitlines()[0] == CSV_HEADER
    poses = [r for r in rows if r["kind"] == "pose"]
    lms = [r for r in rows if r["kind"] == "landmark"]
    assert len(poses) + len(lms) == len(rows)
    got = np.array([[float(r[k]) for k in ("x_m", "y_m", "psi_rad")] for r in poses])
    assert np.array_equal([int(r["id"]) for r in poses], estimate.pose_t)
    assert np.array_equal(got, estimate.poses)  # repr precision: exact
    assert [float(r["time_s"]) for r in poses] == [1000.0 + 0.37 * t for t in estimate.pose_t]
    assert np.array_equal([int(r["id"]) for r in lms], estimate.landmark_ids)
    assert np.array_equal([[float(r["x_m"]), float(r["y_m"])] for r in lms],
                          estimate.landmarks_xy)
    assert all(r["psi_rad"] == "" and r["time_s"] == "" for r in lms)
    # landmarks only: still a csv, while tum and kitti refuse
    lm_only = MapEstimate(estimate.landmark_ids, estimate.landmarks_xy)
    assert {r.split(",")[0] for r in export_text(lm_only, "csv").splitlines()[1:]} == {"landmark"}
    for fmt in ("tum", "kitti", "g2o"):
        with pytest.raises(ExportError, match="none"):
            export_text(lm_only, fmt, stream)


@pytest.mark.parametrize("per_step_sigma", [False, True])
def test_g2o_round_trip_through_the_importer(tmp_path: Path, stream: Stream,
                                             estimate: MapEstimate, per_step_sigma: bool) -> None:
    if per_step_sigma:  # each step its own sigmas: the importer keeps them per step
        steps = tuple(s if s.odom is None else dataclasses.replace(
            s, odom_sigma=np.array([0.01, 0.02, 0.03]) * (1 + 0.1 * s.t)) for s in stream.steps)
        stream = Stream(stream.header, steps, stream.truth)
    path = tmp_path / "p.g2o"
    path.write_text(export_text(estimate, "g2o", stream))
    back = import_g2o(path)
    assert len(back.steps) == len(stream.steps)
    for a, b in zip(stream.steps, back.steps):
        assert np.array_equal(a.landmark_ids, b.landmark_ids)
        assert np.array_equal(a.bearings_rad, b.bearings_rad)  # exact
        assert (a.odom is None) == (b.odom is None)
        if a.odom is not None:
            assert np.array_equal(a.odom, b.odom)
            # sigmas go through the information matrix and back: equal up to rounding; the
            # simulator's sigma_dy = 0 comes back as the documented floor
            want = a.odometry_sigma(stream.header)
            np.testing.assert_allclose(b.odometry_sigma(back.header),
                                       np.where(want > 0, want, ZERO_SIGMA_FLOOR), rtol=1e-9)
    assert (back.steps[1].odom_sigma is not None) == per_step_sigma
    assert back.header.bearing_sigma_rad == pytest.approx(stream.header.bearing_sigma_rad,
                                                          rel=1e-12)
    # the estimate: the vertices, which the importer counts and this reader gives
    g = _G2oFile(path)
    order = back.header.meta["pose_ids"]
    assert np.array_equal(np.array([g.poses[p][0] for p in order]), estimate.poses)
    assert sorted(g.landmarks) == sorted(estimate.landmark_ids.tolist())
    for i, xy in zip(estimate.landmark_ids, estimate.landmarks_xy):
        assert np.array_equal(g.landmarks[int(i)][0], xy)
    assert back.header.meta["fixed_steps"] == [0]


def test_truth_export_matches_the_stream(tmp_path: Path, stream: Stream) -> None:
    s_path, out = tmp_path / "s.jsonl", tmp_path / "truth.tum"
    write_stream(stream, s_path)
    assert main(["export", "--truth", str(s_path), "--format", "tum", "--out", str(out)]) == 0
    rows = _parse_tum(out.read_text())
    np.testing.assert_allclose(rows[:, 1:3], stream.truth.poses[:, :2], rtol=0, atol=1e-9)
    assert np.max(np.abs(angle_residual(_yaw(rows[:, 4:8]), stream.truth.poses[:, 2]))) < 1e-9
    # the truth as g2o values, read back through the importer as its own truth
    g2o = tmp_path / "truth.g2o"
    assert main(["export", "--truth", str(s_path), "--format", "g2o", "--out", str(g2o)]) == 0
    back = import_g2o(g2o, truth_path=g2o)
    assert np.array_equal(back.truth.poses, stream.truth.poses)
    assert np.array_equal(back.truth.landmark_ids, stream.truth.landmark_ids)
    assert np.array_equal(back.truth.landmarks_xy, stream.truth.landmarks_xy)


def test_cli_export_refusals_and_stdout(tmp_path: Path, stream: Stream,
                                        capsys: pytest.CaptureFixture) -> None:
    s_path, est = tmp_path / "s.jsonl", tmp_path / "e.json"
    write_stream(stream, s_path)
    assert main(["run", str(s_path), "--method", "triangulate", "--out", str(est)]) == 0
    capsys.readouterr()
    assert main(["export", str(est), "--format", "kitti", "--out", "-"]) == 0
    assert len(capsys.readouterr().out.splitlines()) == len(stream.steps)
    before = est.read_bytes()
    assert main(["export", str(est), "--format", "tum", "--out", str(est)]) == 2
    assert main(["export", str(est), "--stream", str(s_path), "--format", "csv",
                 "--out", str(s_path)]) == 2
    assert main(["export", str(est), "--format", "g2o", "--out", str(tmp_path / "x")]) == 2
    assert main(["export", "--format", "tum", "--out", str(tmp_path / "x")]) == 2
    assert main(["export", "--truth", str(s_path), "--stream", str(s_path), "--format", "tum",
                 "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 5 and all(ln.startswith("bomgraph: error: ") for ln in err)
    assert "refusing to overwrite" in err[0] and "--stream" in err[2]
    assert est.read_bytes() == before and not (tmp_path / "x").exists()


def test_write_is_atomic(tmp_path: Path) -> None:
    out = tmp_path / "o.txt"
    out.write_text("old\n")

    with pytest.raises(TypeError):
        write_text_atomic(123, out)  # type: ignore[arg-type]
    assert out.read_text() == "old\n"
    assert os.listdir(tmp_path) == ["o.txt"]  # no temporary file left beside it
    write_text_atomic("new\n", out)
    assert out.read_text() == "new\n" and os.listdir(tmp_path) == ["o.txt"]


def test_truth_estimate_is_the_truth_and_needs_one() -> None:
    s = simulate(SimConfig(n_steps=20, n_landmarks=8), np.random.default_rng(4))
    est = truth_estimate(s)
    np.testing.assert_array_equal(est.landmark_ids, s.truth.landmark_ids)
    np.testing.assert_array_equal(est.poses, s.truth.poses)
    np.testing.assert_array_equal(est.pose_t, np.arange(len(s.steps)))
    with pytest.raises(ExportError, match="no truth"):
        truth_estimate(type(s)(s.header, s.steps, None))


def test_a_truth_without_poses_is_named_as_such() -> None:
    """MRCLAM1 has landmark truth only: exporting it as TUM says so (it blamed "the method")."""
    s = simulate(SimConfig(n_steps=20, n_landmarks=8), np.random.default_rng(4))
    lm_only = type(s)(s.header, s.steps, dataclasses.replace(s.truth, poses=None))
    with pytest.raises(ExportError, match=r"the stream's truth has none \(landmark truth only"):
        export_text(truth_estimate(lm_only), "tum")
    assert export_text(truth_estimate(lm_only), "csv").count("landmark,") == 8


def test_cli_export_says_what_the_file_holds(tmp_path: Path, stream: Stream,
                                             capsys: pytest.CaptureFixture) -> None:
    """TUM and KITTI hold poses only: the summary line counted the landmarks too."""
    s_path = tmp_path / "s.jsonl"
    write_stream(stream, s_path)
    for fmt, held in (("tum", "poses"), ("kitti", "poses"), ("csv", "poses, "),
                      ("g2o", "poses, ")):
        capsys.readouterr()
        assert main(["export", "--truth", str(s_path), "--format", fmt,
                     "--out", str(tmp_path / f"t.{fmt}")]) == 0
        line = capsys.readouterr().out.strip()
        n = len(stream.steps)
        assert line.startswith(f"wrote {tmp_path / f't.{fmt}'} ({fmt}): {n} {held}")
        assert ("landmarks" in line) == (fmt in ("csv", "g2o")), line


def test_a_pose_outside_the_stream_steps_is_refused_by_every_format(
        stream: Stream, estimate: MapEstimate) -> None:
    """h18 item 07: g2o silently dropped a pose at a step beyond the stream while counting it;
    it is refused as TUM refuses it, with or without the stream's time stamps (and a
    negative step likewise)."""
    n = len(stream.steps)
    for bad_t in (n, 1_000_000, -1):
        extra = MapEstimate(estimate.landmark_ids, estimate.landmarks_xy,
                            pose_t=np.append(estimate.pose_t, bad_t),
                            poses=np.vstack([estimate.poses, [0.0, 0.0, 0.0]]))
        for fmt, s in (("g2o", stream), ("tum", _with_times(stream)), ("tum", stream)):
            with pytest.raises(ExportError, match=f"pose at step {bad_t} .*estimate's stream"):
                export_text(extra, fmt, s)


def test_g2o_round_trip_keeps_the_streams_priors(tmp_path: Path, stream: Stream,
                                                 estimate: MapEstimate) -> None:
    """Exp. 3's known landmark distances: g2o has no landmark-landmark distance edge, so
    they go into the bomgraph header comment (a comment line says so) and come back through
    the importer; the export dropped them without a word (h37 audit: 123 priors of
    ``simulate --prior-fraction 0.1`` became 0 after export and import)."""
    from bomgraph.sim import make_priors, with_priors

    with_p = with_priors(stream, make_priors(stream.truth, 0.2, 0.03, np.random.default_rng(2)))
    assert len(with_p.header.priors) > 5
    path = tmp_path / "p.g2o"
    path.write_text(export_text(estimate, "g2o", with_p))
    assert f"# {len(with_p.header.priors)} known landmark distances" in path.read_text()
    back = import_g2o(path)
    assert back.header.priors == with_p.header.priors
    assert back.header.meta["fixed_steps"] == [0]
    path.write_text(export_text(estimate, "g2o", stream))  # none: no word of them
    assert import_g2o(path).header.priors == () and "distances" not in path.read_text()


@pytest.mark.parametrize("bad, key", [
    ('[{"i": 1, "j": 1, "distance_m": 1.0, "sigma_m": 0.1}]', "'priors[0]'"),
    ('[{"i": 1, "j": 2, "distance_m": 1.0, "sigma_m": 0}]', "'priors[0].sigma_m'"),
    ('{"i": 1}', "'priors'")])
def test_g2o_header_priors_are_checked_like_a_streams(tmp_path: Path, stream: Stream,
                                                      estimate: MapEstimate, bad: str,
                                                      key: str) -> None:
    from bomgraph.errors import DatasetError

    text = export_text(estimate, "g2o", stream).replace(
        '# bomgraph header: {', f'# bomgraph header: {{"priors":{bad},', 1)
    path = tmp_path / "p.g2o"
    path.write_text(text)
    line = next(k for k, ln in enumerate(text.splitlines(), 1) if "bomgraph header" in ln)
    with pytest.raises(DatasetError, match=rf"p\.g2o, line {line}: .*{re.escape(key)}"):
        import_g2o(path)


def test_cli_g2o_export_names_the_landmarks_g2o_will_drop(
        tmp_path: Path, stream: Stream, estimate: MapEstimate,
        capsys: pytest.CaptureFixture) -> None:
    """h152: an observed landmark without an estimate gets no VERTEX_XY, and g2o's loader
    drops its bearing edges without a word (g2opy read 5,833 of a triangulate export's
    5,862): the command says so, naming them."""
    from bomgraph.estimate_file import write_estimate
    from bomgraph.mapper import run
    from bomgraph.stream_identity import stream_identity

    class Fixed:  # a mapper whose map is the fixture's
        def step(self, step: object) -> None:
            pass

        def estimate(self) -> MapEstimate:
            return estimate

    s_path, e_path = tmp_path / "s.jsonl", tmp_path / "e.est"
    write_stream(stream, s_path)
    write_estimate(run(Fixed(), stream.steps), e_path, stream=stream_identity(stream.steps))
    missing = sorted(set(stream.landmark_ids().tolist()) - set(estimate.landmark_ids.tolist()))
    assert missing  # the fixture leaves landmarks out
    n_edges = sum(int(i) in missing for s in stream.steps for i in s.landmark_ids.tolist())
    capsys.readouterr()
    assert main(["export", str(e_path), "--stream", str(s_path), "--format", "g2o",
                 "--out", str(tmp_path / "e.g2o")]) == 0
    err = capsys.readouterr().err
    assert len(missing) > 1 and n_edges > 1
    assert f"{len(missing)} observed landmarks without an estimate have" in err, err
    assert f"ids {' '.join(map(str, missing))}" in err and f"their {n_edges} bearing" in err
    text = (tmp_path / "e.g2o").read_text()
    assert sum(ln.startswith("EDGE_BEARING_SE2_XY") for ln in text.splitlines()) == sum(
        len(s.landmark_ids) for s in stream.steps)  # the edges stay in the file
    capsys.readouterr()
    assert main(["export", "--truth", str(s_path), "--format", "g2o",
                 "--out", str(tmp_path / "t.g2o")]) == 0
    assert "without an estimate" not in capsys.readouterr().err
