"""Dataset importers: MRCLAM, bearing-only g2o, Victoria Park (issue 7).

Small synthetic excerpts are written to tmp_path and imported with exact answers known; the
real files in ../shared/data are imported, checked against the numbers in their SOURCE.md and
round-tripped through the stream format.
"""

from __future__ import annotations

import gzip
import math
import os
from pathlib import Path

import numpy as np
import pytest

from bomgraph.angles import TWO_PI, angle_residual, wrap_angle
from bomgraph.datasets._text import chain_order
from bomgraph.datasets.calibration import (bearing_residuals, fit_odometry_sigma,
                                           odometry_sigma_model, robust_bearing_stats)
from bomgraph.datasets.g2o import import_g2o, odometry_sigma_from_information
from bomgraph.datasets.mrclam import (DEFAULT_BEARING_SIGMA_RAD, KeyframeConfig, import_mrclam,
                                      integrate_odometry, interpolate_poses, odometry_poses_at,
                                      select_keyframes)
from bomgraph.datasets.victoria import import_victoria
from bomgraph.errors import ConfigError, DatasetError
from bomgraph.geometry import between, bearings_to
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import read_stream, write_stream

DATA = Path(os.environ.get("BOMGRAPH_DATA",
                          Path(__file__).resolve().parents[3] / "shared" / "data"))
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason=f"no shared data at {DATA}")

EXACT = dict(command_delay_s=0.0, attach_window_s=0.0)


def _r(x: float) -> str:
    """A float written so that reading it back gives the same float."""
    return repr(float(x))


# --------------------------------------------------------------------------------------------
# A synthetic MRCLAM folder
# --------------------------------------------------------------------------------------------

HEADER = ["# UTIAS Multi-Robot Cooperative Localization and Mapping Dataset",
          "# synthetic excerpt written by tests/test_datasets.py",
          "# Data Format:", "# columns"]
LANDMARKS = {6: (2.0, 1.0), 7: (3.0, -1.0), 8: (2.5, 0.2), 9: (-1.0, 2.5), 10: (0.5, -2.5),
             11: (-2.0, -1.0), 12: (1.5, 2.5)}
BARCODES = {1: 5, 2: 14, 3: 41, 4: 32, 5: 23, 6: 63, 7: 81, 8: 7, 9: 70, 10: 45, 11: 27,
            12: 18}


def true_poses(t: np.ndarray, v: np.ndarray, w: np.ndarray, start: tuple) -> np.ndarray:
    """Exact poses under held commands, written in the world frame (independent formula)."""
    x, y, psi = start
    out = [(x, y, psi)]
    for k in range(len(t) - 1):
        dt = t[k + 1] - t[k]
        if abs(w[k]) < 1e-12:
            x, y = x + v[k] * dt * math.cos(psi), y + v[k] * dt * math.sin(psi)
        else:
            r = v[k] / w[k]
            x, y = (x + r * (math.sin(psi + w[k] * dt) - math.sin(psi)),
                    y - r * (math.cos(psi + w[k] * dt) - math.cos(psi)))
        psi = psi + w[k] * dt
        out.append((x, y, psi))
    out = np.array(out)
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def write_table(path: Path, rows: list[str], *, crlf: bool = False, gz: bool = False) -> None:
    text = ("\r\n" if crlf else "\n").join(HEADER + rows) + ("\r\n" if crlf else "\n")
    if gz:
        (path.parent / (path.name + ".gz")).write_bytes(gzip.compress(text.encode()))
    else:
        path.write_bytes(text.encode())


def make_mrclam(folder: Path, *, v: float = 0.08, w: float | np.ndarray = 0.15,
                seconds: float = 40.0, noise_rad: float = 0.0, bias_rad: float = 0.0,
                gross_every: int = 0, seed: int = 0, crlf: bool = False, gz: bool = False,
                extras: bool = True, truth: bool = True) -> dict:
    """Robot 1 driving with held commands; bursts of exact (or noisy) bearings every 0.25 s.

    Odometry and ground truth share 100 Hz time stamps; bursts lie on them, so interpolated
    truth is exact. With ``extras`` every burst also holds a sighting of robot 2, every 10th an
    unknown barcode (99) and a repeat of its first landmark 1 ms later.
    """
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    t0 = 1248444000.0
    n = int(round(seconds * 100)) + 1
    t = t0 + 0.01 * np.arange(n)
    vv = np.full(n, v)
    ww = np.broadcast_to(np.asarray(w, dtype=float), (n,)).copy()
    gt = true_poses(t, vv, ww, (0.3, -0.2, 0.4))
    end = " " if crlf else ""
    write_table(folder / "Barcodes.dat", [f"  {s} \t  {b}{end}" for s, b in BARCODES.items()],
                crlf=crlf, gz=gz)
    write_table(folder / "Landmark_Groundtruth.dat",
                [f"  {s} \t {_r(x)} \t {_r(y)} \t 0.0001 \t 0.0001{end}"
                 for s, (x, y) in LANDMARKS.items()], crlf=crlf, gz=gz)
    write_table(folder / "Robot1_Odometry.dat",
                [f"{_r(a)} \t {_r(b)} \t {_r(c)}{end}" for a, b, c in zip(t, vv, ww)],
                crlf=crlf, gz=gz)
    if truth:
        write_table(folder / "Robot1_Groundtruth.dat",
                    [f"{_r(a)} \t {_r(p[0])} \t {_r(p[1])} \t {_r(p[2])}{end}"
                     for a, p in zip(t, gt)],
                    crlf=crlf, gz=gz)
    ids = np.array(list(LANDMARKS))
    xy = np.array(list(LANDMARKS.values()))
    rows, counts = [], {"landmark": 0, "robot": 0, "unknown": 0, "gross": 0, "repeat": 0}
    k_meas = 0
    for b, k in enumerate(range(25, n - 25, 25)):
        brg = bearings_to(gt[k], xy)
        rng_m = np.hypot(*(xy - gt[k, :2]).T)
        seen = np.abs(brg) < 0.6
        for i, lid in enumerate(ids[seen]):
            val = brg[seen][i] + bias_rad + noise_rad * rng.standard_normal()
            k_meas += 1
            if gross_every and k_meas % gross_every == 0:
                val += 0.5
                counts["gross"] += 1
            rows.append(f"{_r(t[k])} \t {BARCODES[int(lid)]} \t {_r(rng_m[seen][i])} \t "
                        f"{_r(float(wrap_angle(val)))}{end}")
            counts["landmark"] += 1
        if extras:
            rows.append(f"{_r(t[k])} \t 14 \t 1.5 \t 0.1{end}")
            counts["robot"] += 1
            if b % 10 == 0:
                rows.append(f"{_r(t[k])} \t 99 \t 2.0 \t -0.2{end}")
                counts["unknown"] += 1
                if seen.any():
                    rows.append(f"{_r(t[k] + 0.001)} \t {BARCODES[int(ids[seen][0])]} \t 2.0 \t "
                                f"0.3{end}")
                    counts["landmark"] += 1
                    counts["repeat"] += 1
    write_table(folder / "Robot1_Measurement.dat", rows, crlf=crlf, gz=gz)
    counts["total"] = len(rows)
    return {"t": t, "gt": gt, "counts": counts}


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


def test_fit_odometry_sigma_recovers_a_known_model():
    rng = np.random.default_rng(7)
    n = 4000
    u = np.column_stack([rng.uniform(0.05, 0.6, n), rng.uniform(-0.02, 0.02, n),
                         rng.uniform(-0.6, 0.6, n)])
    model = np.array([[0.005, 0.08, 0.02], [0.004, 0.03, 0.05], [0.01, 0.1, 0.12]])
    e = rng.standard_normal((n, 3)) * odometry_sigma_model(model, u)
    e[:5] += 5.0  # gross errors are excluded, not fitted
    fit, info = fit_odometry_sigma(u, e)
    assert info["n_excluded"] >= 5
    sig_true = odometry_sigma_model(model, u)
    sig_fit = odometry_sigma_model(fit, u)
    np.testing.assert_allclose(np.median(sig_fit / sig_true, axis=0), 1.0, atol=0.05)
    np.testing.assert_allclose(fit[:, 1:], model[:, 1:], rtol=0.2)


def test_robust_bearing_stats_on_known_residuals():
    rng = np.random.default_rng(1)
    r = 0.004 + 0.006 * rng.standard_normal(20000)
    r[:100] += 1.0
    st = robust_bearing_stats(r)
    assert st["bias_rad"] == pytest.approx(0.004, abs=2e-4)
    assert st["spread_rad"] == pytest.approx(0.006, rel=0.03)
    assert st["n_gross"] == 100 and st["n_outliers"] >= 100
    assert st["sigma_rad"] == pytest.approx(math.hypot(0.004, 0.006), rel=0.03)


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


# --------------------------------------------------------------------------------------------
# g2o
# --------------------------------------------------------------------------------------------

INFO = "500 0 0 500 0 5000"


def write_g2o(path: Path, stream, *, info: str | list[str] = INFO, w: float = 57295.8,
              pose_id0: int = 1200, with_vertices: bool = True, shuffle_seed: int | None = None,
              extra: list[str] = ()) -> None:
    lines = []
    if with_vertices:
        lines += [f"VERTEX_XY {i} {_r(x)} {_r(y)}" for i, (x, y)
                  in zip(stream.truth.landmark_ids, stream.truth.landmarks_xy)]
        lines += [f"VERTEX_SE2 {pose_id0 + t} {_r(p[0])} {_r(p[1])} {_r(p[2])}"
                  for t, p in enumerate(stream.truth.poses)]
    lines.append(f"FIX {pose_id0}")
    for st in stream.steps:
        if st.odom is not None:
            inf = info if isinstance(info, str) else info[st.t - 1]
            lines.append(f"EDGE_SE2 {pose_id0 + st.t - 1} {pose_id0 + st.t} "
                         f"{_r(st.odom[0])} {_r(st.odom[1])} {_r(st.odom[2])} {inf}")
        lines += [f"EDGE_BEARING_SE2_XY {pose_id0 + st.t} {i} {_r(b)} {w}"
                  for i, b in zip(st.landmark_ids, st.bearings_rad)]
    lines += list(extra)
    if shuffle_seed is not None:
        np.random.default_rng(shuffle_seed).shuffle(lines)
    path.write_text("# written by tests/test_datasets.py\n" + "\n".join(lines) + "\n")


@pytest.fixture(scope="module")
def sim_stream():
    return simulate(SimConfig(n_steps=25, n_landmarks=20), np.random.default_rng(4))


def test_g2o_excerpt_reproduces_the_simulated_stream(tmp_path, sim_stream):
    write_g2o(tmp_path / "a.g2o", sim_stream)
    s = import_g2o(tmp_path / "a.g2o", truth_path=tmp_path / "a.g2o")
    assert len(s.steps) == len(sim_stream.steps)
    for a, b in zip(s.steps, sim_stream.steps):
        assert a.t == b.t and a.odom_sigma is None
        np.testing.assert_array_equal(a.landmark_ids, b.landmark_ids)
        np.testing.assert_array_equal(a.bearings_rad, b.bearings_rad)
        if b.odom is not None:
            np.testing.assert_array_equal(a.odom, b.odom)
    assert s.truth == sim_stream.truth
    assert s.header.odometry_sigma == pytest.approx((500 ** -0.5, 500 ** -0.5, 5000 ** -0.5))
    assert s.header.bearing_sigma_rad == pytest.approx(57295.8 ** -0.5)
    assert s.header.meta["fixed_steps"] == [0]
    assert s.header.meta["pose_ids"] == list(range(1200, 1226))
    assert s.header.meta["truth_check"]["bearing"]["max_abs_rad"] < 0.2
    write_stream(s, tmp_path / "a.jsonl")
    assert read_stream(tmp_path / "a.jsonl") == s


def test_g2o_line_order_does_not_matter(tmp_path, sim_stream):
    write_g2o(tmp_path / "a.g2o", sim_stream)
    write_g2o(tmp_path / "b.g2o", sim_stream, shuffle_seed=11)
    a = import_g2o(tmp_path / "a.g2o", truth_path=tmp_path / "a.g2o")
    b = import_g2o(tmp_path / "b.g2o", truth_path=tmp_path / "b.g2o")
    assert a.steps == b.steps and a.truth == b.truth


def test_g2o_varying_information_gives_per_step_sigma(tmp_path, sim_stream):
    infos = [f"{100 * (k + 1)} 0 0 {100 * (k + 1)} 0 {1000 * (k + 1)}" for k in range(25)]
    write_g2o(tmp_path / "a.g2o", sim_stream, info=infos)
    s = import_g2o(tmp_path / "a.g2o")
    assert s.truth is None and s.header.meta["odometry_sigma_per_step"]
    # step 3 has the third edge: information (300, 300, 3000)
    np.testing.assert_allclose(s.steps[3].odom_sigma, 1 / np.sqrt([300, 300, 3000]))
    np.testing.assert_allclose(s.header.odometry_sigma,
                               np.median([st.odom_sigma for st in s.steps[1:]], axis=0))


def test_g2o_information_conversion_against_numeric_jacobian():
    """The g2o error e(delta) = toVector(Z^-1 X(delta)); Sigma_stream = Je^-1 Omega^-1 Je^-T."""
    z = np.array([0.7, -0.2, 0.9])
    a = np.array([[2.0, 0.3, 0.1], [0.3, 1.0, -0.2], [0.1, -0.2, 0.5]])
    omega = np.linalg.inv(a @ a.T * 1e-3)
    eps = 1e-7
    jac = np.zeros((3, 3))
    for k in range(3):
        d = np.zeros(3)
        d[k] = eps
        jac[:, k] = (between(z, z + d) - between(z, z - d)) / (2 * eps)
    jinv = np.linalg.inv(jac)
    cov = jinv @ np.linalg.inv(omega) @ jinv.T
    sigma, corr = odometry_sigma_from_information(z[2], omega)
    np.testing.assert_allclose(sigma, np.sqrt(np.diag(cov)), rtol=1e-6)
    expected = np.max(np.abs((cov / np.outer(sigma, sigma))[np.triu_indices(3, 1)]))
    assert corr == pytest.approx(expected, rel=1e-5)


@pytest.mark.parametrize("extra, pattern", [
    (["EDGE_SE2_XY 1200 3 1.0 2.0 1 0 1"], r"line \d+: field 'tag': unsupported record"),
    (["EDGE_BEARING_SE2_XY 1201 3 0.5"], r"line \d+: EDGE_BEARING_SE2_XY needs 4 fields"),
    (["EDGE_BEARING_SE2_XY 1201 3 zero 57295.8"], r"line \d+: field 'bearing': cannot read"),
    (["EDGE_BEARING_SE2_XY 1201 -3 0.1 57295.8"], r"line \d+: field 'l': vertex id must"),
    (["EDGE_BEARING_SE2_XY 1201 3 0.1 0"], r"line \d+: field 'w': bearing information"),
    (["EDGE_BEARING_SE2_XY 999 3 0.1 57295.8"], r"line \d+: field 'i': bearing from vertex 999"),
    (["EDGE_SE2 1203 1201 1 0 0 " + INFO], r"line \d+: pose 1203 already has odometry"),
    (["EDGE_SE2 1300 1301 1 0 0 " + INFO], r"line \d+: the odometry edges form 2 separate"),
    (["EDGE_SE2 1225 1226 1 0 0 1 2 0 1 0 1"], r"line \d+: field 'information': .*positive"),
    (["VERTEX_XY 3 0 0"], r"line \d+: field 'id': vertex 3 is defined twice"),
])
def test_g2o_malformed_lines(tmp_path, sim_stream, extra, pattern):
    write_g2o(tmp_path / "bad.g2o", sim_stream, extra=extra)
    with pytest.raises(DatasetError, match=r"bad\.g2o, " + pattern):
        import_g2o(tmp_path / "bad.g2o")


def test_g2o_duplicate_bearing_names_both_lines(tmp_path, sim_stream):
    st = sim_stream.steps[2]
    line = f"EDGE_BEARING_SE2_XY 1202 {st.landmark_ids[0]} 0.1 57295.8"
    write_g2o(tmp_path / "bad.g2o", sim_stream, extra=[line])
    with pytest.raises(DatasetError, match=r"line \d+: a second bearing .* \(first on line \d+\)"):
        import_g2o(tmp_path / "bad.g2o")


def test_g2o_truth_missing_a_pose(tmp_path, sim_stream):
    write_g2o(tmp_path / "a.g2o", sim_stream)
    write_g2o(tmp_path / "t.g2o", sim_stream, pose_id0=5000)
    with pytest.raises(DatasetError, match=r"t\.g2o: no VERTEX_SE2 for pose 1200"):
        import_g2o(tmp_path / "a.g2o", truth_path=tmp_path / "t.g2o")


@needs_data
def test_real_g2o_set(tmp_path):
    d = DATA / "bearing_only_sim_g2o"
    s = import_g2o(d / "slam2D_bearing_only_initial_guess.g2o",
                   truth_path=d / "slam2D_bearing_only_ground_truth.g2o")
    assert len(s.steps) == 301
    assert sum(len(st.landmark_ids) for st in s.steps) == 2132
    assert len(s.landmark_ids()) == 141 == len(s.truth.landmark_ids)
    assert s.header.meta["fixed_steps"] == [298]  # FIX 1498, poses 1200..1500
    r, _, _ = bearing_residuals(s)
    assert abs(np.mean(r)) < 5e-4 and np.std(r) == pytest.approx(0.003, abs=5e-4)
    assert np.max(np.abs(r)) < 0.012  # SOURCE.md: max 0.011 rad
    write_stream(s, tmp_path / "g.jsonl")
    assert read_stream(tmp_path / "g.jsonl") == s


# --------------------------------------------------------------------------------------------
# Victoria Park
# --------------------------------------------------------------------------------------------

VICTORIA = """ODOMETRY 0 1 1.0 0 0.1 0.0001 0 0 4e-06 0 4e-06
LANDMARK 1 2 10 0 0.4 0 0.4
ODOMETRY 1 3 0.5 0.01 -0.2 0.0001 0 0 4e-06 0 4e-06
LANDMARK 3 2 5 5 0.4 0 0.4
LANDMARK 3 4 0 -2 0.4 0 0.4
ODOMETRY 3 5 0.0 0.0 0.0 0.0001 0 0 4e-06 0 4e-06
"""


def test_victoria_excerpt(tmp_path):
    (tmp_path / "v.txt").write_text(VICTORIA)
    s = import_victoria(tmp_path / "v.txt")
    assert len(s.steps) == 4 and s.truth is None
    assert s.header.meta["n_landmark_records"] == 3
    np.testing.assert_array_equal(s.steps[1].landmark_ids, [2])
    np.testing.assert_array_equal(s.steps[2].landmark_ids, [2, 4])
    np.testing.assert_allclose(s.steps[2].bearings_rad, [math.pi / 4, -math.pi / 2])
    np.testing.assert_allclose(s.steps[2].odom, [0.5, 0.01, -0.2])
    assert s.header.odometry_sigma == pytest.approx((0.01, 0.002, 0.002))
    # propagated point sigma sqrt(0.4) / range: 0.063, 0.089, 0.316 -> median 0.089
    assert s.header.bearing_sigma_rad == pytest.approx(math.sqrt(0.4) / math.hypot(5, 5))
    assert s.header.meta["bearing_sigma_gtsam_example_rad"] == pytest.approx(0.2)
    write_stream(s, tmp_path / "v.jsonl")
    assert read_stream(tmp_path / "v.jsonl") == s


@pytest.mark.parametrize("bad, pattern", [
    ("LANDMARK 3 6 1.0 1e400 0.4 0 0.4", r"line 7: field 'y': '1e400' is not a finite"),
    ("LANDMARK 3 6 1.0 1.0 0.4 0", r"line 7: LANDMARK needs 7 fields"),
    ("LANDMARK 3 2 1.0 1.0 0.4 0 0.4", r"line 7: landmark 2 seen a second time .*line 4"),
    ("LANDMARK 9 6 1.0 1.0 0.4 0 0.4", r"line 7: field 'i': landmark seen from pose 9"),
    ("ODOMETRY 5 7 1 0 0 0.0001 0 0 -4e-06 0 4e-06", r"line 7: field 'covariance'"),
    ("POINT 1 2", r"line 7: field 'tag': unknown record 'POINT'"),
])
def test_victoria_malformed_lines(tmp_path, bad, pattern):
    (tmp_path / "v.txt").write_text(VICTORIA + bad + "\n")
    with pytest.raises(DatasetError, match=r"v\.txt, " + pattern):
        import_victoria(tmp_path / "v.txt")


@needs_data
def test_real_victoria_park(tmp_path):
    s = import_victoria(DATA / "victoria_park" / "victoria_park.txt")
    assert len(s.steps) == 6969  # 6968 odometry lines, one chain
    assert sum(len(st.landmark_ids) for st in s.steps) == 3640
    assert len(s.landmark_ids()) == 151
    b = np.concatenate([st.bearings_rad for st in s.steps])
    assert -1.23 < b.min() < -1.2 and 1.3 < b.max() < 1.33  # SOURCE.md: -1.22..+1.32 rad
    write_stream(s, tmp_path / "v.jsonl")
    assert read_stream(tmp_path / "v.jsonl") == s


# --------------------------------------------------------------------------------------------
# The odometry chain
# --------------------------------------------------------------------------------------------

def test_chain_order_follows_edges_not_ids():
    assert chain_order([(5, 2, 1), (9, 5, 2), (2, 7, 3)], "f") == [9, 5, 2, 7]
    assert chain_order([], "f") == []
    with pytest.raises(DatasetError, match="f, line 2: .*closed loop"):
        chain_order([(0, 1, 1), (2, 3, 2), (3, 2, 3)], "f")
    with pytest.raises(DatasetError, match="f, line 1: the odometry edges form a closed loop"):
        chain_order([(0, 1, 1), (1, 0, 2)], "f")
    with pytest.raises(DatasetError, match="f, line 2: pose 4 already has odometry from"):
        chain_order([(0, 4, 1), (1, 4, 2)], "f")
    with pytest.raises(DatasetError, match="to itself"):
        chain_order([(3, 3, 1)], "f")


# --------------------------------------------------------------------------------------------
# The command line
# --------------------------------------------------------------------------------------------

def test_cli_import_commands(tmp_path, sim_stream, capsys):
    from bomgraph.cli import main

    make_mrclam(tmp_path / "m")
    assert main(["import", "mrclam", str(tmp_path / "m"), "--robot", "1", "--out",
                 str(tmp_path / "m.jsonl")]) == 0
    assert read_stream(tmp_path / "m.jsonl") == import_mrclam(tmp_path / "m", 1)
    write_g2o(tmp_path / "a.g2o", sim_stream)
    assert main(["import", "g2o", str(tmp_path / "a.g2o"), "--truth", str(tmp_path / "a.g2o"),
                 "--out", str(tmp_path / "g.jsonl")]) == 0
    assert read_stream(tmp_path / "g.jsonl").truth == sim_stream.truth
    (tmp_path / "v.txt").write_text(VICTORIA)
    assert main(["import", "victoria", str(tmp_path / "v.txt"), "--out",
                 str(tmp_path / "v.jsonl")]) == 0
    assert "4 steps, 3 bearings, 2 landmarks" in capsys.readouterr().out
    (tmp_path / "v.txt").write_text(VICTORIA + "LANDMARK 3 6 1.0 oops 0.4 0 0.4\n")
    assert main(["import", "victoria", str(tmp_path / "v.txt"), "--out",
                 str(tmp_path / "x.jsonl")]) == 2
    err = capsys.readouterr().err
    assert "v.txt, line 7: field 'y'" in err and not (tmp_path / "x.jsonl").exists()
