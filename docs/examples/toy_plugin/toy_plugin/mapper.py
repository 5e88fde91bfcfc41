"""``first-sight``: each landmark ``depth_m`` along the first bearing that saw it, from the
dead-reckoned pose of that step. A poor map, but a complete bomgraph Mapper."""

import numpy as np

from bomgraph.geometry import compose
from bomgraph.mapper import MapEstimate
from bomgraph.stream import Step, StreamHeader


class FirstSightMapper:
    """each landmark depth_m along its first bearing (a toy plugin)"""

    description = "each landmark depth_m along its first bearing (a toy plugin)"

    def __init__(self, header: StreamHeader, *, depth_m: float = 1.0) -> None:
        self.depth_m = float(depth_m)
        self.pose = np.zeros(3)  # dead reckoning from the origin
        self.t = -1
        self.poses: list[np.ndarray] = []
        self.seen: dict[int, np.ndarray] = {}

    def step(self, step: Step) -> None:
        if step.odom is not None:  # None at t = 0
            self.pose = compose(self.pose, step.odom)
        self.t = step.t
        self.poses.append(self.pose.copy())
        for lid, brg in zip(step.landmark_ids.tolist(), step.bearings_rad.tolist()):
            if lid not in self.seen:
                angle = self.pose[2] + brg
                self.seen[lid] = self.pose[:2] + self.depth_m * np.array(
                    [np.cos(angle), np.sin(angle)])

    def estimate(self) -> MapEstimate:
        ids = np.array(sorted(self.seen), dtype=np.int64)
        xy = np.array([self.seen[i] for i in ids.tolist()]).reshape(-1, 2)
        return MapEstimate(ids, xy, pose_t=np.arange(self.t + 1),
                           poses=np.array(self.poses).reshape(-1, 3))
