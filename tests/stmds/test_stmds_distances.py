"""BOM-STMDS distance fusion (paper III-C, eq. 3-5) and priors."""

from __future__ import annotations

import numpy as np
import pytest

from bomgraph.errors import ConfigError
from bomgraph.stmds.distances import FUSION_RULES, DistanceStore, IdIndex, prior_squared


def test_id_index_is_vectorised_and_stable() -> None:
    idx = IdIndex()
    np.testing.assert_array_equal(idx.lookup(np.array([40, 7, 10 ** 12])), [0, 1, 2])
    np.testing.assert_array_equal(idx.lookup(np.array([7, 99, 99, 40])), [1, 3, 3, 0])
    np.testing.assert_array_equal(idx.lookup(np.array([5, 7]), add=False), [-1, 1])
    np.testing.assert_array_equal(idx.ids, [40, 7, 10 ** 12, 99])


def test_paper_rule_is_eq_3_and_4() -> None:
    store = DistanceStore("paper")
    est = [(4.0, 0.5), (5.0, 1.0), (3.0, 2.0)]
    for d2, v in est:
        store.add(np.array([0]), np.array([1]), np.array([d2]), np.array([v]))
    # the recursion of eq. 3-4 ...
    fused_d2, fused_v = est[0]
    for d2, v in est[1:]:
        new_v = 1.0 / (1.0 / fused_v + 1.0 / v)
        fused_d2 = new_v * (fused_d2 / fused_v + d2 / v)
        fused_v = new_v
    known = store.known()
    assert known.distance_m[0] == pytest.approx(np.sqrt(fused_d2), rel=1e-14)
    # ... and the reported variance is that of the distance, var(d2) / (4 d2)
    assert known.variance_m2[0] == pytest.approx(fused_v / (4 * fused_d2), rel=1e-14)
    assert known.count[0] == 3


def test_storage_grows_with_observed_pairs_and_ignores_pair_order() -> None:
    store = DistanceStore("relative")
    store.add(np.array([3, 0, 5]), np.array([1, 9, 2]), np.ones(3), np.ones(3))
    store.add(np.array([1, 2]), np.array([3, 7]), np.ones(2), np.ones(2))
    assert len(store) == 4
    k = store.known()
    np.testing.assert_array_equal(np.c_[k.first, k.second], [[1, 3], [0, 9], [2, 5], [2, 7]])
    np.testing.assert_array_equal(k.count, [2, 1, 1, 1])


@pytest.mark.parametrize("rule", FUSION_RULES)
def test_every_rule_returns_the_distance_when_all_estimates_agree(rule: str) -> None:
    store = DistanceStore(rule)
    for v in (0.1, 1.0, 7.0):
        store.add(np.array([0, 1]), np.array([1, 2]), np.array([2.25, 0.04]),
                  np.array([v, 3 * v]))
    np.testing.assert_allclose(store.known().distance_m, [1.5, 0.2], rtol=1e-12)


def test_the_corrected_rule_does_not_favour_short_estimates() -> None:
    # two estimates of a 1 m pair, 0.8 m and 1.25 m, whose variances scale like the
    # triangulation's (var(d2) grows with d2^3 under a common scale error)
    d = np.array([0.8, 1.25])
    var = 0.01 * d ** 6
    paper = DistanceStore("paper")
    fixed = DistanceStore("scale-free")
    for store in (paper, fixed):
        for dk, vk in zip(d, var):
            store.add(np.array([0]), np.array([1]), np.array([dk * dk]), np.array([vk]))
    assert paper.known().distance_m[0] < 0.86            # dominated by the short one
    assert fixed.known().distance_m[0] == pytest.approx(1.0, rel=0.03)


def test_min_count_and_priors_decide_what_is_known() -> None:
    store = DistanceStore("scale-free", min_count=3)
    store.add_priors(np.array([4]), np.array([2]), [1.2], [0.03])
    for _ in range(2):
        store.add(np.array([0, 2]), np.array([1, 4]), np.array([1.0, 1.44]), np.array([0.1, 0.1]))
    k = store.known()
    np.testing.assert_array_equal(np.c_[k.first, k.second], [[2, 4]])
    assert k.distance_m[0] == pytest.approx(1.2)
    assert k.count[0] == 2
    store.add(np.array([0]), np.array([1]), np.array([1.0]), np.array([0.1]))
    assert len(store.known()) == 2


def test_prior_conversion_to_squared_distance() -> None:
    d2, v = prior_squared(2.0, 0.1)
    assert d2 == 4.0
    assert v == pytest.approx((2 * 2.0 * 0.1) ** 2 + 2 * 0.1 ** 4)
    # Monte Carlo: the variance of the square of N(d, s^2)
    x = np.random.default_rng(0).normal(2.0, 0.1, 400_000)
    assert np.var(x * x) == pytest.approx(v, rel=0.01)
    with pytest.raises(ConfigError):
        DistanceStore().add_priors(np.array([1]), np.array([1]), [1.0], [0.1])
    with pytest.raises(ConfigError):
        DistanceStore().add_priors(np.array([1]), np.array([2]), [1.0], [0.0])
    with pytest.raises(ConfigError):
        DistanceStore("median")


def test_repeated_priors_are_fused() -> None:
    store = DistanceStore("paper")
    store.add_priors(np.array([0, 1, 0]), np.array([1, 0, 2]), [1.0, 1.1, 2.0], [0.1, 0.1, 0.1])
    k = store.known()
    assert len(k) == 2
    assert 1.0 < k.distance_m[0] < 1.1
