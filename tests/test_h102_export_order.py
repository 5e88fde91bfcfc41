"""Export of an estimate whose poses are not in step order, and of a timed stream to g2o
(h102's mutation audit: the export tests' estimates list their poses by step and their g2o
round trip has no time stamps, so an export that wrote the poses in the estimate's order,
or a g2o header without the time stamps, passed them)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from bomgraph.datasets import import_g2o
from bomgraph.export import export_text
from bomgraph.mapper import MapEstimate
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream import Stream

#: three poses listed t = 2, 0, 1
SHUFFLED = MapEstimate(np.array([4]), np.array([[1.0, 2.0]]), pose_t=np.array([2, 0, 1]),
                       poses=np.array([[2.0, 20.0, 0.2], [0.0, 0.0, 0.0], [1.0, 10.0, 0.1]]))


def _rows(text: str) -> list[list[float]]:
    return [[float(v) for v in ln.split()] for ln in text.splitlines()
            if ln.strip() and not ln.startswith("#")]


def test_tum_and_kitti_lines_are_in_step_order() -> None:
    tum = _rows(export_text(SHUFFLED, "tum"))
    assert [r[0] for r in tum] == [0.0, 1.0, 2.0]          # t: the step index
    assert [r[1:3] for r in tum] == [[0.0, 0.0], [1.0, 10.0], [2.0, 20.0]]
    np.testing.assert_allclose([2 * math.atan2(r[6], r[7]) for r in tum], [0.0, 0.1, 0.2],
                               rtol=0, atol=1e-15)
    kitti = _rows(export_text(SHUFFLED, "kitti"))
    assert [(r[3], r[7]) for r in kitti] == [(0.0, 0.0), (1.0, 10.0), (2.0, 20.0)]


def test_csv_pose_rows_are_in_step_order() -> None:
    lines = export_text(SHUFFLED, "csv").splitlines()
    assert lines[1:4] == ["pose,0,0.0,0.0,0.0,", "pose,1,1.0,10.0,0.1,", "pose,2,2.0,20.0,0.2,"]


def test_g2o_keeps_the_streams_time_stamps(tmp_path: Path) -> None:
    stream = simulate(SimConfig(n_landmarks=6, n_steps=5), np.random.default_rng(3))
    steps = tuple(dataclasses.replace(s, time_s=50.0 + 0.25 * s.t) for s in stream.steps)
    stream = Stream(stream.header, steps, stream.truth)
    tr = stream.truth
    est = MapEstimate(tr.landmark_ids, tr.landmarks_xy, pose_t=np.arange(len(tr.poses)),
                      poses=tr.poses)
    path = tmp_path / "p.g2o"
    path.write_text(export_text(est, "g2o", stream))
    assert [s.time_s for s in import_g2o(path).steps] == [50.0 + 0.25 * t for t in range(len(steps))]
