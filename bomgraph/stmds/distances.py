"""Fusion of the instantaneous pair distances (paper section III-C, eq. 3-5) and the priors.

Every step gives, for each pair of landmarks triangulated at that step, an instantaneous
squared distance ``d2_k`` and its first-order variance ``v_k`` (eq. 2). They are fused per pair
by inverse-variance weighting. Storage grows with the pairs actually observed: a sorted array
of pair keys (``np.searchsorted``) points to slots of growing arrays of per-pair sums, and a
step's pairs are folded in with a handful of vectorised operations.

Fusion rules (``fusion=``):

``"paper"``
    Eq. 3-4 literally: ``w_k = 1 / v_k`` with ``v_k`` evaluated at the noisy measurements,
    ``d2 = sum w_k d2_k / sum w_k``, ``var = 1 / sum w_k``. Because ``v_k ~ 4 d2_k sigma_d^2``
    grows with the measured value, short underestimates get the largest weights and the fused
    distances come out short.
``"squared"``
    Eq. 3-4 with each estimate's variance re-evaluated at the *fused* distance:
    ``v_k(d) = 4 d^2 g_k`` where ``g_k = v_k / (4 d2_k)`` is the first-order variance of the
    distance itself. The common factor ``4 d^2`` cancels from the weighted mean, so the fused
    value is ``sum d2_k / g_k / sum 1 / g_k``, and ``var(d2) = 4 d2 / sum 1 / g_k``.
``"distance"``
    The same weights ``1 / g_k``, averaging the distances ``d_k = sqrt(d2_k)`` instead of the
    squares (the squared norm of a noisy offset is biased up by the offset's variance trace; the
    norm much less).
``"debiased"``
    Like ``"squared"`` with each ``d2_k`` first corrected by its first-order bias
    ``trace Cov(p_i - p_j)``.

A prior ``(d, s)`` (distance and std. dev., metres) enters every rule as one more estimate:
``d2 = d^2`` with ``var(d2) = (2 d s)^2 + 2 s^4`` (the exact variance of the square of a
Gaussian), i.e. ``g = s^2 + s^4 / (2 d^2)``. A pair counts as *known* once it has a prior or at
least ``min_count`` instantaneous estimates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..errors import ConfigError

# rule -> (exponent m of the weight d2^m / var(d2), averaged quantity)
_RULES = {"paper": (0, "d2"), "squared": (1, "d2"), "distance": (1, "d"),
          "m2": (2, "d2"), "m2d": (2, "d"), "m3inv": (3, "inv"), "m3d": (3, "d"),
          "m25inv": (2.5, "inv"), "m25d": (2.5, "d")}
FUSION_RULES = tuple(_RULES)

_KEY_SHIFT = np.int64(32)
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

    def __init__(self, fusion: str = "distance", min_count: int = 1) -> None:
        if fusion not in FUSION_RULES:
            raise ConfigError(f"unknown fusion rule {fusion!r}; choose one of {FUSION_RULES}")
        if min_count < 1:
            raise ConfigError(f"min_count must be >= 1, got {min_count}")
        self.fusion = fusion
        self.min_count = int(min_count)
        self._keys = np.zeros(0, np.int64)       # sorted pair keys
        self._key_slot = np.zeros(0, np.int64)   # slot of each sorted key
        self._n = 0
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

        The pairs must be distinct within one call; the order inside a pair does not matter.
        """
        lo = np.minimum(first, second).astype(np.int64)
        hi = np.maximum(first, second).astype(np.int64)
        keys = (lo << _KEY_SHIFT) | hi
        n = len(self._keys)
        pos = np.searchsorted(self._keys, keys)
        found = pos < n
        found[found] = self._keys[pos[found]] == keys[found]
        out = np.empty(len(keys), np.int64)
        out[found] = self._key_slot[pos[found]]
        if not found.all():
            new = ~found
            m = int(new.sum())
            new_slots = np.arange(self._n, self._n + m, dtype=np.int64)
            self._grow(self._n + m)
            self._a[new_slots] = lo[new]
            self._b[new_slots] = hi[new]
            self._n += m
            out[new] = new_slots
            keys_all = np.concatenate([self._keys, keys[new]])
            slots_all = np.concatenate([self._key_slot, new_slots])
            order = np.argsort(keys_all)
            self._keys, self._key_slot = keys_all[order], slots_all[order]
        return out

    # ---------------------------------------------------------------------------- updates
    def _weights_values(self, d2: np.ndarray, var: np.ndarray,
                        trace: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Per-estimate weights and the value averaged (d2, d or 1/d, by rule)."""
        m, domain = _RULES[self.fusion]
        d2 = np.maximum(d2, _TINY)
        w = d2 ** m / np.maximum(var, _TINY) if m else 1.0 / np.maximum(var, _TINY)
        if domain == "d2":
            return w, d2
        if domain == "d":
            return w, np.sqrt(d2)
        return w, 1.0 / np.sqrt(d2)

    def add(self, first: np.ndarray, second: np.ndarray, squared_distance_m2: np.ndarray,
            variance_m4: np.ndarray, offset_trace_m2: np.ndarray | None = None) -> None:
        """Fuse one step's instantaneous estimates (pairs distinct within the call).

        Parameters
        ----------
        first, second : arrays of shape (P,)
            Dense landmark indices of each pair.
        squared_distance_m2, variance_m4 : arrays of shape (P,)
            Instantaneous squared distances and their first-order variances (eq. 2).
        offset_trace_m2 : array of shape (P,), optional
            ``trace Cov(p_i - p_j)`` (used by ``fusion="debiased"``).
        """
        if len(first) == 0:
            return
        slot = self.slots(first, second)
        w, x = self._weights_values(np.asarray(squared_distance_m2, float),
                                    np.asarray(variance_m4, float), offset_trace_m2)
        self._sw[slot] += w
        self._sx[slot] += w * x
        self._count[slot] += 1

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
        # Fold one at a time per group of distinct pairs (slots() needs distinct pairs).
        lo, hi = np.minimum(first, second), np.maximum(first, second)
        keys = (lo << _KEY_SHIFT) | hi
        _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
        rank = np.zeros(len(keys), np.int64)
        order = np.argsort(inverse, kind="stable")
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        rank[order] = np.arange(len(keys)) - np.repeat(starts, counts)
        for r in range(int(counts.max()) if len(counts) else 0):
            sel = rank == r
            slot = self.slots(lo[sel], hi[sel])
            w, x = self._weights_values(d2[sel], var[sel], np.zeros(int(sel.sum())))
            self._sw[slot] += w
            self._sx[slot] += w * x
            self._prior[slot] = True

    # ---------------------------------------------------------------------------- reading
    def fused(self) -> tuple[np.ndarray, np.ndarray]:
        """Fused ``(distance_m, variance_m2)`` of every slot, shape ``(n_pairs,)`` each."""
        n = self._n
        sw = np.maximum(self._sw[:n], _TINY)
        x = self._sx[:n] / sw
        domain = _RULES[self.fusion][1]
        if domain != "d2":
            d = np.maximum(x, 0.0) if domain == "d" else 1.0 / np.maximum(x, _TINY)
            return d, 1.0 / sw
        d2 = np.maximum(x, 0.0)
        d = np.sqrt(d2)
        if self.fusion == "paper":
            # var(d2) = 1 / sw  ->  var(d) = var(d2) / (4 d2)
            return d, 1.0 / (sw * 4.0 * np.maximum(d2, _TINY))
        return d, 1.0 / sw

    def known(self) -> KnownPairs:
        """The pairs with a prior or at least ``min_count`` estimates, fused."""
        n = self._n
        ok = self._prior[:n] | (self._count[:n] >= self.min_count)
        d, v = self.fused()
        idx = np.flatnonzero(ok)
        return KnownPairs(self._a[idx], self._b[idx], d[idx], v[idx], self._count[idx])


__all__ = ["FUSION_RULES", "IdIndex", "KnownPairs", "DistanceStore", "prior_squared"]
