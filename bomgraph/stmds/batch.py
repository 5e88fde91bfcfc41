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


def _pairs_within_groups(group: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """All pairs ``i < j`` of items in the same group (``group`` non-decreasing), ordered by
    group, then ``i``, then ``j`` (``np.triu_indices`` order inside each group)."""
    k = group.size
    if k < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    pos = np.arange(k)
    new = np.empty(k, bool)
    new[0] = True
    np.not_equal(group[1:], group[:-1], out=new[1:])
    end = np.append(np.flatnonzero(new)[1:], k)
    count = end[np.cumsum(new) - 1] - pos - 1          # items after each one in its group
    first = np.repeat(pos, count)
    offset = np.arange(first.size) - np.repeat(np.cumsum(count) - count, count)
    return first, first + 1 + offset


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
        self.pending: list[tuple] = []        # (ids, bearings, odom or None, sigma or None)
        self.last: tuple | None = None        # last step processed: (dense idx, bearings)
        self.n_triangulated = 0
        self.n_gated = 0
        self.triangulated = triangulated

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
        sizes = np.array([len(s[0]) for s in steps], np.int64)
        sid = np.repeat(np.arange(1, n_steps + 1), sizes)    # step 0: the last one processed
        ids = np.concatenate([s[0] for s in steps]).astype(np.int64, copy=False)
        brg = np.concatenate([s[1] for s in steps]).astype(float, copy=False)
        order = np.lexsort((ids, sid))
        ids, brg = ids[order], brg[order]
        idx = self.ids.lookup(ids)                             # first appearance: step, then id
        odom = np.zeros((n_steps + 1, 3))
        sigma = np.empty((n_steps + 1, 3))
        chained = np.zeros(n_steps + 1, bool)
        for s, (_, _, o, sg) in enumerate(steps, start=1):
            if o is not None:
                chained[s] = True
                odom[s] = o
                sigma[s] = self.default_sigma if sg is None else sg
        last_idx, last_brg = self.last if self.last is not None else (
            np.zeros(0, np.int64), np.zeros(0))
        end = n_steps
        self.last = (idx[sid == end], brg[sid == end]) if sizes[-1] else (
            np.zeros(0, np.int64), np.zeros(0))
        all_sid = np.concatenate([np.zeros(len(last_idx), np.int64), sid])
        all_idx = np.concatenate([last_idx, idx])
        all_brg = np.concatenate([last_brg, brg])
        key = (all_sid << _SHIFT) | all_idx
        korder = np.argsort(key, kind="stable")
        sorted_key = key[korder]
        # the rays of chained steps and the same landmark one step before
        now = np.flatnonzero(chained[all_sid])
        if now.size == 0 or sorted_key.size == 0:
            return
        want = ((all_sid[now] - 1) << _SHIFT) | all_idx[now]
        pos = np.minimum(np.searchsorted(sorted_key, want), sorted_key.size - 1)
        hit = sorted_key[pos] == want
        now, prev = now[hit], korder[pos[hit]]
        if now.size == 0:
            return
        ray_sid = all_sid[now]
        tri = triangulate_rays(odom[ray_sid], all_brg[prev], all_brg[now])
        ok = np.flatnonzero(gate_points(tri, None, min_parallax_rad=self.min_parallax_rad,
                                        max_range_m=self.max_range_m))
        self.n_triangulated += ok.size
        self.n_gated += now.size - ok.size
        if ok.size == 0:
            return
        lm = all_idx[now]
        self.triangulated[lm[ok]] = True  # type: ignore[index]
        f, g = _pairs_within_groups(ray_sid[ok])
        if f.size == 0:
            return
        pair_sid = ray_sid[ok[f]]
        groups = np.append(0, np.flatnonzero(pair_sid[1:] != pair_sid[:-1]) + 1)
        counts = np.diff(np.append(groups, pair_sid.size))
        pairs = pair_squared_distances(tri, sigma[pair_sid[groups]], self.bearing_sigma_rad,
                                       pairs=(ok[f], ok[g]), pair_groups=counts)
        self.store.add(lm[pairs.first], lm[pairs.second], pairs.squared_distance_m2,
                       pairs.variance_m4)


__all__ = ["BATCH_STEPS", "StepBatch"]
