"""The Victoria Park importer on records written by hand (h102's mutation audit): a step whose
LANDMARK lines come in falling id order, and a point covariance with a correlation. The
excerpt of the other tests lists each step's landmarks in rising order with diagonal
covariances, so bearings left in file order beside sorted ids, or the bearing gradient's
sign, passed them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bomgraph.datasets.victoria import import_victoria

ODO_COV = "0.0001 0 0 0.0001 0 4e-06"
RECORDS = f"""ODOMETRY 100 101 1.0 0 0 {ODO_COV}
LANDMARK 100 5 4 0 0.01 0 0.01
LANDMARK 101 9 1 1 0.02 0.01 0.02
LANDMARK 101 3 0 1 0.01 0 0.01
"""


def test_each_landmark_keeps_its_own_bearing_and_sigma(tmp_path):
    (tmp_path / "v.txt").write_text(RECORDS)
    s = import_victoria(tmp_path / "v.txt")
    assert s.steps[1].landmark_ids.tolist() == [3, 9]
    np.testing.assert_allclose(s.steps[1].bearings_rad, [math.pi / 2, math.pi / 4],
                               rtol=1e-15)
    # a point's bearing sigma: its covariance across the ray, n C n^T with n = [-y, x] / r,
    # over the range: landmark 5 at (4, 0): sqrt(0.01) / 4 = 0.025; 3 at (0, 1): 0.1; 9 at
    # (1, 1): n C n^T = (0.02 - 2 * 0.01 + 0.02) / 2 = 0.01, so 0.1 / sqrt(2): the median
    assert s.header.bearing_sigma_rad == pytest.approx(0.1 / math.sqrt(2), rel=1e-12)
