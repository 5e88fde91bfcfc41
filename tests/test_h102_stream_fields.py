"""Every field of the stream file survives a write and a read with its own value (h102's
mutation audit: the round-trip tests used simulated streams, which have no ``odom_sigma``,
no ``time_s``, sorted landmark ids and a bearing sigma equal to the odometry turn sigma, so
a writer that dropped the first two, paired sorted ids with unsorted bearings, or a reader
that took the bearing sigma from the odometry's passed them all)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from bomgraph.stream import Prior, Step, Stream, StreamHeader, Truth
from bomgraph.stream_file import count_steps, read_stream, write_stream

#: every value distinct, so a field read from another's place shows
HEADER = StreamHeader(bearing_sigma_rad=0.0137, odometry_sigma=(0.021, 0.004, 0.033),
                      sensor_range_m=4.5, priors=(Prior(7, 2, 1.25, 0.05),),
                      meta={"source": "hand-made", "n": 3})
STEPS = (
    Step(0, None, np.array([7, 2]), np.array([0.5, -1.25]), time_s=100.125),
    Step(1, np.array([0.3, 0.01, 0.2]), np.array([2]), np.array([2.75]),
         odom_sigma=np.array([0.031, 0.006, 0.044]), time_s=100.625),
    Step(2, np.array([0.25, -0.02, -0.1]), np.array([9, 7, 2]), np.array([-3.0, 0.125, 1.5]),
         time_s=101.375),
)
TRUTH = Truth(np.array([2, 7, 9]), np.array([[1.0, 2.0], [3.0, -1.0], [-2.0, 0.5]]),
              np.array([[0.0, 0.0, 0.0], [0.3, 0.01, 0.2], [0.55, 0.05, 0.1]]))


def _written(tmp_path: Path) -> tuple[Path, list[dict]]:
    path = tmp_path / "s.jsonl"
    write_stream(Stream(HEADER, STEPS, TRUTH), path)
    return path, [json.loads(line) for line in path.read_text().splitlines()]


def test_the_lines_hold_each_field_as_the_format_spells_it(tmp_path: Path) -> None:
    """The file read as plain JSON (not by bomgraph's reader) against the values given."""
    _, lines = _written(tmp_path)
    head = lines[0]
    assert head["bearing_sigma_rad"] == 0.0137
    assert head["odometry_sigma"] == [0.021, 0.004, 0.033]
    assert head["sensor_range_m"] == 4.5
    assert head["priors"] == [{"i": 7, "j": 2, "distance_m": 1.25, "sigma_m": 0.05}]
    assert head["meta"] == {"source": "hand-made", "n": 3}
    assert head["truth"]["landmarks"] == [[2, 1.0, 2.0], [7, 3.0, -1.0], [9, -2.0, 0.5]]
    assert head["truth"]["poses"][2] == [0.55, 0.05, 0.1]
    assert len(lines) == 1 + len(STEPS)
    assert lines[1] == {"t": 0, "bearings": [[7, 0.5], [2, -1.25]], "time_s": 100.125}
    assert lines[2] == {"t": 1, "odom": [0.3, 0.01, 0.2], "odom_sigma": [0.031, 0.006, 0.044],
                        "bearings": [[2, 2.75]], "time_s": 100.625}
    # each id stays with its own bearing, in the step's order (not sorted apart)
    assert lines[3]["bearings"] == [[9, -3.0], [7, 0.125], [2, 1.5]]
    assert "odom_sigma" not in lines[3] and lines[3]["time_s"] == 101.375


def test_a_read_gives_back_each_field(tmp_path: Path) -> None:
    path, _ = _written(tmp_path)
    s = read_stream(path)
    assert s == Stream(HEADER, STEPS, TRUTH)
    assert s.header.bearing_sigma_rad == 0.0137
    assert s.header.odometry_sigma == (0.021, 0.004, 0.033)
    assert [st.time_s for st in s.steps] == [100.125, 100.625, 101.375]
    assert s.steps[0].odom_sigma is None and s.steps[2].odom_sigma is None
    np.testing.assert_array_equal(s.steps[1].odom_sigma, [0.031, 0.006, 0.044])
    assert dict(zip(s.steps[2].landmark_ids.tolist(), s.steps[2].bearings_rad.tolist())) \
        == {9: -3.0, 7: 0.125, 2: 1.5}


def test_a_step_sigma_override_wins_over_the_header(tmp_path: Path) -> None:
    path, _ = _written(tmp_path)
    s = read_stream(path)
    np.testing.assert_array_equal(s.steps[1].odometry_sigma(s.header), [0.031, 0.006, 0.044])
    np.testing.assert_array_equal(s.steps[2].odometry_sigma(s.header), [0.021, 0.004, 0.033])


def test_landmark_ids_are_each_observed_id_once_sorted() -> None:
    assert Stream(HEADER, STEPS, TRUTH).landmark_ids().tolist() == [2, 7, 9]


def test_count_steps_counts_the_step_lines(tmp_path: Path) -> None:
    path, _ = _written(tmp_path)
    assert count_steps(path) == 3
