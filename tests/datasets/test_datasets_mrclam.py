"""MRCLAM importer: kinematics, keyframes, synthetic folders with exact answers, the real
recordings (checked against their SOURCE.md and round-tripped through the stream format)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from dataset_excerpts import DATA, EXACT, LANDMARKS, make_mrclam, needs_data, true_poses

from bomgraph.angles import TWO_PI, angle_residual
from bomgraph.datasets.calibration import bearing_residuals
from bomgraph.datasets.mrclam import (DEFAULT_BEARING_SIGMA_RAD, KeyframeConfig, import_mrclam,
                                      integrate_odometry, interpolate_poses, odometry_poses_at,
                                      select_keyframes)
from bomgraph.errors import ConfigError, DatasetError
from bomgraph.geometry import between
from bomgraph.stream_file import read_stream, write_stream


# --------------------------------------------------------------------------------------------
# MRCLAM: kinematics, interpolation, keyframes
# --------------------------------------------------------------------------------------------

def test_integrate_odometry_matches_closed_form_arcs():
    t = 100.0 + np.cumsum(np.r_[0.0, np.full(300, 0.013)])
    v = np.linspace(0.02, 0.09, t.size)
    w = np.where(np.arange(t.size) % 50 < 25, 0.4, -0.3)
    w[100:120] = 0.0
    p = integrate_odometry(t, v, w)
    ref = true_poses(t, v, w, (0.0, 0.0, 0.0))
    np.testing.assert_allclose(p[:, :2], ref[:, :2], atol=1e-12)
    np.testing.assert_allclose(angle_residual(p[:, 2], ref[:, 2]), 0.0, atol=1e-12)


def test_full_circle_returns_to_start_and_heading_is_cumulative():
    t = np.linspace(0.0, TWO_PI / 0.5, 1001)  # one full turn at 0.5 rad/s
    p = integrate_odometry(t, np.full(t.size, 0.1), np.full(t.size, 0.5))
    np.testing.assert_allclose(p[-1, :2], 0.0, atol=1e-12)
    assert p[-1, 2] == pytest.approx(TWO_PI, abs=1e-12)  # cumulative, not wrapped


def test_odometry_poses_at_between_samples_is_exact_on_the_arc():
    t = np.array([0.0, 1.0, 2.5])
    v, w = np.array([0.1, 0.05, 0.0]), np.array([0.3, -0.2, 0.0])
    p = integrate_odometry(t, v, w)
    q = np.array([0.0, 0.4, 1.0, 1.7, 2.5])
    got = odometry_poses_at(t, v, w, p, q)
    fine = np.unique(np.r_[t, q])
    seg = np.searchsorted(t, fine, side="right") - 1
    ref = true_poses(fine, v[seg], w[seg], (0.0, 0.0, 0.0))[np.searchsorted(fine, q)]
    np.testing.assert_allclose(got[:, :2], ref[:, :2], atol=1e-12)
    np.testing.assert_allclose(angle_residual(got[:, 2], ref[:, 2]), 0.0, atol=1e-12)


def test_interpolate_poses_takes_the_short_way_across_pi():
    t = np.array([0.0, 1.0])
    poses = np.array([[0.0, 0.0, math.pi - 0.1], [1.0, 2.0, -math.pi + 0.1]])
    got = interpolate_poses(t, poses, np.array([0.0, 0.25, 0.5, 1.0]))
    np.testing.assert_allclose(got[:, :2], [[0, 0], [0.25, 0.5], [0.5, 1.0], [1.0, 2.0]])
    np.testing.assert_allclose(angle_residual(got[:, 2], [math.pi - 0.1, math.pi - 0.05,
                                                          math.pi, -math.pi + 0.1]), 0.0,
                               atol=1e-12)


def test_select_keyframes_by_distance_and_by_turn():
    straight = np.column_stack([0.02 * np.arange(50), np.zeros(50), np.zeros(50)])
    kf = select_keyframes(straight, 0.29, 0.0)
    np.testing.assert_array_equal(kf, np.arange(0, 50, 15))
    turning = np.column_stack([np.zeros(40), np.zeros(40), 0.1 * np.arange(40)])
    kf = select_keyframes(turning, 0.3, 0.25)
    np.testing.assert_array_equal(kf, np.arange(0, 40, 3))
    assert select_keyframes(np.zeros((0, 3)), 0.3, 0.3).size == 0


def test_keyframe_config_is_validated():
    with pytest.raises(ConfigError, match="min_distance_m"):
        KeyframeConfig(min_distance_m=-0.1)
    with pytest.raises(ConfigError, match="both be 0"):
        KeyframeConfig(min_distance_m=0.0, min_turn_rad=0.0)
    with pytest.raises(ConfigError, match="attach_window_s"):
        KeyframeConfig(attach_window_s=float("nan"))


# --------------------------------------------------------------------------------------------
# MRCLAM: synthetic folders
# --------------------------------------------------------------------------------------------

def test_noise_free_excerpt_gives_exact_odometry_bearings_and_truth(tmp_path):
    world = make_mrclam(tmp_path)
    s = import_mrclam(tmp_path, 1, keyframe=KeyframeConfig(**EXACT))
    assert len(s.steps) > 10
    # truth poses are the ground-truth rows at the keyframe times
    rows = np.searchsorted(world["t"], [st.time_s for st in s.steps])
    np.testing.assert_allclose(s.truth.poses, world["gt"][rows], atol=1e-12)
    # odometry = the true increments; bearings = the true bearings
    inc = between(s.truth.poses[:-1], s.truth.poses[1:])
    np.testing.assert_allclose(np.array([st.odom for st in s.steps[1:]]), inc, atol=1e-9)
    r, _, _ = bearing_residuals(s)
    assert r.size == sum(len(st.landmark_ids) for st in s.steps)
    np.testing.assert_allclose(r, 0.0, atol=1e-9)
    # keyframes: every step moved at least the threshold (0.3 m) or turned 0.3 rad
    length = np.hypot(inc[:, 0], inc[:, 1])
    assert np.all((length >= 0.3 - 1e-9) | (np.abs(inc[:, 2]) >= 0.3 - 1e-9))
    # truth landmarks and calibrated sigmas (noise-free: at the floors)
    np.testing.assert_array_equal(s.truth.landmark_ids, list(LANDMARKS))
    assert s.header.bearing_sigma_rad == pytest.approx(1e-4)
    assert np.all(np.array([st.odom_sigma for st in s.steps[1:]]) < 2e-3)
    # every landmark detection at its own time (the 1 ms repeats carry a wrong bearing, 0.3)
    raw = s.header.meta["raw_bearing_check"]
    assert raw["n"] == world["counts"]["landmark"]
    assert raw["bias_rad"] == pytest.approx(0.0, abs=1e-9)
    assert raw["n_outliers"] == world["counts"]["repeat"] > 0


def test_rows_are_all_accounted_for(tmp_path):
    world = make_mrclam(tmp_path)
    s = import_mrclam(tmp_path, 1, keyframe=KeyframeConfig(**EXACT))
    rows = s.header.meta["rows"]
    c = world["counts"]
    assert rows["total"] == c["total"]
    assert rows["robot_sightings"] == c["robot"]
    assert rows["unknown_barcode"] == c["unknown"]
    assert rows["unknown_barcode_values"] == [99]
    assert rows["duplicate_in_keyframe"] + rows["between_keyframes"] + rows["kept"] \
        == c["landmark"]
    assert rows["kept"] == sum(len(st.landmark_ids) for st in s.steps)
    assert rows["between_keyframes"] > 0


def test_repeated_landmark_keeps_the_detection_closest_in_time(tmp_path):
    make_mrclam(tmp_path)
    s = import_mrclam(tmp_path, 1, keyframe=KeyframeConfig(command_delay_s=0.0,
                                                           attach_window_s=0.01))
    # the 1 ms repeats carry a wrong bearing (0.3); they must never win
    r, _, _ = bearing_residuals(s)
    np.testing.assert_allclose(r, 0.0, atol=1e-9)
    assert s.header.meta["rows"]["duplicate_in_keyframe"] > 0


def test_turning_in_place_attached_bearings_are_reexpressed_exactly(tmp_path):
    make_mrclam(tmp_path, v=0.0, w=0.4, extras=False)
    cfg = KeyframeConfig(command_delay_s=0.0, attach_window_s=0.3, min_turn_rad=0.25)
    s = import_mrclam(tmp_path, 1, keyframe=cfg)
    s0 = import_mrclam(tmp_path, 1, keyframe=KeyframeConfig(
        command_delay_s=0.0, attach_window_s=0.0, min_turn_rad=0.25))
    assert len(s.steps) == len(s0.steps) > 10
    # neighbours' detections of landmarks not in the keyframe's own burst were attached
    assert s.header.meta["rows"]["kept"] > s0.header.meta["rows"]["kept"]
    r, _, _ = bearing_residuals(s)
    np.testing.assert_allclose(r, 0.0, atol=1e-9)  # pure rotation: the re-expression is exact
    s_raw = import_mrclam(tmp_path, 1, keyframe=KeyframeConfig(
        command_delay_s=0.0, attach_window_s=0.3, min_turn_rad=0.25, rotate_bearings=False))
    r_raw, _, _ = bearing_residuals(s_raw)
    assert np.max(np.abs(r_raw)) == pytest.approx(0.1, abs=1e-6)  # 0.25 s at 0.4 rad/s


def test_command_delay_shifts_the_odometry(tmp_path):
    w = np.where((np.arange(4001) // 150) % 2 == 0, 0.3, -0.2)
    world = make_mrclam(tmp_path, w=w, extras=False)
    s0 = import_mrclam(tmp_path, 1, keyframe=KeyframeConfig(**EXACT))
    s1 = import_mrclam(tmp_path, 1, keyframe=KeyframeConfig(command_delay_s=0.05,
                                                            attach_window_s=0.0))
    # with a delay the integration starts later, so the first keyframes shift and the
    # odometry no longer matches the (undelayed) truth exactly
    e0 = s0.header.meta["odometry_model"]["rms_error"]
    e1 = s1.header.meta["odometry_model"]["rms_error"]
    assert max(e0) < 1e-9 < max(e1)
    assert world["t"][0] + 0.05 <= s1.steps[0].time_s


def test_noisy_biased_excerpt_calibrates_bias_sigma_and_outliers(tmp_path):
    make_mrclam(tmp_path, seconds=300.0, noise_rad=0.01, bias_rad=0.01, gross_every=97,
                extras=False, seed=3)
    s = import_mrclam(tmp_path, 1, keyframe=KeyframeConfig(min_distance_m=0.1,
                                                           min_turn_rad=0.1, **EXACT))
    cal = s.header.meta["bearing_calibration"]
    assert cal["n"] > 300
    assert cal["bias_rad"] == pytest.approx(0.01, abs=0.002)
    assert cal["spread_rad"] == pytest.approx(0.01, rel=0.15)
    # header sigma is the RMS about zero: bias and noise together
    assert s.header.bearing_sigma_rad == pytest.approx(math.hypot(0.01, 0.01), rel=0.15)
    r, _, _ = bearing_residuals(s)
    assert cal["n_gross"] == int((np.abs(r) > 0.2).sum()) > 0
    assert cal["n_outliers"] >= cal["n_gross"]


def test_gzip_crlf_and_trailing_blanks_give_the_same_stream(tmp_path):
    make_mrclam(tmp_path / "plain")
    make_mrclam(tmp_path / "gz", gz=True)
    make_mrclam(tmp_path / "crlf", crlf=True)
    cfg = KeyframeConfig(**EXACT)
    a = import_mrclam(tmp_path / "plain", 1, keyframe=cfg)
    b = import_mrclam(tmp_path / "gz", 1, keyframe=cfg)
    c = import_mrclam(tmp_path / "crlf", 1, keyframe=cfg)
    assert a.steps == b.steps == c.steps
    assert a.truth == b.truth == c.truth
    assert a.header.bearing_sigma_rad == b.header.bearing_sigma_rad
    assert b.header.meta["files"]["odometry"] == "Robot1_Odometry.dat.gz"


def test_round_trip_and_keep_ranges(tmp_path):
    make_mrclam(tmp_path / "d")
    s = import_mrclam(tmp_path / "d", 1, keep_ranges=True)
    ranges = s.header.meta["ranges_m"]
    assert len(ranges) == s.header.meta["rows"]["kept"]
    assert s.header.sensor_range_m == pytest.approx(max(r for _, _, r in ranges))
    write_stream(s, tmp_path / "s.jsonl")
    assert read_stream(tmp_path / "s.jsonl") == s


def test_odometry_scale_scales_the_lengths_and_the_meta_measures_it(tmp_path):
    """Velocities logged 5 % high: the odometry increments are the true chords x 1.05 (the
    same headings, arcs over the same intervals), so ``odometry_length_ratio`` is 1 / 1.05,
    and importing with that scale gives the true increments back."""
    world = make_mrclam(tmp_path, extras=False)
    odo = tmp_path / "Robot1_Odometry.dat"
    lines = odo.read_text().split("\n")
    head = [ln for ln in lines if ln.startswith("#")]
    rows = [ln.split("\t") for ln in lines if ln.strip() and not ln.startswith("#")]
    odo.write_text("\n".join(head + [f"{a}\t {float(b) * 1.05!r} \t{c}" for a, b, c in rows])
                   + "\n")
    s = import_mrclam(tmp_path, 1, keyframe=KeyframeConfig(**EXACT))
    assert s.header.meta["odometry_scale"] == 1.0
    assert s.header.meta["odometry_length_ratio"] == pytest.approx(1 / 1.05, abs=1e-9)
    fixed = import_mrclam(tmp_path, 1, keyframe=KeyframeConfig(**EXACT),
                          odometry_scale=1 / 1.05)
    assert fixed.header.meta["odometry_scale"] == pytest.approx(1 / 1.05)
    assert fixed.header.meta["odometry_length_ratio"] == pytest.approx(1.0, abs=1e-9)
    rows_at = np.searchsorted(world["t"], [st.time_s for st in fixed.steps])
    np.testing.assert_allclose(fixed.truth.poses, world["gt"][rows_at], atol=1e-12)
    inc = between(fixed.truth.poses[:-1], fixed.truth.poses[1:])
    np.testing.assert_allclose(np.array([st.odom for st in fixed.steps[1:]]), inc, atol=1e-9)
    for bad in (0.0, 3.0, float("nan")):
        with pytest.raises(ConfigError, match="odometry_scale"):
            import_mrclam(tmp_path, 1, odometry_scale=bad)


def test_without_truth_calibration_must_be_turned_off(tmp_path):
    make_mrclam(tmp_path, truth=False)
    with pytest.raises(DatasetError, match="calibrate=False"):
        import_mrclam(tmp_path, 1)
    s = import_mrclam(tmp_path, 1, calibrate=False)
    assert s.truth.poses is None
    assert s.header.bearing_sigma_rad == DEFAULT_BEARING_SIGMA_RAD
    assert s.steps[1].odom_sigma is not None


def _replace_line(path: Path, line_no: int, new: str) -> None:
    lines = path.read_text().split("\n")
    lines[line_no - 1] = new
    path.write_text("\n".join(lines))


@pytest.mark.parametrize("file, line_no, new, field", [
    ("Robot1_Measurement.dat", 7, "1248444000.5 \t 63 \t 2.0 \t abc", "bearing"),
    ("Robot1_Measurement.dat", 9, "1248444000.5 \t 6x3 \t 2.0 \t 0.1", "barcode"),
    ("Robot1_Odometry.dat", 12, "1248444000.07 \t 0.08 \t nan", "w"),
    ("Robot1_Groundtruth.dat", 30, "1248444000.25 \t 1.0 \t inf \t 0.2", "y"),
    ("Landmark_Groundtruth.dat", 6, "  7 \t 3.0 \t -1.0 \t 0.0001 \t ?", "y_std"),
])
def test_malformed_value_names_file_line_and_field(tmp_path, file, line_no, new, field):
    make_mrclam(tmp_path)
    _replace_line(tmp_path / file, line_no, new)
    with pytest.raises(DatasetError) as exc:
        import_mrclam(tmp_path, 1)
    msg = str(exc.value)
    assert file in msg and f"line {line_no}" in msg and f"'{field}'" in msg
    assert "fix" in msg


def test_malformed_structure_names_file_and_line(tmp_path):
    make_mrclam(tmp_path)
    _replace_line(tmp_path / "Robot1_Odometry.dat", 20, "1248444000.16 \t 0.08")
    with pytest.raises(DatasetError, match=r"Robot1_Odometry\.dat, line 20: expected 3 fields"):
        import_mrclam(tmp_path, 1)
    make_mrclam(tmp_path)
    _replace_line(tmp_path / "Robot1_Odometry.dat", 20, "1248444000.0 \t 0.08 \t 0.15")
    with pytest.raises(DatasetError, match=r"line 20: field 'time'.*earlier"):
        import_mrclam(tmp_path, 1)
    make_mrclam(tmp_path)
    _replace_line(tmp_path / "Barcodes.dat", 8, "  4 \t 5")
    with pytest.raises(DatasetError, match=r"Barcodes\.dat, line 8: field 'barcode'.*twice"):
        import_mrclam(tmp_path, 1)


def test_missing_folder_file_and_bad_robot(tmp_path):
    with pytest.raises(DatasetError, match="not a directory"):
        import_mrclam(tmp_path / "nope", 1)
    make_mrclam(tmp_path)
    with pytest.raises(DatasetError, match="one of 1, 2, 3, 4, 5"):
        import_mrclam(tmp_path, 6)
    with pytest.raises(DatasetError, match="Robot2_Odometry.dat nor Robot2_Odometry.dat.gz"):
        import_mrclam(tmp_path, 2)


# --------------------------------------------------------------------------------------------
# MRCLAM: the real recordings
# --------------------------------------------------------------------------------------------

@needs_data
def test_real_mrclam6_robot3_matches_source_and_round_trips(tmp_path):
    s = import_mrclam(DATA / "mrclam6", 3)
    rows = s.header.meta["rows"]
    # SOURCE.md: 5627 rows = 4348 landmark / 1277 robot / 2 unknown barcode
    assert (rows["total"], rows["robot_sightings"], rows["unknown_barcode"]) == (5627, 1277, 2)
    assert rows["total"] - rows["robot_sightings"] - rows["unknown_barcode"] == 4348
    assert len(s.steps) > 100 and len(s.truth.poses) == len(s.steps)
    assert len(s.landmark_ids()) == 15
    # sanity: measured bearings agree with truth poses and landmarks
    r, _, _ = bearing_residuals(s)
    assert abs(np.median(r)) < 0.005
    assert 1.4826 * np.median(np.abs(r - np.median(r))) < 0.015
    assert 0.005 < s.header.bearing_sigma_rad < 0.03
    assert np.all(np.abs(np.concatenate([st.bearings_rad for st in s.steps])) < 0.75)  # FOV
    out = tmp_path / "r3.jsonl"
    write_stream(s, out)
    assert read_stream(out) == s


@needs_data
def test_real_mrclam6_robot4_shows_its_bearing_bias():
    s = import_mrclam(DATA / "mrclam6", 4)
    cal = s.header.meta["bearing_calibration"]
    assert -0.02 < cal["bias_rad"] < -0.008  # SOURCE.md quirk 6: about -0.01 rad
    assert cal["outlier_rate"] < 0.05
    raw = s.header.meta["raw_bearing_check"]  # all 2023 landmark detections
    assert raw["n"] == 2023 and -0.02 < raw["bias_rad"] < -0.008


@needs_data
def test_real_mrclam1_gzip_without_robot_truth(tmp_path):
    s = import_mrclam(DATA / "mrclam1", 3, calibrate=False)
    rows = s.header.meta["rows"]
    # SOURCE.md: 8742 rows = 6771 landmark / 1969 robot / 2 unknown barcode
    assert (rows["total"], rows["robot_sightings"], rows["unknown_barcode"]) == (8742, 1969, 2)
    assert s.truth.poses is None and len(s.truth.landmark_ids) == 15
    write_stream(s, tmp_path / "m1.jsonl")
    assert read_stream(tmp_path / "m1.jsonl") == s


def test_too_few_steps_to_calibrate_names_the_folder_and_the_flag(tmp_path):
    """h91's fuzz: a ground-truth file cut short left 5 keyframes with truth, and the refusal
    named neither the folder nor the robot, and only the library's ``calibrate=False``."""
    make_mrclam(tmp_path, seconds=2.0)
    with pytest.raises(DatasetError, match=rf"^{tmp_path}: robot 1: need at least 6 steps to "
                                           rf"calibrate .*--no-calibrate"):
        import_mrclam(tmp_path, 1)
