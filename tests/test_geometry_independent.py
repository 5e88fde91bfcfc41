"""Independent checks of the planar geometry kernels (bomgraph/geometry.py).

The existing tests check the SE(2) chain against repeated composition and the grouped ray
intersection against the one-point call; these check the ray intersection against another
formulation of the same least squares, the closed-form eigenvalue and the spread measures
against brute force, the group identities of ``inverse``, and equivariance of the
intersection under rotation and translation of the world.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bomgraph.angles import angle_residual
from bomgraph.geometry import (between, bearings_to, compose, direction_span, intersect_rays,
                               inverse, origin_spread, parallax_eigenvalue, ray_normals)


def _rays_to(point: np.ndarray, origins: np.ndarray) -> np.ndarray:
    d = point - origins
    return np.arctan2(d[:, 1], d[:, 0])


def test_intersect_rays_is_exact_without_noise_and_is_the_perpendicular_least_squares() -> None:
    rng = np.random.default_rng(31)
    exact = noisy = 0
    for _ in range(20):
        target = rng.uniform(-3, 3, 2)
        k = int(rng.integers(2, 9))
        origins = target + rng.uniform(0.5, 2.0, (k, 1)) * np.column_stack(
            [np.cos(a := rng.uniform(-math.pi, math.pi, k)), np.sin(a)])
        x, ok = intersect_rays(origins, _rays_to(target, origins), min_parallax_rad=0.0)
        if not ok:
            continue
        np.testing.assert_allclose(x, target, rtol=0, atol=1e-9)
        exact += 1
        # noisy rays: the answer solves min sum_k (n_k . (x - o_k))^2 with n_k the rays'
        # normals, written as an ordinary least-squares problem (not normal equations)
        dirs = _rays_to(target, origins) + rng.normal(0, 0.05, k)
        x, ok = intersect_rays(origins, dirs, min_parallax_rad=0.0, min_front_fraction=0.0)
        normals = np.column_stack([-np.sin(dirs), np.cos(dirs)])
        ref, *_ = np.linalg.lstsq(normals, (normals * origins).sum(1), rcond=None)
        if ok:
            np.testing.assert_allclose(x, ref, rtol=0, atol=1e-9)
            noisy += 1
    assert exact >= 15 and noisy >= 15


def test_intersect_rays_moves_with_the_world() -> None:
    rng = np.random.default_rng(32)
    origins = rng.uniform(-1, 1, (6, 2))
    dirs = _rays_to(np.array([0.4, 2.0]), origins) + rng.normal(0, 0.03, 6)
    x, ok = intersect_rays(origins, dirs)
    assert ok
    for ang in (0.7, -2.9, math.pi):
        rot = np.array([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]])
        t = np.array([5.0, -7.0])
        y, ok2 = intersect_rays(origins @ rot.T + t, dirs + ang + 2 * math.pi)
        assert ok2
        np.testing.assert_allclose(y, rot @ x + t, rtol=0, atol=1e-9)
    # relabelling the rays changes nothing
    perm = rng.permutation(6)
    np.testing.assert_allclose(intersect_rays(origins[perm], dirs[perm])[0], x, atol=1e-12)


def test_parallax_eigenvalue_is_the_smallest_eigenvalue_and_one_minus_cos_for_two_rays() -> None:
    rng = np.random.default_rng(33)
    m = rng.normal(size=(200, 2, 2))
    sym = m @ m.transpose(0, 2, 1)
    np.testing.assert_allclose(parallax_eigenvalue(sym), np.linalg.eigvalsh(sym)[:, 0],
                               rtol=1e-9, atol=1e-12)
    alpha = rng.uniform(0, math.pi, 50)
    base = rng.uniform(-math.pi, math.pi, 50)
    a = ray_normals(base) + ray_normals(base + alpha)
    np.testing.assert_allclose(parallax_eigenvalue(a), 1 - np.abs(np.cos(alpha)), atol=1e-12)


def _brute_span(angles: np.ndarray) -> float:
    """The smallest arc holding every angle (by trying each angle as the arc's start)."""
    best = math.inf
    for a0 in angles:
        best = min(best, float(np.max(np.mod(angles - a0, 2 * math.pi))))
    return best


def test_direction_span_and_origin_spread_are_the_smallest_arc_by_brute_force() -> None:
    rng = np.random.default_rng(34)
    counts = rng.integers(1, 7, 40)
    owner = np.repeat(np.arange(40), counts)
    centre = rng.uniform(-math.pi, math.pi, 40)
    half = rng.uniform(0.0, 1.4, 40)          # spans below pi: the circular mean is inside
    d = centre[owner] + rng.uniform(-1, 1, owner.size) * half[owner]
    got = direction_span(d + 2 * math.pi * rng.integers(-2, 3, d.size), owner, 40)
    want = [_brute_span(d[owner == i]) for i in range(40)]
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    # origin_spread: the angles of the origins seen from the points
    pts = rng.uniform(-2, 2, (40, 2))
    reach = rng.uniform(0.5, 2, d.size)[:, None]
    origins = pts[owner] + np.column_stack([np.cos(d), np.sin(d)]) * reach
    np.testing.assert_allclose(origin_spread(pts, origins, owner, 40), want, rtol=0, atol=1e-9)


def test_inverse_between_compose_are_a_group() -> None:
    rng = np.random.default_rng(35)
    p = np.column_stack([rng.normal(0, 3, (50, 2)), rng.uniform(-math.pi, math.pi, 50)])
    q = np.column_stack([rng.normal(0, 3, (50, 2)), rng.uniform(-math.pi, math.pi, 50)])
    r = np.column_stack([rng.normal(0, 3, (50, 2)), rng.uniform(-math.pi, math.pi, 50)])
    np.testing.assert_allclose(compose(p, inverse(p)), 0, atol=1e-12)
    np.testing.assert_allclose(compose(inverse(p), p), 0, atol=1e-12)
    np.testing.assert_allclose(between(p, q), compose(inverse(p), q), atol=1e-12)
    lhs, rhs = compose(compose(p, q), r), compose(p, compose(q, r))
    np.testing.assert_allclose(lhs[:, :2], rhs[:, :2], atol=1e-12)
    np.testing.assert_allclose(angle_residual(lhs[:, 2], rhs[:, 2]), 0, atol=1e-12)


def test_bearings_to_a_point_behind_is_plus_pi_and_follows_the_heading_branch() -> None:
    pose = np.array([1.0, 1.0, 0.0])
    assert float(bearings_to(pose, [[0.0, 1.0]])[0]) == math.pi
    for k in (-3, 1, 4):
        shifted = pose + [0.0, 0.0, 2 * math.pi * k]
        pts = np.array([[2.0, 3.0], [-1.0, 0.5], [1.0, -4.0]])
        np.testing.assert_allclose(bearings_to(shifted, pts), bearings_to(pose, pts),
                                   atol=1e-12)


def test_effective_parallax_is_the_smallest_eigenvalue_of_the_mean_ray_normal() -> None:
    """The docstring's identity: ``lambda_min(mean(I - u u^T)) = (1 - |mean exp(2 i a)|) / 2``,
    so ``effective_parallax = arccos(1 - 2 lambda_min)``, checked with eigvalsh."""
    from bomgraph.geometry import effective_parallax

    rng = np.random.default_rng(36)
    counts = rng.integers(2, 9, 30)
    owner = np.repeat(np.arange(30), counts)
    d = rng.uniform(-math.pi, math.pi, owner.size)
    got = effective_parallax(d, owner, 30)
    for i in range(30):
        lam = np.linalg.eigvalsh(ray_normals(d[owner == i]).mean(0))[0]
        assert got[i] == pytest.approx(math.acos(1 - 2 * lam), abs=1e-7)


def test_two_rays_are_accepted_just_above_the_parallax_gate_and_refused_just_below() -> None:
    """``min_parallax_rad`` is the angle between two rays that counts as determined: the
    normal matrix's smallest eigenvalue for two rays at ``alpha`` is ``1 - cos(alpha)``, so
    the gate is ``1 - cos(min_parallax)`` (not ``sin^2``, which asks for ~1.4 times the
    angle). Checked at 0.95 and 1.05 times the gate for several gates, ray lengths and
    orientations."""
    rng = np.random.default_rng(37)
    for gate in (math.radians(1.0), math.radians(2.0), 0.2, 0.5):
        for _ in range(5):
            target = rng.uniform(-3, 3, 2)
            base = rng.uniform(-math.pi, math.pi)
            reach = rng.uniform(1, 10, 2)
            for factor, want in ((1.05, True), (0.95, False)):
                back = np.array([base, base + factor * gate])   # directions from the point
                origins = target + reach[:, None] * np.column_stack([np.cos(back),
                                                                     np.sin(back)])
                x, ok = intersect_rays(origins, _rays_to(target, origins),
                                       min_parallax_rad=gate)
                assert ok == want, (gate, factor)
                if want:
                    np.testing.assert_allclose(x, target, rtol=0, atol=1e-6)
                else:
                    assert np.all(np.isnan(x))


def test_many_rays_from_two_places_do_not_make_parallax() -> None:
    """Twenty-five rays from each of two places 1.5 degrees apart (seen from the point) sum
    to a normal matrix whose smallest eigenvalue ``25 (1 - cos 1.5 deg)`` passes the 2-degree
    eigenvalue test; the angle the origins span seen from the point (1.5 degrees) refuses it.
    Two degrees apart, it is accepted."""
    target = np.array([1.0, 2.0])
    for span_deg, want in ((1.5, False), (2.5, True)):
        back = np.repeat([0.3, 0.3 + math.radians(span_deg)], 25)
        origins = target + 4.0 * np.column_stack([np.cos(back), np.sin(back)])
        dirs = _rays_to(target, origins)
        lam = parallax_eigenvalue(ray_normals(dirs).sum(0))
        assert lam > 1 - math.cos(math.radians(2.0))     # the eigenvalue alone would pass
        x, ok = intersect_rays(origins, dirs, min_parallax_rad=math.radians(2.0))
        assert ok == want
        if want:
            np.testing.assert_allclose(x, target, rtol=0, atol=1e-9)


def test_a_zero_parallax_gate_refuses_one_ray_and_parallel_rays_without_raising() -> None:
    """``min_parallax_rad=0`` (the gate off, as the tests above use it): a point with one ray,
    or with two parallel rays, has a singular normal matrix. It is refused (NaN, False) like
    any undetermined point; before, ``np.linalg.solve`` raised ``LinAlgError('Singular
    matrix')`` for the whole group, so one such point lost every other point's answer."""
    from bomgraph.geometry import intersect_ray_groups

    target = np.array([2.0, 1.0])
    good = np.array([[0.0, 0.0], [4.0, 0.0]])
    origins = np.vstack([good, [[5.0, 5.0]], [[0.0, 3.0], [1.0, 3.0]]])
    dirs = np.concatenate([_rays_to(target, good), [0.3], [0.0, 0.0]])
    owner = np.array([0, 0, 1, 2, 2])
    for gate in (0.0, 1e-12):
        xy, ok = intersect_ray_groups(origins, dirs, owner, 3, min_parallax_rad=gate)
        assert ok.tolist() == [True, False, False]
        np.testing.assert_allclose(xy[0], target, rtol=0, atol=1e-12)
        assert np.all(np.isnan(xy[1:]))
        x, ok1 = intersect_rays(origins[3:], dirs[3:], min_parallax_rad=gate)
        assert not ok1 and np.all(np.isnan(x))
