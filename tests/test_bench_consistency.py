"""scripts/bench_consistency.py: the anchored NEES it reports, and a short run of it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from _scripts import load_script  # noqa: E402  (tests/_scripts.py)
from bomgraph.geometry import rotation
from bomgraph.map_estimate import MapEstimate
from bomgraph.stream import Truth

bench = load_script("bench_consistency")


def _truth() -> Truth:
    rng = np.random.default_rng(3)
    poses = np.cumsum(rng.normal(0, 0.3, (6, 3)), axis=0)
    return Truth(np.arange(8), rng.uniform(-2, 2, (8, 2)), poses)


def test_an_estimate_in_another_frame_is_carried_onto_the_truth() -> None:
    """The truth written in a frame turned by 1 rad and shifted, with one known error on the
    last pose and one landmark: the NEES is that error against its covariance turned back
    into the truth's frame."""
    truth = _truth()
    frame = np.array([0.7, -1.2, 1.0])           # the estimate's frame in the truth's
    inv_rot = rotation(np.array([-frame[2]]))[0]
    poses = truth.poses.copy()
    poses[:, :2] = (poses[:, :2] - frame[:2]) @ inv_rot.T
    poses[:, 2] -= frame[2]
    xy = (truth.landmarks_xy - frame[:2]) @ inv_rot.T
    d_pose, d_lm = np.array([0.02, -0.01, 0.03]), np.array([0.05, 0.0])
    poses[-1] += d_pose
    xy[2] += d_lm
    pose_cov = np.tile(np.diag([1e-4, 4e-4, 1e-3]), (len(poses), 1, 1))
    lm_cov = np.tile(np.diag([1e-2, 1e-3]), (8, 1, 1))
    est = MapEstimate(truth.landmark_ids, xy, pose_t=np.arange(6), poses=poses,
                      landmark_cov=lm_cov, pose_cov=pose_cov)
    out = bench.anchored_nees(est, truth)
    rot = rotation(np.array([frame[2]]))[0]
    jac = np.eye(3)
    jac[:2, :2] = rot
    e = jac @ d_pose
    want = e @ np.linalg.solve(jac @ pose_cov[-1] @ jac.T, e)
    assert out["pose"] == pytest.approx(want, rel=1e-9)
    assert out["pose"] == pytest.approx(4 + 0.25 + 0.9, rel=1e-9)   # frame-free: d^T P^-1 d
    assert out["landmarks"] == pytest.approx(0.25 / 8, rel=1e-9)
    assert out["n_landmarks"] == 8


def test_a_short_run_prints_and_saves_every_run(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "c.json"
    assert bench.main(["--methods", "gtsam-batch", "--seeds", "0:2", "--steps", "40",
                       "--landmarks", "20", "--out", str(out)]) == 0
    line = capsys.readouterr().out
    assert line.startswith("gtsam-batch") and "pose NEES" in line and "runs   2/2" in line
    rows = json.loads(out.read_text())["gtsam-batch"]
    assert [r["seed"] for r in rows] == [0, 1]
    assert all(np.isfinite(r["pose"]) and r["n_landmarks"] >= 3 for r in rows)
