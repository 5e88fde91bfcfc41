"""The batched consecutive-step path (stmds/batch.py), the merged pair keys of the distance store
and the dense shortest paths: the same numbers as the step-by-step code."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bomgraph.mapper import create_mapper
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream import Prior
from bomgraph.stmds import completion
from bomgraph.stmds.completion import shortest_path_completion
from bomgraph.stmds.distances import DistanceStore


def _stream_with_breaks():
    """A short simulated stream with a restart of the odometry chain, an empty step and a
    step with its own odometry sigmas."""
    stream = simulate(SimConfig(n_steps=90), np.random.default_rng(3))
    steps = list(stream.steps)
    steps[30] = dataclasses.replace(steps[30], odom=None)
    steps[41] = dataclasses.replace(steps[41], landmark_ids=np.zeros(0, np.int64),
                                    bearings_rad=np.zeros(0))
    steps[55] = dataclasses.replace(steps[55], odom_sigma=np.array([0.05, 0.01, 0.07]))
    return stream.header, steps


@pytest.mark.parametrize("cut_every", [1, 7, 1000])
def test_batches_fuse_the_same_bits_as_one_step_at_a_time(cut_every: int) -> None:
    header, steps = _stream_with_breaks()
    batched = create_mapper("stmds-smacof", header)
    single = create_mapper("stmds-smacof", header)
    assert batched._batch is not None
    single._batch = None                       # the step-by-step code
    for s in steps:
        batched.step(s)
        single.step(s)
        if s.t % cut_every == 0:
            batched.flush()
    batched.flush()
    a, b = batched._store, single._store
    assert len(a) == len(b) > 100
    n = len(a)
    for name in ("_a", "_b", "_count", "_sw", "_sx"):
        np.testing.assert_array_equal(getattr(a, name)[:n], getattr(b, name)[:n], err_msg=name)
    assert batched._n_triangulated == single._n_triangulated
    assert batched._n_gated == single._n_gated
    np.testing.assert_array_equal(batched._ids.ids, single._ids.ids)
    np.testing.assert_array_equal(batched._triangulated.array, single._triangulated.array)
    ea, eb = batched.estimate(), single.estimate()
    np.testing.assert_array_equal(ea.landmarks_xy, eb.landmarks_xy)


def _relabelled(header, steps, layout: str, rng):
    """The stream with its landmark ids mapped (``small``: as simulated; ``cache``: past the
    id cache; ``huge``: past 2**31, the dense-index keys) and each step's readings shuffled
    (``shuffled``), with two priors on the mapped ids."""
    ids = np.unique(np.concatenate([s.landmark_ids for s in steps]))
    offset = {"small": 0, "shuffled": 0, "cache": (1 << 20) + 3, "huge": (1 << 40) + 11}[layout]
    new_ids = {int(i): offset + 7 * int(i) for i in ids}
    out = []
    for s in steps:
        lid = np.array([new_ids[int(i)] for i in s.landmark_ids], np.int64)
        brg = s.bearings_rad
        if layout in ("shuffled", "huge") and lid.size:
            order = rng.permutation(lid.size)
            lid, brg = lid[order], brg[order]
        out.append(dataclasses.replace(s, landmark_ids=lid, bearings_rad=brg))
    a, b, c = (new_ids[int(i)] for i in ids[:3])
    header = dataclasses.replace(header, priors=(Prior(a, b, 1.5, 0.1), Prior(c, a, 2.0, 0.2)))
    return header, out


@pytest.mark.parametrize("layout", ["small", "shuffled", "cache", "huge"])
def test_batch_keys_and_id_cache_follow_the_step_by_step_code(layout: str) -> None:
    """Steps not sorted by id, ids past the id cache and past the (step, id) keys: the batch
    gives the step-by-step numbers (pair slots in the same order, the same sums)."""
    header, steps = _relabelled(*_stream_with_breaks(), layout, np.random.default_rng(4))
    batched = create_mapper("stmds-smacof", header)
    single = create_mapper("stmds-smacof", header)
    single._batch = None
    for s in steps:
        batched.step(s)
        single.step(s)
        if s.t % 10 == 0:
            batched.flush()
    batched.flush()
    a, b = batched._store, single._store
    n = len(a)
    assert n == len(b) > 100
    for name in ("_a", "_b", "_count", "_sw", "_sx", "_prior"):
        np.testing.assert_array_equal(getattr(a, name)[:n], getattr(b, name)[:n], err_msg=name)
    np.testing.assert_array_equal(batched._ids.ids, single._ids.ids)
    np.testing.assert_array_equal(batched._triangulated.array, single._triangulated.array)
    cache = batched._batch._id_cache
    assert (cache.size > 0) == (layout in ("small", "shuffled"))


@pytest.mark.parametrize("dense", [True, False])
def test_store_with_repeated_pairs_equals_one_call_per_step(dense: bool) -> None:
    rng = np.random.default_rng(0)
    one, many = DistanceStore("scale-free"), DistanceStore("scale-free")
    if not dense:                                  # the sorted keys from the start
        one._dense_max = many._dense_max = 0
    calls = []
    for _ in range(40):
        a = rng.integers(0, 30, 12)
        b = (a + 1 + rng.integers(0, 29, 12)) % 30
        key = np.minimum(a, b) * 100 + np.maximum(a, b)
        _, first = np.unique(key, return_index=True)      # distinct within one step
        a, b = a[first], b[first]
        calls.append((a, b, rng.uniform(0.1, 4, a.size), rng.uniform(0.01, 1, a.size)))
    for c in calls:
        one.add(*c)
    many.add(*(np.concatenate(x) for x in zip(*calls)))
    n = len(one)
    assert len(many) == n
    for name in ("_a", "_b", "_count", "_sw", "_sx"):
        np.testing.assert_array_equal(getattr(one, name)[:n], getattr(many, name)[:n])
    if dense:
        assert one._table is not None and (one._table >= 0).sum() == n
        return
    keys = one._keys
    assert np.all(np.diff(keys) > 0)                           # sorted, merged
    np.testing.assert_array_equal(np.sort(one._key_slot), np.arange(n))


@pytest.mark.parametrize("dense_max", [64, 200, 100_000])
def test_dense_pair_table_gives_the_slots_of_the_sorted_keys(dense_max: int) -> None:
    """The dense table (growing with the landmark indices, and switching to sorted keys past
    ``dense_max``) numbers the pairs as the sorted keys do: first appearance, repeats and
    pairs of a landmark with itself included; the sums follow the slots."""
    rng = np.random.default_rng(5)
    table, keys = DistanceStore("scale-free"), DistanceStore("scale-free")
    table._dense_max, keys._dense_max = dense_max, 0
    top = 10
    for call in range(60):
        top = min(top + int(rng.integers(0, 12)), 400)     # indices grow past the table
        size = int(rng.integers(0, 40))
        a = rng.integers(0, top, size)
        b = np.where(rng.random(size) < 0.05, a, rng.integers(0, top, size))
        if size and call % 7 == 0:                          # a repeated block of pairs
            a, b = np.concatenate([a, a[:5], b[:3]]), np.concatenate([b, b[:5], a[:3]])
        np.testing.assert_array_equal(table.slots(a, b), keys.slots(a, b))
        d2 = rng.uniform(0.1, 4, a.size)
        var = rng.uniform(0.01, 1, a.size)
        table.add(a, b, d2, var)
        keys.add(a, b, d2, var)
    n = len(keys)
    assert len(table) == n > 1000
    for name in ("_a", "_b", "_count", "_sw", "_sx"):
        np.testing.assert_array_equal(getattr(table, name)[:n], getattr(keys, name)[:n])
    assert (table._table is None) == (dense_max < 400)


def test_degenerate_estimates_are_dropped_and_counted() -> None:
    store = DistanceStore("scale-free")
    store.add(np.array([0, 1, 2]), np.array([1, 2, 3]), np.array([0.0, 1.0, 2.0]),
              np.array([1.0, np.inf, 0.5]))
    known = store.known()
    assert store.n_degenerate == 2
    np.testing.assert_array_equal(known.first, [2])
    assert np.all(np.isfinite(known.distance_m))


@pytest.mark.parametrize("n", [12, 40])
def test_dense_and_sparse_shortest_paths_agree(n: int, monkeypatch) -> None:
    rng = np.random.default_rng(n)
    xy = rng.uniform(0, 3, (n, 2))
    i, j = np.triu_indices(n, 1)
    d = np.hypot(*(xy[i] - xy[j]).T)
    near = d < 1.2
    dense = shortest_path_completion(n, i[near], j[near], d[near])
    monkeypatch.setattr(completion, "DENSE_PATHS_MAX", 0)
    sparse = shortest_path_completion(n, i[near], j[near], d[near])
    np.testing.assert_array_equal(np.isinf(dense), np.isinf(sparse))
    fin = np.isfinite(dense)
    np.testing.assert_allclose(dense[fin], sparse[fin], rtol=1e-13)
    np.testing.assert_array_equal(dense[i[near], j[near]], d[near])
