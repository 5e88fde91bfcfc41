"""Fusion of the instantaneous pair distances (paper section III-C, eq. 3-5) and the priors.

Every step gives, for each pair of landmarks triangulated at that step, an instantaneous
squared distance ``d2_k`` and its first-order variance ``v_k`` (eq. 2). They are fused per pair
by inverse-variance weighting. Storage grows with the pairs actually observed: a sorted array
of pair keys (``np.searchsorted``) points to slots of growing arrays of per-pair sums (count,
sum of weights, sum of weighted values), and a step's pairs are folded in with a handful of
vectorised operations.

Why the literal rule fails, and the rules offered (``fusion=``). The instantaneous estimates
are very noisy (with the paper's settings one two-view triangulation has a relative depth error
of tens of percent) and their first-order variance grows steeply with the measured value: with
``d`` scaled by a factor ``s`` by an error in the odometry length ``v_k`` grows like ``s^4``
(``var(d) ~ s^2``), and by an error in the parallax like ``s^6`` (``var(d) ~ s^4``). Weighting
by ``1 / v_k`` evaluated at the noisy values therefore favours the estimates that came out
short. Each rule below uses the weight ``w_k = d2_k^m / v_k``, which removes a factor
``s^(2m)`` from that correlation; a rule is "the variance re-evaluated at the fused distance"
under the model ``v_k(d) = v_k (d^2 / d2_k)^m``.

``"paper"`` (m = 0, averages ``d2``)
    Eq. 3-4 literally: ``d2 = sum d2_k / v_k / sum 1 / v_k``, ``var(d2) = 1 / sum 1 / v_k``.
    Collapses: fused distances come out short (``docs/measurements.md``).
``"relative"`` (m = 2, averages ``d``)
    Weights are the inverse *relative* variances ``d2_k / var_k(d)``, invariant to a common
    scale error of the step (the odometry length). Close to unbiased once the triangulation
    baseline is long enough to make the parallax well determined (``baseline_steps=(4,)``).
``"scale-free"`` (m = 3, averages ``1 / d``)
    Weights invariant to the parallax-type scale error as well; averaging ``1 / d`` (linear in
    the parallax) avoids the upward bias of ``1 / sin(parallax)``. The default.

The benchmark (``scripts/bench_stmds.py``) measures them (``docs/measurements.md``). A prior ``(d, s)`` (distance
and std. dev., metres) enters every rule as one more estimate: ``d2 = d^2`` with
``var(d2) = (2 d s)^2 + 2 s^4`` (the exact variance of the square of a Gaussian). A pair counts
as *known* once it has a prior or at least ``min_count`` instantaneous estimates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..errors import ConfigError

# rule -> (exponent m of the weight d2^m / var(d2), the quantity averaged)
_RULES: dict[str, tuple[int, str]] = {
    "paper": (0, "d2"), "relative": (2, "d"), "scale-free": (3, "inv")}
FUSION_RULES = tuple(_RULES)


def estimate_weights(rule: str, squared_distance_m2: np.ndarray,
                     variance_m4: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weights and averaged values of independent estimates under a fusion rule (no state).

    Combine with :func:`fused_from_sums`.
    """
    m, domain = _RULES[rule]
    d2 = np.maximum(squared_distance_m2, _TINY)
    var = np.maximum(variance_m4, _TINY)
    w = d2 ** m / var if m else 1.0 / var
    if domain == "d2":
        return w, d2
    d = np.sqrt(d2)
    return w, (d if domain == "d" else 1.0 / d)


def fused_from_sums(rule: str, sum_w: np.ndarray,
                    sum_wx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fused ``(distance_m, variance_m2)`` from the sums of :func:`estimate_weights`.

    With weights ``w_k = d2_k^m / v_k`` each estimate's variance is modelled as
    ``v_k (d2 / d2_k)^m`` and re-evaluated at the fused ``d2``; the fused variance of the
    squared distance is then ``d2^m / sum w_k`` (eq. 3 when ``m = 0``) and that of the
    distance ``d2^(m-1) / (4 sum w_k)``.
    """
    m, domain = _RULES[rule]
    sw = np.maximum(sum_w, _TINY)
    x = sum_wx / sw
    if domain == "d2":
        d = np.sqrt(np.maximum(x, 0.0))
    elif domain == "d":
        d = np.maximum(x, 0.0)
    else:
        d = 1.0 / np.maximum(x, _TINY)
    d2 = np.maximum(d * d, _TINY)
    return d, d2 ** (m - 1) / (4.0 * sw)


_KEY_SHIFT = np.int64(32)
#: Landmark indices up to which :class:`DistanceStore` finds pair slots in a dense table
#: (at most ``DENSE_MAX ** 2`` int64, 8 MB); beyond, in sorted pair keys.
DENSE_MAX = 1024
_TINY = 1e-300


class IdIndex:
    """Landmark ids (any non-negative int64) to dense indices ``0, 1, 2, ...`` in order of first
    appearance, looked up vectorised (sorted ids + ``np.searchsorted``)."""

    def __init__(self) -> None:
        self._sorted = np.zeros(0, np.int64)
        self._sorted_index = np.zeros(0, np.int64)
        self._ids = np.zeros(0, np.int64)

    def __len__(self) -> int:
        return len(self._ids)

    @property
    def ids(self) -> np.ndarray:
        """The ids by dense index, shape ``(n,)`` (a read-only view)."""
        v = self._ids.view()
        v.setflags(write=False)
        return v

    def lookup(self, ids: np.ndarray, *, add: bool = True) -> np.ndarray:
        """Dense indices of ``ids``; new ids are added (in order of first appearance) when
        ``add``, else reported as -1. Repeated ids are allowed."""
        ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        n = len(self._sorted)
        pos = np.searchsorted(self._sorted, ids)
        pos[pos >= n] = 0
        if n and (self._sorted[pos] == ids).all():
            return self._sorted_index[pos]
        if add and ids.size > 1:
            uniq, first_pos, inverse = np.unique(ids, return_index=True, return_inverse=True)
            if uniq.size < ids.size:
                order = np.argsort(first_pos, kind="stable")
                dense = np.empty(uniq.size, np.int64)
                dense[order] = self.lookup(uniq[order], add=True)
                return dense[inverse]
        n = len(self._sorted)
        pos = np.searchsorted(self._sorted, ids)
        found = pos < n
        found[found] = self._sorted[pos[found]] == ids[found]
        out = np.full(ids.shape, -1, np.int64)
        out[found] = self._sorted_index[pos[found]]
        if add and not found.all():
            new = ids[~found]
            new_index = np.arange(len(self._ids), len(self._ids) + len(new), dtype=np.int64)
            out[~found] = new_index
            self._ids = np.concatenate([self._ids, new])
            keys = np.concatenate([self._sorted, new])
            vals = np.concatenate([self._sorted_index, new_index])
            order = np.argsort(keys, kind="stable")
            self._sorted, self._sorted_index = keys[order], vals[order]
        return out


def prior_squared(distance_m: ArrayLike, sigma_m: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """A distance prior as a squared-distance estimate: ``(d^2, (2 d s)^2 + 2 s^4)``."""
    d = np.asarray(distance_m, dtype=float)
    s = np.asarray(sigma_m, dtype=float)
    return d * d, (2.0 * d * s) ** 2 + 2.0 * s ** 4


@dataclass(frozen=True, eq=False)
class KnownPairs:
    """The fused pairs that count as known, in the order of their slots.

    Attributes
    ----------
    first, second : ndarray of shape (P,), int64
        Dense landmark indices (``first < second``), see :class:`IdIndex`.
    distance_m : ndarray of shape (P,)
        Fused distances (the square root of the fused squared distance, clipped at 0).
    variance_m2 : ndarray of shape (P,)
        First-order variance of the fused distance.
    count : ndarray of shape (P,), int64
        Number of instantaneous estimates fused (priors not counted).
    """

    first: np.ndarray
    second: np.ndarray
    distance_m: np.ndarray
    variance_m2: np.ndarray
    count: np.ndarray

    def __len__(self) -> int:
        return len(self.first)


class DistanceStore:
    """Per-pair inverse-variance fusion (eq. 3-4) in storage that grows with observed pairs.

    Parameters
    ----------
    fusion : str
        One of :data:`FUSION_RULES` (see the module docstring).
    min_count : int
        Instantaneous estimates a pair needs (without a prior) to count as known.
    """

    def __init__(self, fusion: str = "scale-free", min_count: int = 1) -> None:
        if fusion not in FUSION_RULES:
            raise ConfigError(f"unknown fusion rule {fusion!r}; choose one of {FUSION_RULES}")
        if min_count < 1:
            raise ConfigError(f"min_count must be >= 1, got {min_count}")
        self.fusion = fusion
        self.min_count = int(min_count)
        self._keys = np.zeros(0, np.int64)       # sorted pair keys (past the dense table)
        self._key_slot = np.zeros(0, np.int64)   # slot of each sorted key
        # while every landmark index is below DENSE_MAX: slot (or -1) of pair (lo, hi) at
        # lo * cap + hi of a flat (cap * cap) table, cap a power of two
        self._dense_max = DENSE_MAX
        self._cap = 0
        self._table: np.ndarray | None = np.zeros(0, np.int64)
        self._n = 0
        self.n_degenerate = 0   # estimates dropped: zero length, or no finite, positive weight
        cap = 64
        self._a = np.zeros(cap, np.int64)
        self._b = np.zeros(cap, np.int64)
        self._count = np.zeros(cap, np.int64)
        self._prior = np.zeros(cap, bool)
        self._sw = np.zeros(cap)    # sum of weights
        self._sx = np.zeros(cap)    # sum of weight * value (d2 or d, by rule)

    def __len__(self) -> int:
        return self._n

    # ---------------------------------------------------------------------------- storage
    def _grow(self, need: int) -> None:
        cap = len(self._a)
        if need <= cap:
            return
        new_cap = max(need, 2 * cap)
        for name in ("_a", "_b", "_count", "_prior", "_sw", "_sx"):
            old = getattr(self, name)
            arr = np.zeros(new_cap, old.dtype)
            arr[:cap] = old
            setattr(self, name, arr)

    def slots(self, first: np.ndarray, second: np.ndarray) -> np.ndarray:
        """Slots of the pairs ``(first[p], second[p])`` of dense indices, created if new.

        The order inside a pair does not matter; a pair may repeat (one slot). New pairs get
        consecutive slots in the order of their first appearance. While the landmark indices
        stay below :data:`DENSE_MAX` the slots are read from a dense table of pairs (one
        gather); beyond, the new keys are merged into a sorted key array
        (``np.searchsorted``, then one scatter: linear in the pairs stored, not a re-sort of
        them). Both give the same slots.
        """
        lo = np.minimum(first, second)
        hi = np.maximum(first, second)
        if len(hi) == 0:
            return np.zeros(0, np.int64)
        if self._table is not None:
            top = int(hi.max())
            if top >= self._cap:
                self._grow_table(top + 1)
            if self._table is not None:
                return self._dense_slots(lo, hi)
        keys = (lo << _KEY_SHIFT) | hi
        n = len(self._keys)
        if n:
            pos = np.searchsorted(self._keys, keys)
            np.minimum(pos, n - 1, out=pos)
            found = self._keys[pos] == keys
            if found.all():
                return self._key_slot[pos]
            out = np.where(found, self._key_slot[pos], -1)
        else:
            found = np.zeros(len(keys), bool)
            out = np.empty(len(keys), np.int64)
        new = np.flatnonzero(~found)
        new_keys, first_at, inverse = np.unique(keys[new], return_index=True,
                                                return_inverse=True)
        m = len(new_keys)
        # slots by first appearance: rank of each unique new key's first position
        rank = np.empty(m, np.int64)
        rank[np.argsort(first_at, kind="stable")] = np.arange(m)
        new_slots = self._n + rank
        self._grow(self._n + m)
        self._a[new_slots] = lo[new[first_at]]
        self._b[new_slots] = hi[new[first_at]]
        self._n += m
        out[new] = new_slots[inverse]
        # merge: new key k goes to (old keys below it) + (new keys below it)
        dest = np.searchsorted(self._keys, new_keys) + np.arange(m)
        old = np.ones(n + m, bool)
        old[dest] = False
        keys_all = np.empty(n + m, np.int64)
        slots_all = np.empty(n + m, np.int64)
        keys_all[dest], slots_all[dest] = new_keys, new_slots
        keys_all[old], slots_all[old] = self._keys, self._key_slot
        self._keys, self._key_slot = keys_all, slots_all
        return out

    def _grow_table(self, need: int) -> None:
        """A dense table for indices below ``need`` (rebuilt from the slots), or the sorted
        keys once ``need`` passes ``_dense_max``."""
        n = self._n
        a, b = self._a[:n], self._b[:n]
        if need > self._dense_max:
            keys = (a << _KEY_SHIFT) | b
            order = np.argsort(keys, kind="stable")
            self._keys, self._key_slot = keys[order], order.astype(np.int64, copy=False)
            self._table, self._cap = None, 0
            return
        cap = max(64, self._cap)
        while cap < need:
            cap *= 2
        table = np.full(cap * cap, -1, np.int64)
        table[a * cap + b] = np.arange(n)
        self._table, self._cap = table, cap

    def _dense_slots(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """:meth:`slots` from the dense table (``lo <= hi``, both below its size)."""
        table = self._table
        flat = lo * self._cap + hi
        out = table[flat]
        new = (out < 0).nonzero()[0]
        if new.size == 0:
            return out
        new_flat = flat[new]
        # each new pair's first appearance: the least position among its repeats
        order = np.arange(new.size)
        table[new_flat] = new.size
        np.minimum.at(table, new_flat, order)
        first = (table[new_flat] == order).nonzero()[0]
        m = first.size
        new_slots = np.arange(self._n, self._n + m)
        self._grow(self._n + m)
        self._a[new_slots] = lo[new[first]]
        self._b[new_slots] = hi[new[first]]
        self._n += m
        table[new_flat[first]] = new_slots
        out[new] = table[new_flat]
        return out

    # ---------------------------------------------------------------------------- updates
    def add(self, first: np.ndarray, second: np.ndarray, squared_distance_m2: np.ndarray,
            variance_m4: np.ndarray) -> None:
        """Fuse instantaneous estimates: one step's, or several steps' in order.

        A pair may repeat (e.g. the same pair seen at consecutive steps of a batch): its
        estimates are added one after the other in the order given (``np.add.at``), so a
        batch gives the same sums, bit for bit, as one call per step.

        Parameters
        ----------
        first, second : arrays of shape (P,)
            Dense landmark indices of each pair.
        squared_distance_m2, variance_m4 : arrays of shape (P,)
            Instantaneous squared distances and their first-order variances (eq. 2). Estimates
        of zero length or without a finite positive weight are dropped and counted in
        ``n_degenerate``.
        """
        if len(first) == 0:
            return
        d2 = np.asarray(squared_distance_m2, float)
        var = np.asarray(variance_m4, float)
        w, x = estimate_weights(self.fusion, d2, var)
        # an estimate of zero length (two landmarks on one point: parallel rays) or without a
        # finite, positive weight (overflowing variances) carries no distance: dropped, counted
        # (the usual case, all usable, by four reductions: NaN and inf propagate into them, and
        # an overflowing sum only sends the check to the element-wise mask)
        with np.errstate(over="ignore"):
            all_usable = d2.min() > _TINY and w.min() > 0 and math.isfinite(w.sum() + x.sum())
        if not all_usable:
            usable = (d2 > _TINY) & (w > 0) & np.isfinite(w) & np.isfinite(x)
            if not usable.all():
                self.n_degenerate += int(usable.size - usable.sum())
                first, second, w, x = first[usable], second[usable], w[usable], x[usable]
                if len(first) == 0:
                    return
        slot = self.slots(first, second)
        np.add.at(self._sw, slot, w)
        np.add.at(self._sx, slot, w * x)
        np.add.at(self._count, slot, 1)

    def add_priors(self, first: np.ndarray, second: np.ndarray, distance_m: ArrayLike,
                   sigma_m: ArrayLike) -> None:
        """Known distances as initial estimates (eq. 3-4 with a prior, paper Exp. 3).

        Repeated pairs (within or across calls) are fused like any other estimate.
        """
        first = np.asarray(first, np.int64)
        second = np.asarray(second, np.int64)
        d = np.asarray(distance_m, float)
        s = np.asarray(sigma_m, float)
        if np.any(first == second):
            raise ConfigError("a prior must join two different landmarks")
        if np.any(~np.isfinite(d)) or np.any(d <= 0) or np.any(~(s > 0)):
            raise ConfigError("prior distances and sigmas must be finite and > 0")
        d2, var = prior_squared(d, s)
        slot = self.slots(first, second)
        w, x = estimate_weights(self.fusion, d2, var)
        np.add.at(self._sw, slot, w)
        np.add.at(self._sx, slot, w * x)
        self._prior[slot] = True

    # ---------------------------------------------------------------------------- reading
    def fused(self) -> tuple[np.ndarray, np.ndarray]:
        """Fused ``(distance_m, variance_m2)`` of every slot, shape ``(n_pairs,)`` each (see
        :func:`fused_from_sums`)."""
        n = self._n
        return fused_from_sums(self.fusion, self._sw[:n], self._sx[:n])

    def known(self) -> KnownPairs:
        """The pairs with a prior or at least ``min_count`` estimates, fused."""
        n = self._n
        ok = self._prior[:n] | (self._count[:n] >= self.min_count)
        d, v = self.fused()
        if ok.all():                     # every pair known: copies of the slots, in order
            return KnownPairs(self._a[:n].copy(), self._b[:n].copy(), d, v,
                              self._count[:n].copy())
        idx = np.flatnonzero(ok)
        return KnownPairs(self._a[idx], self._b[idx], d[idx], v[idx], self._count[idx])


__all__ = ["FUSION_RULES", "estimate_weights", "fused_from_sums", "IdIndex", "KnownPairs",
           "DistanceStore", "prior_squared"]
