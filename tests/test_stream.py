"""The stream's data classes refuse what a researcher can hand them by mistake from Python:
wrong shapes (never reshaped into a wrong answer), non-integral ids (never rounded), wrong
types (a StreamFormatError naming the key, never a raw TypeError/ValueError/AttributeError)."""

from __future__ import annotations

from typing import Any, Callable

import numpy as np
import pytest

from bomgraph.errors import StreamFormatError
from bomgraph.stream import Prior, Step, Stream, StreamHeader, Truth

H = StreamHeader(0.05, (0.01, 0.0, 0.05))


def test_truth_refuses_points_given_as_columns_instead_of_reshaping_them() -> None:
    xy = np.array([[0.0, 1.0, 2.0, 3.0], [0.0, 0.0, 1.0, 1.0]])  # (2, n): four points as columns
    with pytest.raises(StreamFormatError, match=r"shape \(n, 2\), got \(2, 4\); transpose"):
        Truth([1, 2, 3, 4], xy)
    assert np.array_equal(Truth([1, 2, 3, 4], xy.T).landmarks_xy, xy.T)
    with pytest.raises(StreamFormatError, match=r"poses must have shape \(n, 3\), got \(3, 4\)"):
        Truth([1], [[0.0, 0.0]], poses=np.zeros((3, 4)))
    with pytest.raises(StreamFormatError, match=r"shape \(n, 2\), got \(3,\)"):
        Truth([1], [1.0, 2.0, 3.0])
    assert Truth([], []).landmarks_xy.shape == (0, 2)  # nothing known: still (0, 2)


@pytest.mark.parametrize("make", [
    lambda: Step(0, None, [1.5, 2], [0.1, 0.2]),
    lambda: Step(0, None, [np.nan], [0.1]),
    lambda: Step(0, None, [1e30], [0.1]),
    lambda: Step(0, None, ["a"], [0.1]),
    lambda: Step(0, None, None, [0.1]),
    lambda: Step(0, None, [True], [0.1]),
    lambda: Truth([1.5, 2, 3], np.zeros((3, 2))),
    lambda: Truth([np.nan, 2, 3], np.zeros((3, 2))),
], ids=["step-1.5", "step-nan", "step-1e30", "step-str", "step-none", "step-bool",
        "truth-1.5", "truth-nan"])
def test_ids_are_integers_never_rounded(make: Callable[[], Any]) -> None:
    with pytest.raises(StreamFormatError, match="must be integers"):
        make()


def test_integral_float_and_unsigned_ids_are_taken() -> None:
    assert Step(0, None, np.array([1.0, 2.0]), [0.1, 0.2]).landmark_ids.tolist() == [1, 2]
    assert Step(0, None, np.array([3], np.uint8), [0.1]).landmark_ids.dtype == np.int64
    assert Step(0, None, [], []).landmark_ids.shape == (0,)


@pytest.mark.parametrize("t", [-1, 1.5, "1", None, True])
def test_step_index_must_be_a_non_negative_integer(t: Any) -> None:
    with pytest.raises(StreamFormatError, match="'t': must be the step index"):
        Step(t, [0.1, 0.0, 0.0], [1], [0.1])
    assert Step(np.int64(2), [0.1, 0.0, 0.0], [1], [0.1]).t == 2


@pytest.mark.parametrize("kwargs,key", [
    ({"bearings_rad": ["a"]}, "bearings"), ({"bearings_rad": [1j]}, "bearings"),
    ({"odom": "abc"}, "odom"), ({"time_s": "x"}, "time_s"),
    ({"time_s": np.array([1.0, 2.0])}, "time_s"),
])
def test_step_values_of_the_wrong_type_name_their_key(kwargs: dict, key: str) -> None:
    args = {"t": 1, "odom": [0.1, 0.0, 0.0], "landmark_ids": [1], "bearings_rad": [0.1],
            **kwargs}
    with pytest.raises(StreamFormatError, match=f"'{key}'"):
        Step(**args)


@pytest.mark.parametrize("kwargs,match", [
    ({"bearing_sigma_rad": "0.1"}, "bearing_sigma_rad must be a number"),
    ({"bearing_sigma_rad": None}, "bearing_sigma_rad must be a number"),
    ({"bearing_sigma_rad": True}, "bearing_sigma_rad must be a number"),
    ({"bearing_sigma_rad": np.array([0.1, 0.2])}, "bearing_sigma_rad must be a number"),
    ({"odometry_sigma": 0.1}, "'odometry_sigma': must be 3 finite numbers"),
    ({"odometry_sigma": None}, "'odometry_sigma': must be 3 finite numbers"),
    ({"odometry_sigma": ("a", 0, 0)}, "'odometry_sigma': must be 3 finite numbers"),
    ({"sensor_range_m": "5"}, "sensor_range_m must be a number"),
    ({"priors": ((1, 2, 1.0, 0.1),)}, r"'priors\[0\]': must be a Prior"),
    ({"priors": 5}, r"'priors\[0\]': must be a Prior"),
    ({"priors": (Prior(1.5, 2, 1.0, 0.1),)}, "ids must be integers"),
    ({"priors": (Prior(1, 2, "1", 0.1),)}, r"priors\[0\].distance_m must be a number"),
])
def test_header_values_of_the_wrong_type_are_refused_by_name(kwargs: dict, match: str) -> None:
    args = {"bearing_sigma_rad": 0.05, "odometry_sigma": (0.01, 0.0, 0.05), **kwargs}
    with pytest.raises(StreamFormatError, match=match):
        StreamHeader(**args)


def test_stream_refuses_parts_of_the_wrong_type() -> None:
    steps = (Step(0, None, [1], [0.1]),)
    with pytest.raises(StreamFormatError, match="'header': must be a StreamHeader, got dict"):
        Stream({"bearing_sigma_rad": 0.1}, steps)  # type: ignore[arg-type]
    with pytest.raises(StreamFormatError, match="'truth': must be a Truth or None, got dict"):
        Stream(H, steps, truth={"landmarks": []})  # type: ignore[arg-type]
    with pytest.raises(StreamFormatError, match=r"steps\[0\] is a tuple, not a Step"):
        Stream(H, [(0, None, [1], [0.1])])  # type: ignore[list-item]
    for bad in (None, steps[0]):
        with pytest.raises(StreamFormatError, match="'steps': must be a sequence of Step"):
            Stream(H, bad)  # type: ignore[arg-type]
    assert len(Stream(H, (s for s in steps))) == 1


def test_an_integer_too_large_for_a_float_is_refused_by_name() -> None:
    """``float(10**400)`` raised OverflowError from inside the header's check."""
    with pytest.raises(StreamFormatError, match="bearing_sigma_rad must be a number"):
        StreamHeader(10**400, (0.03, 0.0, 0.05))
    with pytest.raises(StreamFormatError, match="odometry_sigma"):
        StreamHeader(0.05, (10**400, 0.0, 0.05))
