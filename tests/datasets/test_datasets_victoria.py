"""Victoria Park importer: an excerpt with exact answers, malformed lines, the real file."""

from __future__ import annotations

import math

import numpy as np
import pytest
from dataset_excerpts import DATA, VICTORIA, needs_data

from bomgraph.datasets.victoria import import_victoria
from bomgraph.errors import DatasetError
from bomgraph.stream_file import read_stream, write_stream


def test_victoria_excerpt(tmp_path):
    (tmp_path / "v.txt").write_text(VICTORIA)
    s = import_victoria(tmp_path / "v.txt")
    assert len(s.steps) == 4 and s.truth is None
    assert s.header.meta["n_landmark_records"] == 3
    np.testing.assert_array_equal(s.steps[1].landmark_ids, [2])
    np.testing.assert_array_equal(s.steps[2].landmark_ids, [2, 4])
    np.testing.assert_allclose(s.steps[2].bearings_rad, [math.pi / 4, -math.pi / 2])
    np.testing.assert_allclose(s.steps[2].odom, [0.5, 0.01, -0.2])
    # the file's covariance diag(0.01^2, 0.002^2, 0.002^2) is a GTSAM BetweenFactor's, in the
    # frame of the measured pose j: turned by dtheta into pose i's frame, var_dx = c^2 a^2 +
    # s^2 b^2 and var_dy = s^2 a^2 + c^2 b^2 (dtheta 0.1, -0.2, 0: the medians are at 0.1)
    def turned(th: float) -> tuple[float, float, float]:
        c, sn = math.cos(th), math.sin(th)
        return (math.sqrt(c * c * 1e-4 + sn * sn * 4e-6), math.sqrt(sn * sn * 1e-4 + c * c * 4e-6),
                0.002)

    assert s.header.odometry_sigma == pytest.approx(turned(0.1), rel=1e-12)
    np.testing.assert_allclose(s.steps[2].odom_sigma, turned(-0.2), rtol=1e-12)
    sx, sy, _ = turned(-0.2)
    c, sn = math.cos(-0.2), math.sin(-0.2)
    assert s.header.meta["odometry_max_dropped_correlation"] == pytest.approx(
        abs(c * sn * (1e-4 - 4e-6)) / (sx * sy), rel=1e-12)
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


def test_gtsam_between_factor_error_is_in_the_measured_pose_frame():
    """What the importer assumes of the file's covariance (GTSAM's ``load2D`` makes it a
    ``BetweenFactor<Pose2>``'s noise): the factor's error is in the frame of the measured pose
    j, so moving pose j by ``d`` along pose i's x axis gives the error ``R(dtheta)^T d``."""
    import gtsam

    th, h = 0.5, 1e-6
    measured = gtsam.Pose2(1.0, 0.2, th)
    factor = gtsam.BetweenFactorPose2(0, 1, measured, gtsam.noiseModel.Unit.Create(3))
    values = gtsam.Values()
    values.insert(0, gtsam.Pose2())
    values.insert(1, gtsam.Pose2(1.0 + h, 0.2, th))
    err = factor.unwhitenedError(values)
    np.testing.assert_allclose(err, [math.cos(th) * h, -math.sin(th) * h, 0.0], atol=1e-12)


def test_victoria_weak_rotation_keeps_the_steps_sigmas_and_caps_the_header(tmp_path):
    """ODOMETRY records whose turn variance is 10 (sigma 3.16 rad: 'turn unknown', valid) were
    refused by the importer once 27c0b72 limited the header's turn sigma to pi/sqrt(3) (only
    the g2o importer capped it; h60 noticed): the steps keep their own, the header's is
    capped, and the stream reads back without a warning."""
    from bomgraph.plausibility import MAX_ODOMETRY_SIGMA
    text = VICTORIA.replace(" 4e-06 0 4e-06\n", " 4e-06 0 10\n")
    (tmp_path / "v.txt").write_text(text)
    s = import_victoria(tmp_path / "v.txt")
    assert s.header.odometry_sigma[2] == MAX_ODOMETRY_SIGMA[2]
    assert s.header.meta["odometry_sigma_per_step"] is True
    assert [float(st.odom_sigma[2]) for st in s.steps[1:]] == pytest.approx([math.sqrt(10)] * 3)
    write_stream(s, tmp_path / "v.jsonl")
    back = read_stream(tmp_path / "v.jsonl")
    assert back.header.odometry_sigma[2] == MAX_ODOMETRY_SIGMA[2]
