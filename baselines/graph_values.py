"""Keys and values of the bearing-only graph read in bulk, without a Python loop per variable.

The keys (:func:`pose_key`, :func:`mid_key`, :func:`landmark_key`): a robot pose ``x_t`` is
``gtsam.symbol("x", t)``, an intermediate pose ``m_t`` is ``symbol("m", t)``, both
``(char << 56) | index``; landmark ``i`` is ``symbol("l", i)`` below ``2**56`` and
``2**63 | i`` above. Here the same keys are also
computed as ``uint64`` arrays, and poses and points are read from a ``gtsam.Values`` with one
``Values.extract`` of the keys (a copy of those entries, C++) and one
``gtsam.utilities.extractPose2`` / ``extractPoint2``, which return the entries in key order.
The numbers are the values' own doubles (``extractPose2`` reads ``x(), y(), theta()`` like
``Pose2`` in Python), so the readers give bit for bit what a loop of ``atPose2`` /
``atPoint2`` gives.

Assumption of :func:`points_at`: every landmark of ``values`` is stored as a GTSAM ``Vector``
(what ``Values.insert(key, numpy array)``, hence ``gtsam.Point2`` in Python, stores, and LM's
retract keeps); ``extractPoint2`` lists fixed-size ``Point2`` entries before them.
"""

from __future__ import annotations

from typing import Sequence

import gtsam
import numpy as np

from bomgraph.errors import ConfigError

_CHAR_SHIFT = np.uint64(56)
#: ``gtsam.symbol`` holds an index of 56 bits; stream ids go up to 2^63 - 1 (int64).
_SYMBOL_INDEX_LIMIT = 1 << 56
_WIDE_LANDMARK = np.uint64(1 << 63)


def pose_key(t: int) -> int:
    """GTSAM key of the robot pose at step ``t``."""
    return gtsam.symbol("x", int(t))


def mid_key(t: int) -> int:
    """GTSAM key of the intermediate pose of step ``t`` (after the move, before the turn)."""
    return gtsam.symbol("m", int(t))


def landmark_key(landmark_id: int) -> int:
    """GTSAM key of landmark ``landmark_id``, for every id the stream format allows
    (``0 <= id < 2**63``).

    Ids below 2^56 get ``symbol("l", id)``; larger ids (which ``gtsam.symbol`` refuses) get
    the key ``2**63 | id``, whose top byte (>= 0x80) no symbol key of this module (``l``,
    ``m``, ``x``) uses, so the map is injective without a table and the keys of ordinary ids,
    hence every solve on them, are unchanged.

    Raises
    ------
    ConfigError
        For a negative id or one of 2^63 or more.
    """
    i = int(landmark_id)
    if 0 <= i < _SYMBOL_INDEX_LIMIT:
        return gtsam.symbol("l", i)
    if _SYMBOL_INDEX_LIMIT <= i < 1 << 63:
        return (1 << 63) | i
    raise ConfigError(f"landmark id {i} is outside 0 .. 2**63 - 1, the range of the stream "
                      f"format; renumber the landmarks")


def symbol_keys(char: str, indices: np.ndarray) -> np.ndarray:
    """``gtsam.symbol(char, j)`` for every ``j`` of ``indices`` (>= 0, < 2^56): (k,) uint64."""
    return (np.uint64(ord(char)) << _CHAR_SHIFT) | np.asarray(indices, dtype=np.uint64)


def landmark_keys(ids: np.ndarray) -> np.ndarray:
    """:func:`landmark_key` of every id (0 <= id < 2^63): (k,) uint64,
    increasing with the id."""
    i = np.asarray(ids, dtype=np.int64).astype(np.uint64)
    return np.where(i < np.uint64(_SYMBOL_INDEX_LIMIT), symbol_keys("l", i), _WIDE_LANDMARK | i)


def is_pose_key(keys: np.ndarray) -> np.ndarray:
    """Whether each of ``keys`` ((k,) uint64, any keys of the graph) is a pose's (symbols
    ``x``, ``m``; every other key is a landmark's): (k,) bool."""
    char = np.asarray(keys, dtype=np.uint64) >> _CHAR_SHIFT
    return (char == ord("x")) | (char == ord("m"))


def key_landmark_ids(keys: np.ndarray) -> np.ndarray:
    """The landmark ids of the landmark keys among ``keys`` ((k,) uint64, any keys of the
    graph: poses ``x``, ``m`` are left out), in the order given: (n,) int64."""
    k = np.asarray(keys, dtype=np.uint64)
    k = k[~is_pose_key(k)]
    wide = (k >> np.uint64(63)).astype(bool)
    return np.where(wide, k ^ _WIDE_LANDMARK, k & np.uint64(_SYMBOL_INDEX_LIMIT - 1)
                    ).astype(np.int64)


def _read(values: gtsam.Values, keys: np.ndarray, extract, width: int) -> np.ndarray:
    """Rows of ``extract(values restricted to keys)`` in the order of ``keys`` (any order,
    repeats allowed): (len(keys), width)."""
    if not len(keys):
        return np.zeros((0, width))
    u, at = np.unique(keys, return_inverse=True)
    rows = np.asarray(extract(values.extract(u.tolist()))).reshape(-1, width)
    if len(rows) != len(u):
        raise ValueError(f"read {len(rows)} entries of {len(u)} keys")
    return rows[at.reshape(-1)]


def poses_at(values: gtsam.Values, ts: Sequence[int] | np.ndarray) -> np.ndarray:
    """Robot poses ``x_t`` (``[x, y, theta]``) of ``values`` for the steps ``ts`` (k,), in
    that order: (k, 3). Raises GTSAM's RuntimeError if one is missing."""
    return _read(values, symbol_keys("x", np.asarray(ts, dtype=np.int64)),
                 gtsam.utilities.extractPose2, 3)


def points_at(values: gtsam.Values, ids: Sequence[int] | np.ndarray) -> np.ndarray:
    """Landmark points of ``values`` for the ids ``ids`` (k,), in that order: (k, 2) (module
    docstring: landmarks stored as ``Vector``). Raises if one is missing."""
    return _read(values, landmark_keys(np.asarray(ids, dtype=np.int64)),
                 gtsam.utilities.extractPoint2, 2)


__all__ = ["symbol_keys", "landmark_keys", "is_pose_key", "key_landmark_ids", "poses_at",
           "points_at"]
