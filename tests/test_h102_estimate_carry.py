"""Estimate files: what a checkpoint without poses reads back as (h102's mutation audit).

docs/FORMATS.md: an earlier checkpoint without poses keeps the trajectory so far (and its
covariances); the last line is the final map, exact. A final map without poses after
checkpoints with them read back with the earlier trajectory, a map the method never gave
(``bomgraph evaluate`` scored its robot error)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bomgraph.estimate_file import read_estimate, write_estimate
from bomgraph.mapper import Checkpoint, MapEstimate, RunResult

LMS = (np.array([1, 2]), np.array([[0.0, 1.0], [2.0, -1.0]]))
COV = np.stack([np.diag([0.01, 0.02, 0.003]), np.diag([0.04, 0.05, 0.006])])
WITH_POSES = MapEstimate(*LMS, pose_t=np.array([0, 1]),
                         poses=np.array([[0.0, 0.0, 0.0], [0.3, 0.1, 0.2]]), pose_cov=COV)
WITHOUT = MapEstimate(*LMS)


def _round_trip(tmp_path: Path, *estimates: MapEstimate) -> list[MapEstimate]:
    cps = tuple(Checkpoint(5 * (k + 1), e, 0.001 * k) for k, e in enumerate(estimates))
    write_estimate(RunResult("m", cps, np.full(3, 0.01), 0.5), tmp_path / "e.jsonl")
    return [c.estimate for c in read_estimate(tmp_path / "e.jsonl").checkpoints]


def test_an_earlier_checkpoint_without_poses_keeps_the_trajectory_and_its_covariances(
        tmp_path: Path) -> None:
    got = _round_trip(tmp_path, WITH_POSES, WITHOUT, WITH_POSES)
    np.testing.assert_array_equal(got[1].pose_t, [0, 1])
    np.testing.assert_array_equal(got[1].poses, WITH_POSES.poses)
    np.testing.assert_array_equal(got[1].pose_cov, COV)


def test_a_final_map_without_poses_reads_back_without_poses(tmp_path: Path) -> None:
    got = _round_trip(tmp_path, WITH_POSES, WITHOUT)
    assert got[-1].poses is None and got[-1].pose_t is None and got[-1].pose_cov is None
    np.testing.assert_array_equal(got[-1].landmarks_xy, LMS[1])
    assert read_estimate(tmp_path / "e.jsonl").final.poses is None


def test_the_timing_line_by_hand(tmp_path: Path) -> None:
    """steps: the sum of the step times; step_median and estimate_median: medians."""
    cps = tuple(Checkpoint(5 * (k + 1), WITHOUT, s) for k, s in enumerate((0.001, 0.002, 0.009)))
    write_estimate(RunResult("m", cps, np.array([0.01, 0.02, 0.06]), 0.5), tmp_path / "e.jsonl")
    timing = read_estimate(tmp_path / "e.jsonl").timing_s
    assert timing == {"total": 0.5, "steps": 0.09, "step_median": 0.02, "estimates": 0.012,
                      "estimate_median": 0.002}
