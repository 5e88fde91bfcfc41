"""Angle wrapping and planar pose algebra."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bomgraph.angles import angle_residual, wrap_angle
from bomgraph.geometry import (between, bearings_to, compose, dead_reckon, to_local, to_world)


def test_wrap_textbook_values() -> None:
    assert wrap_angle(np.pi) == pytest.approx(np.pi)
    assert wrap_angle(-np.pi) == pytest.approx(np.pi)
    assert wrap_angle(3 * np.pi / 2) == pytest.approx(-np.pi / 2)
    assert wrap_angle(0.0) == 0.0
    np.testing.assert_allclose(wrap_angle([7.0, -7.0]), [7.0 - 2 * np.pi, -7.0 + 2 * np.pi])


@settings(max_examples=200, deadline=None)
@given(a=st.floats(-1e4, 1e4), b=st.floats(-1e4, 1e4))
def test_residual_is_the_shortest_turn(a: float, b: float) -> None:
    r = float(angle_residual(a, b))
    assert -np.pi < r <= np.pi
    # a - b - r is a multiple of 2 pi
    k = (a - b - r) / (2 * np.pi)
    assert abs(k - round(k)) < 1e-6


def test_residual_across_pi() -> None:
    assert angle_residual(np.pi - 0.01, -np.pi + 0.01) == pytest.approx(-0.02)
    assert angle_residual(-np.pi + 0.01, np.pi - 0.01) == pytest.approx(0.02)


def test_dead_reckon_equals_repeated_compose_and_between_inverts() -> None:
    rng = np.random.default_rng(1)
    u = np.column_stack([rng.uniform(0, 0.3, 50), rng.normal(0, 0.05, 50),
                         rng.uniform(-1, 1, 50)])
    poses = dead_reckon(u, (0.3, -1.0, 2.9))
    p = np.array([0.3, -1.0, 2.9])
    for k in range(50):
        p = compose(p, u[k])
        np.testing.assert_allclose(poses[k + 1], p, atol=1e-12)
    np.testing.assert_allclose(between(poses[:-1], poses[1:]), u, atol=1e-12)


def test_frames_and_bearings() -> None:
    pose = np.array([1.0, 2.0, 0.7])
    pts = np.array([[2.0, 2.0], [1.0, 3.0], [-1.0, 0.5]])
    np.testing.assert_allclose(to_world(pose, to_local(pose, pts)), pts, atol=1e-12)
    local = to_local(pose, pts)
    np.testing.assert_allclose(bearings_to(pose, pts), np.arctan2(local[:, 1], local[:, 0]))
