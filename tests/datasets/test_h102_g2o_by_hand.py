"""The g2o importer on a file written by hand (h102's mutation audit): a chain whose pose ids
do not increase along it, correlated odometry information, bearing edges of different
information and a bomgraph header's time stamps. The simulated files of the other tests
have increasing pose ids, diagonal information and one bearing weight, so truth poses taken
in id order, bearings put on the step of their id's rank, the information's I23 read as I13,
a mean bearing sigma, or time stamps one step late passed them. Expected values are worked
out by hand below."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bomgraph.datasets.g2o import import_g2o

#: the odometry error covariance of every edge, in the frame of the measurement
SIGMA_E = np.array([[0.04, 0.01, 0.002], [0.01, 0.09, -0.003], [0.002, -0.003, 0.01]])
#: truth: the chain 30 -> 10 -> 20 (ids not increasing along it); the first step turns a
#: quarter to the left, the second goes straight on
POSES = {30: (0.0, 0.0, 0.0), 10: (1.0, 0.0, math.pi / 2), 20: (1.0, 0.5, math.pi / 2)}
ODOMS = [(30, 10, (1.0, 0.0, math.pi / 2)), (10, 20, (0.5, 0.0, 0.0))]
LANDMARKS = {1: (3.0, 3.0), 2: (-1.0, 4.0)}
#: (pose, landmark, information w)
BEARINGS = [(30, 1, 100.0), (10, 2, 400.0), (20, 1, 400.0), (20, 2, 10000.0)]


def _bearing(pose: int, lid: int) -> float:
    x, y, psi = POSES[pose]
    lx, ly = LANDMARKS[lid]
    return math.atan2(ly - y, lx - x) - psi


def _write(path: Path, *, scale_second: float = 1.0, odoms: list = ODOMS) -> Path:
    lines = ['# bomgraph header: {"sensor_range_m": null, "time_s": [10.0, 10.5, 11.25]}']
    lines += [f"VERTEX_SE2 {v} {x!r} {y!r} {p!r}" for v, (x, y, p) in POSES.items()]
    lines += [f"VERTEX_XY {i} {x!r} {y!r}" for i, (x, y) in LANDMARKS.items()]
    for k, (i, j, (dx, dy, dth)) in enumerate(odoms):
        omega = np.linalg.inv(SIGMA_E) * (scale_second if k == 1 else 1.0)
        upper = [omega[0, 0], omega[0, 1], omega[0, 2], omega[1, 1], omega[1, 2], omega[2, 2]]
        lines.append(f"EDGE_SE2 {i} {j} {dx!r} {dy!r} {dth!r} "
                     + " ".join(repr(float(v)) for v in upper))
    lines += [f"EDGE_BEARING_SE2_XY {i} {lid} {_bearing(i, lid)!r} {w!r}"
              for i, lid, w in BEARINGS]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_steps_follow_the_chain_not_the_pose_ids(tmp_path):
    path = _write(tmp_path / "h.g2o")
    s = import_g2o(path, truth_path=path)
    assert s.header.meta["pose_ids"] == [30, 10, 20]
    np.testing.assert_array_equal(s.truth.poses, [POSES[30], POSES[10], POSES[20]])
    assert [st.landmark_ids.tolist() for st in s.steps] == [[1], [2], [1, 2]]
    assert s.steps[1].bearings_rad.tolist() == [_bearing(10, 2)]
    assert [st.time_s for st in s.steps] == [10.0, 10.5, 11.25]
    # the bearings are exact, so they fit the truth exactly
    assert s.header.meta["truth_check"]["bearing"]["max_abs_rad"] < 1e-12


def test_correlated_information_gives_the_rotated_marginal_sigmas(tmp_path):
    """The edge's error is in the measurement's frame: turned by dth = pi / 2 into the frame
    of pose i, its x and y sigmas swap: (0.3, 0.2, 0.1); the straight step keeps
    (0.2, 0.3, 0.1) (the square roots of SIGMA_E's diagonal)."""
    s = import_g2o(_write(tmp_path / "h.g2o"))
    assert s.header.meta["odometry_sigma_per_step"]
    np.testing.assert_allclose(s.steps[1].odom_sigma, [0.3, 0.2, 0.1], rtol=1e-9)
    np.testing.assert_allclose(s.steps[2].odom_sigma, [0.2, 0.3, 0.1], rtol=1e-9)


def test_the_bearing_sigma_is_the_median_of_the_edges(tmp_path):
    """1 / sqrt(w) of the four edges: 0.1, 0.05, 0.05, 0.01; the median is 0.05 (the mean
    0.0525)."""
    s = import_g2o(_write(tmp_path / "h.g2o"))
    assert s.header.bearing_sigma_rad == pytest.approx(0.05, rel=1e-12)


def test_sigmas_half_a_per_cent_apart_are_kept_per_step(tmp_path):
    """Two straight steps whose information differs by 0.5 %: not one header sigma."""
    straight = [(30, 10, (1.0, 0.0, 0.0)), (10, 20, (0.5, 0.0, 0.0))]
    s = import_g2o(_write(tmp_path / "h.g2o", scale_second=1.005, odoms=straight))
    assert s.header.meta["odometry_sigma_per_step"]
    np.testing.assert_allclose(s.steps[2].odom_sigma / s.steps[1].odom_sigma, 1.005 ** -0.5,
                               rtol=1e-9)
