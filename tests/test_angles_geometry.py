"""Angle wrapping and planar pose algebra."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bomgraph.angles import angle_residual, wrap_angle
from bomgraph.geometry import (arc_root, between, bearings_to, compose, dead_reckon,
                               intersect_ray_groups, intersect_rays, ray_normals, to_local,
                               to_world)


def test_wrap_textbook_values() -> None:
    assert wrap_angle(np.pi) == pytest.approx(np.pi)
    assert wrap_angle(-np.pi) == pytest.approx(np.pi)
    assert wrap_angle(3 * np.pi / 2) == pytest.approx(-np.pi / 2)
    assert wrap_angle(0.0) == 0.0
    np.testing.assert_allclose(wrap_angle([7.0, -7.0]), [7.0 - 2 * np.pi, -7.0 + 2 * np.pi])



def test_wrap_of_one_float_is_the_array_path_bit_for_bit() -> None:
    """Python floats and numpy float64 scalars take the scalar path (math, no arrays); it gives
    the same bits as the array path, at the edges of the interval too."""
    rng = np.random.default_rng(1)
    a = np.concatenate([rng.uniform(-50, 50, 2000),
                        [np.pi, -np.pi, 3 * np.pi, -3 * np.pi, 0.0, -0.0, 1e-300,
                         np.nextafter(np.pi, 4), np.nextafter(-np.pi, -4)]])
    whole = wrap_angle(a)
    for one in (np.float64, float):
        got = np.array([wrap_angle(one(x)) for x in a])
        assert got.tobytes() == whole.tobytes()
    assert type(wrap_angle(np.float64(1.0))) is np.float64


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


def test_arc_root_composed_k_times_is_the_increment() -> None:
    rng = np.random.default_rng(3)
    for u in np.column_stack([rng.normal(0, 2, (40, 2)), rng.uniform(-3.1, 3.1, 40)]):
        for k in (1, 2, 7, 30):
            v = arc_root(u, k)
            p = np.zeros(3)
            for _ in range(k):
                p = compose(p, v)
            np.testing.assert_allclose(p[:2], u[:2], atol=1e-9)
            assert abs(float(angle_residual(p[2], u[2]))) < 1e-12
            assert abs(v[2] - u[2] / k) < 1e-12           # equal turns along the arc
    np.testing.assert_allclose(arc_root([1.0, 0.0, 0.0], 4), [0.25, 0.0, 0.0])
    # a quarter circle of radius 1 in two halves: each an eighth
    half = arc_root([1.0, 1.0, np.pi / 2], 2)
    np.testing.assert_allclose(half, [np.sin(np.pi / 4), 1 - np.cos(np.pi / 4), np.pi / 4],
                               atol=1e-12)


def test_ray_groups_are_intersect_rays_point_by_point_bit_for_bit() -> None:
    """One grouped call gives each point exactly what :func:`intersect_rays` gives it alone
    (the refusals too: one ray, parallel rays, a point behind a ray), so batching the
    admission of landmarks changes no map."""
    rng = np.random.default_rng(5)
    target = rng.uniform(-3, 3, (40, 2))
    counts = rng.integers(1, 12, 40)
    owner = np.repeat(np.arange(40), counts)
    origins = target[owner] + rng.normal(0, 1.5, (len(owner), 2))
    d = target[owner] - origins
    dirs = np.arctan2(d[:, 1], d[:, 0]) + rng.normal(0, 0.02, len(owner))
    dirs[owner == 3] = dirs[owner == 3][0]                      # parallel rays
    dirs[np.flatnonzero(owner == 5)[0]] += np.pi                # one ray pointing away
    xy, ok = intersect_ray_groups(origins, dirs, owner, 40, min_parallax_rad=0.05)
    refused = 0
    for i in range(40):
        one, good = intersect_rays(origins[owner == i], dirs[owner == i], min_parallax_rad=0.05)
        assert good == ok[i]
        assert np.array_equal(one, xy[i], equal_nan=True)
        refused += not good
        if good:  # the normal equations summed as a single point's were before the groups
            n = ray_normals(dirs[owner == i])
            a, b = n.sum(0), np.einsum("kij,kj->i", n, origins[owner == i])
            assert np.array_equal(np.linalg.solve(a[None], b[None, :, None])[0, :, 0], xy[i])
    assert ok[counts > 1].sum() > 25 and refused >= 3 and not ok[3] and not ok[5]


def test_wrap_leaves_an_angle_in_range_exactly_as_it_is() -> None:
    """(-pi, pi] is the range: an angle in it comes back bit for bit, as an array, one float
    and through a residual of zero length turn (``pi - mod(pi - a, 2 pi)`` moved 0.31 to
    0.31000000000000005, and a fifth of uniform angles by an ulp)."""
    rng = np.random.default_rng(7)
    a = np.concatenate([rng.uniform(-np.pi, np.pi, 20_000), [0.31, np.pi, np.nextafter(-np.pi, 0),
                                                             1e-300, -0.0, 3.0]])
    assert np.array_equal(wrap_angle(a), a)
    assert all(wrap_angle(float(x)) == x for x in a[-6:])
    assert wrap_angle(0.31) == 0.31
    assert np.array_equal(angle_residual(a, 0.0), a)
    # outside the range it still wraps, to (-pi, pi]
    out = np.concatenate([a + 2 * np.pi, a - 4 * np.pi, [-np.pi, 7.0]])
    w = wrap_angle(out)
    assert np.all((w > -np.pi) & (w <= np.pi))
    np.testing.assert_allclose(np.cos(w), np.cos(out), atol=1e-12)
    np.testing.assert_allclose(np.sin(w), np.sin(out), atol=1e-12)


def test_wrap_of_an_array_in_range_is_a_copy_not_the_input() -> None:
    """The shortcut for an array wholly in (-pi, pi] returns a new array (writing to the
    result leaves the input alone), a scalar for a 0-d input, and a mixed array still wraps
    only its angles out of range."""
    a = np.array([0.31, -1.0, np.pi])
    w = wrap_angle(a)
    assert w is not a and np.array_equal(w, a)
    w[0] = 9.0
    assert a[0] == 0.31
    assert type(wrap_angle(np.array(0.31))) is np.float64 and wrap_angle(np.array(0.31)) == 0.31
    assert wrap_angle(np.zeros(0)).shape == (0,)
    mixed = wrap_angle(np.array([0.31, -np.pi, np.nan, 4.0]))
    assert mixed[0] == 0.31 and mixed[1] == np.pi and np.isnan(mixed[2])
    assert mixed[3] == 4.0 - 2 * np.pi
