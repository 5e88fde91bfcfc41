"""MRCLAM keyframing and calibration at their edges (h102's mutation audit: a threshold
passed instead of reached, a turn wrapped before it is compared, the command delay's sign,
the header sigma's median, the sigma model's regressors: each was changed and every test
still passed). Expected values are worked out here by hand or from the synthetic world's
own constant commands, not by the importer's functions."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from dataset_excerpts import EXACT, make_mrclam

from bomgraph.datasets.calibration import odometry_sigma_model
from bomgraph.datasets.mrclam import (DEFAULT_ODOMETRY_MODEL, KeyframeConfig, _attach_detections,
                                      _select_keyframes, import_mrclam, integrate_odometry,
                                      select_keyframes)


def test_a_keyframe_threshold_is_reached_not_passed():
    """The docstring: a candidate becomes a keyframe when its motion *reaches* a threshold.
    0.25 and 0.5 are exact in binary, so the distance and the turn equal it exactly."""
    k = np.arange(8)
    straight = np.column_stack([0.25 * k, np.zeros(8), np.zeros(8)])
    assert select_keyframes(straight, 0.5, 0.0).tolist() == [0, 2, 4, 6]
    turning = np.column_stack([np.zeros(8), np.zeros(8), 0.25 * k])
    assert select_keyframes(turning, 0.0, 0.5).tolist() == [0, 2, 4, 6]


def test_a_turn_of_nearly_a_full_circle_between_candidates_is_a_keyframe():
    """The heading is cumulative: 6.2 rad of turning is 6.2 rad, not the -0.08 rad it wraps
    to (a robot spinning between two bursts of detections)."""
    poses = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 6.2], [0.0, 0.0, 6.25]])
    assert select_keyframes(poses, 0.0, 0.3).tolist() == [0, 1]


def test_an_arc_below_the_series_switch_bends_by_half_the_turn():
    """One held command, v = 1 m/s, w = 1e-7 rad/s for 1 s: the chord's lateral part is
    (1 - cos th) / w = 2 sin^2(th / 2) / w (th = 1e-7), about 5e-8 m."""
    th = 1e-7
    pose = integrate_odometry(np.array([0.0, 1.0]), np.array([1.0, 1.0]),
                              np.array([th, th]))[-1]
    assert pose[0] == pytest.approx(math.sin(th) / th, rel=1e-12)
    assert pose[1] == pytest.approx(2.0 * math.sin(th / 2) ** 2 / th, rel=1e-6)
    assert pose[2] == pytest.approx(th, rel=1e-12)


def test_burst_gap_and_attach_window_include_their_bound():
    """"Detections at most burst_gap_s apart are one burst"; "at most attach_window_s from a
    keyframe are attached" (0.25 and 0.5 s: exact in binary)."""
    cfg = KeyframeConfig(burst_gap_s=0.25, min_distance_m=0.3, attach_window_s=0.5,
                         command_delay_s=0.0)
    tu = np.array([0.0, 0.25, 0.5, 1.0])
    burst_of, burst_t, kf_burst, kf_t = _select_keyframes(
        tu, lambda q: np.column_stack([q, 0 * q, 0 * q]), cfg)
    assert burst_of.tolist() == [0, 0, 0, 1] and burst_t.tolist() == [0.0, 1.0]
    # a lone detection half-way between keyframes at 0 and 1 s, 0.5 s from each
    tu = np.array([0.0, 0.5, 1.0])
    rows: dict = {}
    step, ids, _, _ = _attach_detections(
        tu, np.array([0, 1, 2]), tu.copy(), np.array([0, 2]), np.array([0.0, 1.0]), None,
        np.array([1, 2, 3]), np.array([0.1, 0.2, 0.3]), np.ones(3), cfg, rows)
    assert rows["between_keyframes"] == 0 and ids.tolist() == [1, 2, 3]
    assert step.tolist() == [0, 0, 1]   # a tie goes to the earlier keyframe
    # a keyframe's own burst is attached to it whole, even a detection of it nearer in time
    # to the next keyframe (a burst chained over 0.5 s, the next keyframe at 0.75 s)
    tu = np.array([0.0, 0.25, 0.5, 0.75])
    rows = {}
    step, ids, _, _ = _attach_detections(
        tu, np.array([0, 0, 0, 1]), np.array([0.0, 0.75]), np.array([0, 1]),
        np.array([0.0, 0.75]), None, np.array([1, 2, 3, 4]), np.full(4, 0.1), np.ones(4),
        KeyframeConfig(burst_gap_s=0.25, attach_window_s=0.0), rows)
    assert rows["between_keyframes"] == 0 and step.tolist() == [0, 0, 0, 1]


def _rewrite_odometry(folder: Path, dt_s: float = 0.0, w_factor: float = 1.0) -> None:
    """Robot 1's odometry file with its time stamps moved by ``dt_s`` and its turn rates
    multiplied by ``w_factor``."""
    odo = folder / "Robot1_Odometry.dat"
    lines = odo.read_text().split("\n")
    head = [ln for ln in lines if ln.startswith("#")]
    rows = [ln.split("\t") for ln in lines if ln.strip() and not ln.startswith("#")]
    odo.write_text("\n".join(head + [f"{float(a) + dt_s!r}\t{b}\t{float(c) * w_factor!r}"
                                     for a, b, c in rows]) + "\n")


def test_commands_logged_before_they_act_are_moved_later_by_the_delay(tmp_path):
    """Commands logged 0.05 s before the robot obeys them: a delay of +0.05 s gives the true
    motion back (to the rounding of the Unix time stamps), no delay does not."""
    make_mrclam(tmp_path, w=np.where((np.arange(4001) // 150) % 2 == 0, 0.3, -0.2),
                extras=False)
    _rewrite_odometry(tmp_path, dt_s=-0.05)
    late = import_mrclam(tmp_path, 1, keyframe=KeyframeConfig(command_delay_s=0.05,
                                                              attach_window_s=0.0))
    now = import_mrclam(tmp_path, 1, keyframe=KeyframeConfig(**EXACT))
    assert max(late.header.meta["odometry_model"]["rms_error"]) < 1e-6
    assert max(now.header.meta["odometry_model"]["rms_error"]) > 1e-4


def test_the_header_odometry_sigma_is_the_median_of_the_steps(tmp_path):
    make_mrclam(tmp_path, w=np.where((np.arange(4001) // 700) % 2 == 0, 0.15, -0.6))
    s = import_mrclam(tmp_path, 1, keyframe=KeyframeConfig(**EXACT), calibrate=False)
    per_step = np.array([st.odom_sigma for st in s.steps[1:]])
    assert not np.allclose(per_step.mean(axis=0), np.median(per_step, axis=0), rtol=1e-3)
    np.testing.assert_array_equal(s.header.odometry_sigma, np.median(per_step, axis=0))


def test_a_step_sigma_grows_with_the_whole_turn_of_a_spin(tmp_path):
    """Spinning in place at 1 rad/s with both landmarks to one side: a keyframe step spans
    most of a turn (more than pi) while they are out of view. Its turn sigma is
    sqrt(a^2 + (c * turn)^2) with the whole turn w * dt (DEFAULT_ODOMETRY_MODEL), not the
    turn wrapped to (-pi, pi]."""
    make_mrclam(tmp_path, v=0.0, w=1.0, seconds=30.0, extras=False,
                landmarks={6: (3.0, 0.0), 7: (3.0, 0.6)})
    s = import_mrclam(tmp_path, 1, keyframe=KeyframeConfig(**EXACT), calibrate=False,
                      landmark_check=False)
    turn = 1.0 * np.diff([st.time_s for st in s.steps])
    assert turn.max() > math.pi   # the premise: some step turns more than half a circle
    a, _, c = DEFAULT_ODOMETRY_MODEL[2]
    got = np.array([st.odom_sigma[2] for st in s.steps[1:]])
    np.testing.assert_allclose(got, np.sqrt(a ** 2 + (c * turn) ** 2), rtol=1e-6)


def test_the_turn_sigma_is_fitted_on_the_whole_turns(tmp_path):
    """The spin above with turn rates logged 5 % high: each step's turn error is exactly
    0.05 / 1.05 of its odometry turn, so the fitted c of the turn sigma is that, the whole
    turns being the regressors (wrapped ones make the long steps' errors look 4 times too
    big)."""
    make_mrclam(tmp_path, v=0.0, w=1.0, seconds=60.0, extras=False,
                landmarks={6: (3.0, 0.0), 7: (3.0, 0.6)})
    _rewrite_odometry(tmp_path, w_factor=1.05)
    s = import_mrclam(tmp_path, 1, keyframe=KeyframeConfig(**EXACT), landmark_check=False)
    c = s.header.meta["odometry_model"]["abc"][2][2]
    assert c == pytest.approx(0.05 / 1.05, rel=0.02)


def test_the_sigma_model_by_hand():
    """sigma_j = sqrt(a_j^2 + (b_j l)^2 + (c_j |dpsi|)^2), l = |(dx, dy)|: a 3-4-5 step."""
    model = np.array([[0.1, 1.0, 2.0], [0.2, 3.0, 0.0], [0.0, 0.0, 4.0]])
    got = odometry_sigma_model(model, np.array([[0.3, 0.4, -0.5]]))
    np.testing.assert_allclose(got, [[math.sqrt(0.01 + 0.25 + 1.0), math.sqrt(0.04 + 2.25),
                                      2.0]], rtol=1e-12)


def test_the_turn_ratio_is_truth_over_odometry(tmp_path):
    """Turn rates logged 5 % high: the calibration's turn ratio is 1 / 1.05."""
    make_mrclam(tmp_path, extras=False)
    _rewrite_odometry(tmp_path, w_factor=1.05)
    s = import_mrclam(tmp_path, 1, keyframe=KeyframeConfig(**EXACT))
    ratio = s.header.meta["odometry_model"]["turn_ratio_truth_over_odometry"]
    assert ratio == pytest.approx(1 / 1.05, rel=1e-6)


def test_detections_in_a_truth_gap_longer_than_the_limit_are_dropped(tmp_path):
    """Ground truth missing for 0.8 s (> max_truth_gap_s = 0.5, < twice it): every detection
    from the gap's start up to its end is dropped and counted, as many as the measurement
    file has there (counted here from the file)."""
    world = make_mrclam(tmp_path, extras=False)
    t = world["t"]
    gt = tmp_path / "Robot1_Groundtruth.dat"
    lines = gt.read_text().split("\n")
    head = [ln for ln in lines if ln.startswith("#")]
    rows = [ln for ln in lines if ln.strip() and not ln.startswith("#")]
    gt.write_text("\n".join(head + rows[:1001] + rows[1080:]) + "\n")   # t[1000] .. t[1080]
    me = (tmp_path / "Robot1_Measurement.dat").read_text().split("\n")
    times = np.array([float(ln.split()[0]) for ln in me if ln.strip() and not ln.startswith("#")])
    in_gap = int(np.sum((times >= t[1000]) & (times < t[1080])))
    assert in_gap > 0
    s = import_mrclam(tmp_path, 1, keyframe=KeyframeConfig(**EXACT))
    assert s.header.meta["rows"]["in_truth_gap"] == in_gap
