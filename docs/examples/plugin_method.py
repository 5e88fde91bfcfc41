"""A plugin method: a tiny Mapper registered under a name and run like the built-in ones.

    python docs/examples/plugin_method.py STREAM.jsonl OUT.est

The mapper places each landmark at the dead-reckoned position of the first pose that saw it,
pushed one metre along the bearing: a (poor) map, but a complete Mapper.
"""

import sys

import numpy as np

from bomgraph.cli import main
from bomgraph.geometry import compose
from bomgraph.mapper import MapEstimate, register_method
from bomgraph.stream import Step, StreamHeader


class FirstSightMapper:
    """``step()`` takes one step of the stream, ``estimate()`` returns the map so far."""

    def __init__(self, header: StreamHeader, *, depth_m: float = 1.0) -> None:
        self.depth_m = depth_m
        self.pose = np.zeros(3)  # dead reckoning from the origin
        self.seen: dict[int, np.ndarray] = {}

    def step(self, step: Step) -> None:
        if step.odom is not None:  # None at t = 0
            self.pose = compose(self.pose, step.odom)
        for lid, brg in zip(step.landmark_ids.tolist(), step.bearings_rad.tolist()):
            if lid not in self.seen:
                angle = self.pose[2] + brg
                self.seen[lid] = self.pose[:2] + self.depth_m * np.array(
                    [np.cos(angle), np.sin(angle)])

    def estimate(self) -> MapEstimate:
        ids = np.array(sorted(self.seen), dtype=np.int64)
        xy = np.array([self.seen[i] for i in ids.tolist()]).reshape(-1, 2)
        return MapEstimate(ids, xy)


# "module:attribute" of the factory; this file runs as __main__, so register it from there.
# (a name of its own: the installed toy plugin is called first-sight)
register_method("first-sight-script", "__main__:FirstSightMapper",
                "each landmark one metre along its first bearing (an example plugin)")

if __name__ == "__main__":
    if len(sys.argv) != 3:
        print("usage: python docs/examples/plugin_method.py STREAM.jsonl OUT.est", file=sys.stderr)
        sys.exit(2)
    stream_path, out = sys.argv[1:3]
    sys.exit(main(["run", stream_path, "--method", "first-sight-script", "--option", "depth_m=0.5",
                   "--out", out]))
