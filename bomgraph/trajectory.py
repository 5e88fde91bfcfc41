"""Pose errors of an aligned trajectory, as evo reports them, and a truth-free consistency
figure.

- :func:`absolute_pose_errors`: per pose, the translation error [m] and the heading error
  [rad] of the aligned estimate against the reference (evo's APE, translation and rotation
  parts).
- :func:`relative_pose_errors`: per pair of poses ``delta`` steps apart, the error of the
  relative motion ``E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)`` (evo's RPE with ``--delta``):
  ``|E.xy|`` [m] and ``|E.psi|`` [rad].
- :func:`bearing_residuals`: measured minus predicted bearing of every measurement the
  estimate's own map and trajectory cover (no truth needed); :class:`BearingResidualSums`
  their RMS summed batch by batch as a stream is read (exactly: :class:`ExactSum`), without
  holding the bearings.

Nothing here aligns; :mod:`bomgraph.evaluate` does, then calls these on the aligned poses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .angles import angle_residual
from .geometry import between, pair_bearings
from .stream import Step


def rms(v: np.ndarray) -> float:
    """RMS without overflow (scaled by the largest magnitude); NaN when empty."""
    if not v.size:
        return float("nan")
    m = float(np.max(np.abs(v)))
    return 0.0 if m == 0 else m * float(np.sqrt(np.mean((v / m) ** 2)))


@dataclass(frozen=True)
class PoseErrors:
    """Errors per pose (APE) or per pose pair (RPE): ``t`` (k,) the step (for RPE the first
    step of the pair), ``translation_m`` (k,), ``heading_rad`` (k,) absolute values."""

    t: np.ndarray
    translation_m: np.ndarray
    heading_rad: np.ndarray

    def __len__(self) -> int:
        return len(self.t)

    @property
    def translation_rmse_m(self) -> float:
        return rms(self.translation_m)

    @property
    def heading_rmse_rad(self) -> float:
        return rms(self.heading_rad)


def absolute_pose_errors(t: np.ndarray, est_poses: np.ndarray,
                         ref_poses: np.ndarray) -> PoseErrors:
    """APE of aligned ``(k, 3)`` poses ``est_poses`` against ``ref_poses`` at steps ``t``."""
    e, r = np.asarray(est_poses, float).reshape(-1, 3), np.asarray(ref_poses, float).reshape(-1, 3)
    trans = np.hypot(e[:, 0] - r[:, 0], e[:, 1] - r[:, 1])
    head = np.abs(angle_residual(e[:, 2], r[:, 2]))
    return PoseErrors(np.asarray(t, np.int64), trans, np.asarray(head, float))


def relative_pose_errors(t: np.ndarray, est_poses: np.ndarray, ref_poses: np.ndarray,
                         delta: int = 1) -> PoseErrors:
    """RPE over every pair of steps ``(t_i, t_i + delta)`` both present in ``t``.

    ``est_poses`` and ``ref_poses`` are ``(k, 3)`` at the steps ``t`` (aligned, so that a
    mirrored estimate is compared in the reference's handedness).
    """
    if delta < 1:
        raise ValueError(f"delta must be >= 1 step, got {delta}")
    t = np.asarray(t, np.int64)
    e, r = np.asarray(est_poses, float).reshape(-1, 3), np.asarray(ref_poses, float).reshape(-1, 3)
    order = np.argsort(t)
    t, e, r = t[order], e[order], r[order]
    if not len(t) or delta > int(t[-1]) - int(t[0]):  # no pair (and no int64 overflow)
        return PoseErrors(t[:0], np.zeros(0), np.zeros(0))
    j = np.searchsorted(t, t + delta)
    ok = j < len(t)
    ok[ok] = t[j[ok]] == t[ok] + delta
    i, j = np.nonzero(ok)[0], j[ok]
    err = between(between(r[i], r[j]), between(e[i], e[j]))
    return PoseErrors(t[i], np.hypot(err[:, 0], err[:, 1]), np.abs(err[:, 2]))


def bearing_residuals(landmark_ids: np.ndarray, landmarks_xy: np.ndarray, pose_t: np.ndarray,
                      poses: np.ndarray, steps: Sequence[Step], *,
                      mirrored: bool = False) -> np.ndarray:
    """Measured minus predicted bearing [rad] of every measurement of a mapped landmark from
    a pose the estimate holds, shape (m,): how well a map and trajectory explain the data.

    ``mirrored`` negates the predictions: an estimate in a mirrored frame explains the
    bearings that way (a reflection reverses every angle).
    """
    if not len(steps) or not len(landmark_ids) or not len(pose_t):
        return np.zeros(0)
    t, ids, brg = bearing_arrays(steps)
    covered = _Covered(landmark_ids, landmarks_xy, pose_t, poses)
    ok, pred = covered(t, ids)
    if not ok.any():
        return np.zeros(0)
    return angle_residual(brg[ok], -pred if mirrored else pred)


def bearing_arrays(steps: Sequence[Step]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The bearings of ``steps`` as flat arrays: step ``t``, landmark id, bearing [rad]."""
    t = np.concatenate([np.full(len(st.landmark_ids), st.t) for st in steps]).astype(np.int64)
    ids = np.concatenate([st.landmark_ids for st in steps]).astype(np.int64)
    brg = np.concatenate([st.bearings_rad for st in steps]).astype(float)
    return t, ids, brg


class _Covered:
    """The bearings a map and trajectory cover and their predictions: called with flat
    arrays of step ``t`` and landmark ids, gives the mask of those with both a pose at ``t``
    and the landmark, and their predicted bearings [rad]."""

    def __init__(self, landmark_ids: np.ndarray, landmarks_xy: np.ndarray,
                 pose_t: np.ndarray, poses: np.ndarray) -> None:
        self._lm = _Rows(landmark_ids)
        self._pose = _Rows(pose_t)
        self._xy = np.asarray(landmarks_xy, float)
        self._poses = np.asarray(poses, float)

    def __call__(self, t: np.ndarray, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        pr, pok = self._pose(t)
        lr, lok = self._lm(ids)
        ok = pok & lok
        p, q = self._poses[pr[ok]], self._xy[lr[ok]]
        return ok, pair_bearings(p, q)


class _Rows:
    """Rows of integer ``keys`` (non-empty): for wanted keys, the row and whether it is one."""

    def __init__(self, keys: np.ndarray) -> None:
        self._keys = np.asarray(keys, np.int64)
        self._order = np.argsort(self._keys)

    def __call__(self, wanted: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        pos = np.clip(np.searchsorted(self._keys, wanted, sorter=self._order), 0,
                      len(self._keys) - 1)
        return self._order[pos], self._keys[self._order[pos]] == wanted


class ExactSum:
    """The exact sum of finite floats given in batches, rounded once when read: it does not
    depend on how the values are batched or ordered (a running float sum, or numpy's pairwise
    one, does), in memory bounded by the exponent range.

    Each value is ``M * 2**(e - 53)`` with an integer ``M`` (``np.frexp``); the ``M`` are
    summed per exponent as integers, exactly, and the total kept as one Python integer.
    A NaN or an infinity given makes the sum that (NaN for both infinities), as a float sum
    would; a finite sum beyond the float range reads as an infinity of its sign.
    """

    _BIAS = 1073            # frexp's exponent of the smallest subnormal is -1073
    _ULP = 1 << (1073 + 53)  # the total counts units of 2**-1126
    _CHUNK = 1 << 25        # 27-bit halves of M: float64 bin sums stay exact below 2**26

    def __init__(self) -> None:
        self._total = 0
        self._special = 0.0     # the float sum of the NaNs and infinities given

    def add(self, values: np.ndarray) -> None:
        v = np.asarray(values, float).ravel()
        finite = np.isfinite(v)
        if not finite.all():    # frexp gives no integer mantissa for these
            self._special += float(np.sum(v[~finite]))
            v = v[finite]
        for start in range(0, v.size, self._CHUNK):
            m, e = np.frexp(v[start:start + self._CHUNK])
            big = (m * 2.0 ** 53).astype(np.int64)
            bins = e.astype(np.int64) + self._BIAS
            hi = np.bincount(bins, weights=(big >> 26).astype(float))
            lo = np.bincount(bins, weights=(big & ((1 << 26) - 1)).astype(float))
            for k in np.flatnonzero((hi != 0) | (lo != 0)):
                self._total += ((int(hi[k]) << 26) + int(lo[k])) << int(k)

    @property
    def value(self) -> float:
        """The sum, correctly rounded (Python's integer division is)."""
        if self._special != 0.0 or math.isnan(self._special):
            return self._special
        try:
            return self._total / self._ULP
        except OverflowError:   # beyond the largest float: as a float sum would round it
            return math.inf if self._total > 0 else -math.inf


class BearingResidualSums:
    """:func:`bearing_residuals` of a map and trajectory summed as the bearings are read, for
    the RMS without holding them: feed the stream's bearings in order with :meth:`add`
    (those after step ``until_t``, if given, are left out). The RMS values use the exact sum
    of the squares (:class:`ExactSum`), the same however the bearings were batched. With
    ``mirrored=False`` the mirrored sums are not kept (:attr:`mirrored_rms_rad` is NaN)."""

    def __init__(self, landmark_ids: np.ndarray, landmarks_xy: np.ndarray, pose_t: np.ndarray,
                 poses: np.ndarray | None, until_t: int | None = None, *,
                 mirrored: bool = True) -> None:
        self.until_t = until_t
        self.n = 0
        self._sq = ExactSum()
        self._mirrored_sq = ExactSum() if mirrored else None
        self._covered = (None if poses is None or not len(landmark_ids) or not len(pose_t)
                         else _Covered(landmark_ids, landmarks_xy, pose_t, poses))

    def add(self, t: np.ndarray, ids: np.ndarray, bearings_rad: np.ndarray) -> None:
        """Bearings as flat arrays in stream order: step ``t``, landmark id, bearing [rad]."""
        if self._covered is None or not len(t):
            return
        if self.until_t is not None:
            k = int(np.searchsorted(t, self.until_t, side="right"))
            t, ids, bearings_rad = t[:k], ids[:k], bearings_rad[:k]
        ok, pred = self._covered(t, ids)
        if ok.any():
            brg = bearings_rad[ok]
            self.n += int(ok.sum())
            self._sq.add(angle_residual(brg, pred) ** 2)
            if self._mirrored_sq is not None:
                self._mirrored_sq.add(angle_residual(brg, -pred) ** 2)

    def add_steps(self, steps: Sequence[Step]) -> None:
        if len(steps):
            self.add(*bearing_arrays(steps))

    @property
    def rms_rad(self) -> float:
        return math.sqrt(self._sq.value / self.n) if self.n else math.nan

    @property
    def mirrored_rms_rad(self) -> float:
        if self._mirrored_sq is None or not self.n:
            return math.nan
        return math.sqrt(self._mirrored_sq.value / self.n)


__all__ = ["PoseErrors", "absolute_pose_errors", "relative_pose_errors", "bearing_residuals",
           "bearing_arrays", "BearingResidualSums", "ExactSum", "rms"]
