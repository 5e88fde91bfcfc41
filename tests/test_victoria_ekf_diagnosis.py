"""scripts/victoria_ekf_diagnosis.py: its measures on streams whose answer is known (no data
file needed): the window test of the odometry's heading error, the file reader, the synthetic
streams, and the lean range-bearing EKF (exact on noise-free data; with a heading bias beyond
its declared sigma it gates the bearings that close the loop, as the filters do on Victoria)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bomgraph.geometry import between
from bomgraph.map_estimate import MapEstimate
from bomgraph.stream import Step, Stream, StreamHeader

from _scripts import load_script  # noqa: E402  (tests/_scripts.py)


@pytest.fixture(scope="module")
def diag():
    return load_script("victoria_ekf_diagnosis")


def _circle(n_steps: int, laps: float = 1.0, radius_m: float = 10.0) -> np.ndarray:
    """Poses on a circle, counter-clockwise, ``laps`` times round in ``n_steps`` steps."""
    a = np.linspace(0.0, 2 * math.pi * laps, n_steps)
    return np.column_stack([radius_m * np.sin(a), radius_m * (1 - np.cos(a)), a])


def _steps(poses: np.ndarray, dpsi_error: np.ndarray) -> list[Step]:
    """Steps whose odometry is the true increment minus ``dpsi_error`` on the heading."""
    odom = between(poses[:-1], poses[1:])
    odom[:, 2] -= dpsi_error
    return [Step(t=0, odom=None, landmark_ids=np.zeros(0, np.int64), bearings_rad=np.zeros(0))] + [
        Step(t=t, odom=odom[t - 1], landmark_ids=np.zeros(0, np.int64), bearings_rad=np.zeros(0))
        for t in range(1, len(poses))]


def test_white_heading_error_keeps_the_window_ratio_near_one(diag):
    poses = _circle(3001)
    sigma = 0.002
    e = np.random.default_rng(3).normal(0.0, sigma, 3000)
    out = diag.odometry_heading_windows(_steps(poses, e), poses, sigma, windows=(1, 10, 30))
    np.testing.assert_allclose(out["per_step"], e, atol=1e-12)
    for n, rms, declared in out["windows"]:
        assert declared == pytest.approx(math.sqrt(n) * sigma)
        assert 0.8 < rms / declared < 1.2, n


def test_a_constant_heading_bias_grows_the_ratio_as_sqrt_n(diag):
    poses = _circle(1001)
    bias = 0.001                                  # half the declared sigma, every step
    out = diag.odometry_heading_windows(_steps(poses, np.full(1000, bias)), poses, 0.002,
                                        windows=(1, 100))
    (n1, r1, d1), (n100, r100, d100) = out["windows"]
    assert r1 / d1 == pytest.approx(0.5)
    assert r100 / d100 == pytest.approx(5.0)      # 100 * bias / (10 * sigma)


def test_read_ranges_follows_the_chain_and_keeps_range_and_bearing(diag, tmp_path):
    f = tmp_path / "v.txt"
    f.write_text("ODOMETRY 0 1 1 0 0.1 0.0001 0 0 4e-06 0 4e-06\n"
                 "LANDMARK 1 2 3 4 0.4 0 0.4\n"
                 "ODOMETRY 1 3 2 0 -0.1 0.0001 0 0 4e-06 0 9e-06\n"
                 "LANDMARK 3 2 0 -5 0.4 0 0.4\n", encoding="utf-8")
    motion, sightings = diag.read_ranges(f)
    assert len(motion) == 2 and len(sightings) == 3
    np.testing.assert_allclose(motion[1][0], [2, 0, -0.1])
    assert motion[1][1][2, 2] == 9e-06
    assert sightings[0] == []
    (lid, r, b), = sightings[1]
    assert (lid, r) == (2, 5.0) and b == pytest.approx(math.atan2(4, 3))
    assert sightings[2][0][2] == pytest.approx(-math.pi / 2)


def _loop_world(n_steps: int = 400):
    """Two laps of a 10 m circle with 8 landmarks around it, seen within 8 m."""
    poses = _circle(n_steps, laps=2.0)
    ang = np.linspace(0, 2 * math.pi, 8, endpoint=False)
    lm = np.column_stack([14 * np.sin(ang), 10 - 14 * np.cos(ang)])
    sightings = []
    for p in poses:
        d = lm - p[:2]
        r = np.hypot(d[:, 0], d[:, 1])
        b = np.arctan2(d[:, 1], d[:, 0]) - p[2]
        sightings.append([(i, float(r[i]), float(math.remainder(b[i], 2 * math.pi)))
                          for i in np.flatnonzero(r < 8.0)])
    return poses, lm, sightings


def _motion(poses: np.ndarray, dpsi_error: float, sigma_psi: float):
    odom = between(poses[:-1], poses[1:])
    odom[:, 2] -= dpsi_error
    cov = np.diag([1e-4, 4e-6, sigma_psi ** 2])
    return [(u, cov) for u in odom]


def test_lean_range_bearing_ekf_is_exact_without_noise(diag):
    poses, lm, sightings = _loop_world()
    out = diag.lean_range_bearing_ekf(_motion(poses, 0.0, 0.002), sightings, poses)
    assert out["gated"] == 0 and out["used"] > 100
    assert np.abs(out["herr"]).max() < 1e-9
    for i, xy in out["map"].items():
        np.testing.assert_allclose(xy, lm[i], atol=1e-8)


def test_lean_ekf_gates_the_loop_closure_when_the_heading_bias_beats_its_sigma(diag):
    """A heading bias of 0.004 rad per step (twice the declared sigma, 0.32 rad over the 80
    steps between two sightings of a landmark): the filter's heading is many of its standard
    deviations off when the loop closes, it gates, and its heading follows dead reckoning. Declared to cover the drift (sigma x10)
    the same data are used."""
    poses, _, sightings = _loop_world()
    tight = diag.lean_range_bearing_ekf(_motion(poses, 0.004, 0.002), sightings, poses)
    wide = diag.lean_range_bearing_ekf(_motion(poses, 0.004, 0.02), sightings, poses)
    dead_reckoned = np.cumsum(np.full(len(poses) - 1, 0.004))
    assert tight["gated"] > 50
    assert abs(tight["herr"][-1] + dead_reckoned[-1]) < 0.2      # it follows dead reckoning
    assert wide["gated"] == 0
    assert abs(wide["herr"][-1]) < 0.05


def test_victoria_like_streams(diag):
    poses = np.array([[0, 0, 0], [1, 0, 0.1], [2, 0.2, 0.2]], float)
    ref = MapEstimate(np.array([4, 7]), np.array([[5.0, 5.0], [6.0, -3.0]]),
                      pose_t=np.arange(3), poses=poses)
    header = StreamHeader(bearing_sigma_rad=0.05, odometry_sigma=(0.01, 0.002, 0.002))
    file_odom = [None, np.array([1.0, 0.0, 0.2]), np.array([1.0, 0.1, 0.0])]
    steps = tuple(Step(t=t, odom=file_odom[t], landmark_ids=np.array([4, 9]),
                       bearings_rad=np.array([0.3, -0.2])) for t in range(3))
    stream = Stream(header, steps, None)
    b = diag.victoria_like(stream, ref, "B", np.random.default_rng(0))
    c = diag.victoria_like(stream, ref, "C", np.random.default_rng(0))
    for t in (1, 2):
        np.testing.assert_array_equal(b.steps[t].odom, file_odom[t])      # the file's
        assert np.all(np.abs(c.steps[t].odom - between(poses[t - 1], poses[t]))
                      < 5 * np.array(header.odometry_sigma))              # white, declared
        np.testing.assert_array_equal(c.steps[t].bearings_rad, steps[t].bearings_rad)
    assert all(st.landmark_ids.tolist() == [4] for st in b.steps)         # ref's landmarks
    z = b.steps[2].bearings_rad[0]
    assert abs(math.remainder(z - (math.atan2(5 - 0.2, 5 - 2) - 0.2), 2 * math.pi)) < 0.25
