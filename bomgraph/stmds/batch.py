"""The paper's consecutive-step triangulation (section III-B, eq. 1-2) over many steps at once.

Per step, triangulating the landmarks seen at ``t-1`` and ``t`` and fusing their pairs is about
a hundred small numpy calls on ~10 rays; their fixed cost dominates. :class:`StepBatch` holds
the steps and does the same work for a batch of them in a few calls over all their rays and
pairs: the steps are sorted by landmark id within each step, every ray of step ``s`` is matched
to the same landmark at step ``s-1`` (one ``searchsorted`` on ``(step, landmark)`` keys), the
rays are intersected with one odometry row each (:func:`.triangulation.triangulate_rays`),
gated (:func:`.triangulation.gate_points`), paired within their step (``np.triu_indices``
order, as one step at a time) and fused in step order (:meth:`.distances.DistanceStore.add`).

The numbers are those of one step at a time, bit for bit: the same rays, points and pairs, each
step's pair variances by one matrix-vector product on its own rows, and the fusion sums added
in step order. The result does not depend on where the batches are cut.
"""

from __future__ import annotations

import numpy as np

from .distances import DistanceStore, IdIndex
from .triangulation import gate_points, pair_squared_distances, triangulate_rays

#: Steps held before they are processed (``estimate()`` processes them at once too).
BATCH_STEPS = 64

_SHIFT = np.int64(32)


class StepBatch:
    """Steps waiting for the consecutive-step triangulation, and the last step processed.

    Parameters
    ----------
    store : DistanceStore
        Receives the pairs.
    ids : IdIndex
        Landmark ids to dense indices (assigned in the order the steps saw them).
    bearing_sigma_rad, min_parallax_rad, max_range_m : float
        The bearing noise and the gates of :func:`.triangulation.gate_points`.
    default_sigma : array of shape (3,)
        Odometry std. devs. of steps without their own.
    triangulated : object
        Flags by dense index (``triangulated[idx] = True``) of the landmarks that passed the
        gates.
    """

    def __init__(self, store: DistanceStore, ids: IdIndex, *, bearing_sigma_rad: float,
                 min_parallax_rad: float, max_range_m: float, default_sigma: np.ndarray,
                 triangulated: object) -> None:
        self.store = store
        self.ids = ids
        self.bearing_sigma_rad = float(bearing_sigma_rad)
        self.min_parallax_rad = float(min_parallax_rad)
        self.max_range_m = float(max_range_m)
        self.default_sigma = np.asarray(default_sigma, float).reshape(3)
        self._default_rows = np.broadcast_to(self.default_sigma, (BATCH_STEPS + 1, 3))
        self.pending: list[tuple] = []        # (ids, bearings, odom or None, sigma or None)
        self.last: tuple | None = None        # last step processed: (dense idx, bearings)
        self.n_triangulated = 0
        self.n_gated = 0
        self.triangulated = triangulated
        self._id_cache = np.zeros(0, np.int64)   # dense index by landmark id, -1: unknown

    def __len__(self) -> int:
        return len(self.pending)

    def push(self, landmark_ids: np.ndarray, bearings_rad: np.ndarray,
             odom: np.ndarray | None, odom_sigma: np.ndarray | None) -> None:
        """Hold one step (``odom`` None: the chain restarts here)."""
        self.pending.append((landmark_ids, bearings_rad, odom, odom_sigma))

    def flush(self) -> None:
        """Triangulate and fuse every held step."""
        steps, self.pending = self.pending, []
        if not steps:
            return
        n_steps = len(steps)
        # rows: the last step processed (step 0, sorted by id) and the held steps 1..n
        last_ids, last_brg = self.last if self.last is not None else (_NO_IDS, _NO_BRG)
        sizes = [len(last_ids)] + [len(s[0]) for s in steps]
        total = sum(sizes)
        if total == sizes[0]:                   # nothing seen since the last step processed
            if sizes[-1] == 0:
                self.last = None
            return
        ids = np.concatenate([last_ids] + [s[0] for s in steps]).astype(np.int64, copy=False)
        brg = np.concatenate([last_brg] + [s[1] for s in steps]).astype(float, copy=False)
        sid = np.repeat(_arange(n_steps + 1), sizes)
        top = int(ids.max())                    # ids are non-negative (a Step checks)
        small_ids = top < _ID_LIMIT
        if small_ids:
            # (step, id) keys: increasing when every step is sorted by id (a stream's usual
            # order), else sorted once (stable, as a lexsort on step then id)
            key = (sid << _SHIFT) | ids
            if total > 1 and not (key[1:] > key[:-1]).all():
                order = np.argsort(key, kind="stable")
                key, ids, brg = key[order], ids[order], brg[order]
        else:
            order = np.lexsort((ids, sid))
            ids, brg = ids[order], brg[order]
        idx = self._lookup(ids, top)            # first appearance: step, then id
        self.last = (ids[total - sizes[-1]:], brg[total - sizes[-1]:]) if sizes[-1] else None
        odoms = [s[2] for s in steps]
        start = sizes[0]
        if any(o is None for o in odoms):       # the chain restarts: those steps pair nothing
            chained = np.array([False] + [o is not None for o in odoms])
            odoms = [o if o is not None else _ZERO3 for o in odoms]
            now = chained[sid].nonzero()[0]
        else:
            now = None                          # every ray from ``start`` on
        if now is not None and now.size == 0:
            return
        odom = np.concatenate([_ZERO3] + odoms).reshape(n_steps + 1, 3)
        # the ray of the same landmark one step before (the first, if it repeats)
        if small_ids:
            sorted_key, korder = key, None
        else:
            key = (sid << _SHIFT) | idx
            korder = np.argsort(key, kind="stable")
            sorted_key = key[korder]
        want = (key[start:] if now is None else key[now]) - _STEP
        pos = np.searchsorted(sorted_key, want)
        np.minimum(pos, total - 1, out=pos)
        hit = sorted_key[pos] == want
        if now is None:
            now = hit.nonzero()[0] + start
            pos = pos[hit]
        elif not hit.all():
            now, pos = now[hit], pos[hit]
        if now.size == 0:
            return
        prev = pos if korder is None else korder[pos]
        ray_sid = sid[now]
        tri = triangulate_rays(np.take(odom, ray_sid, axis=0), brg[prev], brg[now])
        ok = gate_points(tri, None, min_parallax_rad=self.min_parallax_rad,
                         max_range_m=self.max_range_m).nonzero()[0]
        self.n_triangulated += ok.size
        self.n_gated += now.size - ok.size
        if ok.size == 0:
            return
        lm = idx[now]
        self.triangulated[lm[ok]] = True  # type: ignore[index]
        # pairs within each step, in np.triu_indices order, step after step
        blocks, counts, rows, offsets = [], [], [], []
        offset = 0
        for s, c in enumerate(np.bincount(ray_sid[ok], minlength=n_steps + 1).tolist()):
            if c > 1:
                blocks.append(_triu2(c))
                counts.append(c * (c - 1) // 2)
                rows.append(s)
                offsets.append(offset)
            offset += c
        if not blocks:
            return
        local = np.concatenate(blocks, axis=1) + np.repeat(offsets, counts)
        pair_idx = ok[local]
        sigma = self._sigmas(steps, rows)
        pairs = pair_squared_distances(tri, sigma, self.bearing_sigma_rad, pairs=pair_idx,
                                       pair_groups=counts)
        lm_pairs = lm[pair_idx]
        self.store.add(lm_pairs[0], lm_pairs[1], pairs.squared_distance_m2, pairs.variance_m4)

    def _lookup(self, ids: np.ndarray, top: int) -> np.ndarray:
        """``self.ids.lookup(ids)`` (``top``: the largest id), answered from a cache by id
        while the ids are small and already known (the ids are only ever added here after
        the priors, and their dense indices never change)."""
        cache = self._id_cache
        if top < len(cache):
            idx = cache[ids]
            if idx.min() >= 0:
                return idx
        idx = self.ids.lookup(ids)
        if top < _ID_CACHE_MAX:
            if top >= len(cache):
                size = max(64, len(cache))
                while size <= top:
                    size *= 2
                cache = self._id_cache = np.full(size, -1, np.int64)
                known = self.ids.ids
                small = known < size
                cache[known[small]] = np.flatnonzero(small)
            else:
                cache[ids] = idx
        return idx

    def _sigmas(self, steps: list[tuple], rows: list[int]) -> np.ndarray:
        """Odometry std. devs. of the steps ``rows`` (1-based into ``steps``), shape (G, 3)."""
        own = [steps[r - 1][3] for r in rows]
        if all(sg is None for sg in own) and len(rows) <= len(self._default_rows):
            return self._default_rows[:len(rows)]
        return np.array([self.default_sigma if sg is None else sg for sg in own], float)


_NO_IDS = np.zeros(0, np.int64)
_NO_BRG = np.zeros(0)
_ZERO3 = np.zeros(3)
_STEP = np.int64(1) << _SHIFT
_ID_LIMIT = 1 << 31
_ID_CACHE_MAX = 1 << 20         # ids below it are cached by id (8 MB at most)
_ARANGE = np.arange(BATCH_STEPS + 1)
_TRIU2: dict[int, np.ndarray] = {}


def _arange(n: int) -> np.ndarray:
    """``np.arange(n)`` (a view of a cached range for batch-sized ``n``)."""
    return _ARANGE[:n] if n <= len(_ARANGE) else np.arange(n)


def _triu2(k: int) -> np.ndarray:
    """``np.triu_indices(k, 1)`` stacked as a ``(2, k (k - 1) / 2)`` array (cached, read-only)."""
    hit = _TRIU2.get(k)
    if hit is None:
        hit = _TRIU2[k] = np.stack(np.triu_indices(k, 1))
        hit.setflags(write=False)
    return hit


__all__ = ["BATCH_STEPS", "StepBatch"]
