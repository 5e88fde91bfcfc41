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
