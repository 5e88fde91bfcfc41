"""The bulk readers of ``baselines/graph_values.py``: the keys they compute are GTSAM's, and
the poses and points they read are, bit for bit, those of a loop of ``atPose2`` /
``atPoint2``, in the order asked for (repeats and wide landmark ids included)."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from baselines.bearing_graph import landmark_key, mid_key, pose_key
from baselines.graph_values import key_landmark_ids, landmark_keys, points_at, poses_at

IDS = np.array([0, 5, 3, 2 ** 40, (1 << 56) + 7, (1 << 63) - 1], dtype=np.int64)


def _values() -> gtsam.Values:
    rng = np.random.default_rng(4)
    v = gtsam.Values()
    for t in range(40):
        v.insert(pose_key(t), gtsam.Pose2(*(rng.normal(size=3) * [5.0, 5.0, 3.0])))
        v.insert(mid_key(t), gtsam.Pose2(*rng.normal(size=3)))
    for i in IDS:
        v.insert(landmark_key(int(i)), gtsam.Point2(*rng.normal(size=2) * 10))
    return v


def test_keys_are_gtsams_and_invert() -> None:
    keys = landmark_keys(IDS)
    assert [int(k) for k in keys] == [landmark_key(int(i)) for i in IDS]
    mixed = np.concatenate([keys, np.array([pose_key(3), mid_key(9)], dtype=np.uint64)])
    assert np.array_equal(key_landmark_ids(mixed), IDS)


def test_readers_match_the_loop_bit_for_bit() -> None:
    v = _values()
    ts = np.array([7, 0, 39, 7, 12])
    loop = np.array([[p.x(), p.y(), p.theta()] for p in (v.atPose2(pose_key(int(t)))
                                                         for t in ts)])
    assert poses_at(v, ts).tobytes() == loop.tobytes()
    ids = IDS[[4, 0, 5, 2, 0]]
    loop = np.array([v.atPoint2(landmark_key(int(i))) for i in ids])
    assert points_at(v, ids).tobytes() == loop.tobytes()
    assert points_at(v, []).shape == (0, 2)


def test_a_missing_key_raises() -> None:
    with pytest.raises(RuntimeError, match="does not exist"):
        poses_at(_values(), [40])
