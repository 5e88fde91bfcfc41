"""The toy method of the cache tests, as module source text: each landmark a fixed depth along
its first bearing, so an edit of the depth shows in every map and its MPE."""

from __future__ import annotations


def depth_mapper(depth: str, name: str = "DepthMapper", attrs: str = "") -> str:
    """The source of a module defining class ``name``, which puts each landmark ``depth``
    metres (an expression: ``"DEPTH_M"``, ``"self.DEPTH"``) along its first bearing;
    ``attrs``: a line put first in the class body (``"DEPTH = 1.0"``)."""
    body = f"    {attrs}\n" if attrs else ""
    return f'''
import numpy as np
from bomgraph.geometry import compose
from bomgraph.mapper import MapEstimate

class {name}:
    """each landmark a fixed depth along its first bearing"""
{body}    def __init__(self, header, **options):
        self.pose, self.seen = np.zeros(3), {{}}
    def step(self, step):
        if step.odom is not None:
            self.pose = compose(self.pose, step.odom)
        for lid, b in zip(step.landmark_ids.tolist(), step.bearings_rad.tolist()):
            a = self.pose[2] + b
            self.seen.setdefault(lid, self.pose[:2] + {depth} * np.array([np.cos(a), np.sin(a)]))
    def estimate(self):
        ids = np.array(sorted(self.seen), dtype=np.int64)
        return MapEstimate(ids, np.array([self.seen[i] for i in ids.tolist()]).reshape(-1, 2))
'''
