"""Faults found by helper h126's hostile-input audit (a driver of ~2,000 cases over every
subcommand's arguments and readers), each reduced to its smallest reproduction. Each test
failed before its fix."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from hostile_helpers import HEADER, bomgraph, one_error, write_jsonl

FULL = "/dev/full"
needs_full = pytest.mark.skipif(not os.path.exists(FULL), reason="needs /dev/full")


@pytest.fixture
def small_stream(tmp_path: Path) -> Path:
    steps = [{"t": 0, "bearings": [[0, 0.5], [1, -0.5]]}] + [
        {"t": t, "odom": [0.1, 0.0, 0.05], "bearings": [[0, 0.5 + 0.05 * t], [1, -0.5]]}
        for t in range(1, 6)]
    return write_jsonl(tmp_path / "s.jsonl", HEADER, steps)


@needs_full
@pytest.mark.parametrize("command", ["simulate", "run", "plot"])
def test_a_full_stdout_is_not_blamed_on_the_out_file(tmp_path: Path, small_stream: Path,
                                                     command: str) -> None:
    """``bomgraph run ... --out e.json > /dev/full`` said "--out e.json: No space left on
    device" (exit 2) of an estimate written whole: the full device was stdout, where the
    summary line goes."""
    out = {"simulate": "o.jsonl", "run": "o.json", "plot": "o.png"}[command]
    args = {"simulate": ["simulate", "--steps", "5", "--landmarks", "3"],
            "run": ["run", small_stream, "--method", "triangulate"],
            "plot": ["plot", tmp_path / "e.json", small_stream]}[command]
    if command == "plot":
        assert bomgraph("run", small_stream, "--method", "triangulate", "--out",
                        tmp_path / "e.json").returncode == 0
    with open(FULL, "wb") as full:
        proc = bomgraph(*args, "--out", tmp_path / out, stdout=full.fileno())
    line = one_error(proc, "the standard output: No space left on device")
    assert "--out" not in line
    assert (tmp_path / out).stat().st_size > 0


@needs_full
@pytest.mark.parametrize("args", [["methods"], ["--help"], ["evaluate", "E", "S"]])
def test_a_full_stdout_is_named_without_out(tmp_path: Path, small_stream: Path,
                                            args: list[str]) -> None:
    """``bomgraph evaluate E S > /dev/full`` said "[Errno 28] No space left on device",
    naming nothing."""
    if "E" in args:
        est = tmp_path / "e.json"
        assert bomgraph("run", small_stream, "--method", "triangulate", "--out",
                        est).returncode == 0
        args = ["evaluate", str(est), str(small_stream)]
    with open(FULL, "wb") as full:
        proc = bomgraph(*args, stdout=full.fileno())
    one_error(proc, "the standard output: No space left on device")


def _estimate_with_landmarks(tmp_path: Path, stream: Path, landmarks: list) -> Path:
    """The estimate of ``triangulate`` on ``stream`` with its final map's landmarks replaced
    (the file stays bound to its stream)."""
    est = tmp_path / "e.json"
    assert bomgraph("run", stream, "--method", "triangulate", "--out", est).returncode == 0
    lines = est.read_text().splitlines()
    final = json.loads(lines[-2])
    final["landmarks"] = landmarks
    lines[-2] = json.dumps(final)
    est.write_text("\n".join(lines) + "\n")
    return est


@pytest.mark.parametrize("truth", [True, False])
def test_plot_refuses_a_map_too_far_out_to_draw(tmp_path: Path, truth: bool) -> None:
    """An estimate with landmarks at 1e308 m (finite, valid JSON: a diverged method's) made
    ``bomgraph plot`` die of matplotlib's "Axis limits cannot be NaN or Inf" traceback
    (exit 1), with and without truth in the stream."""
    header = dict(HEADER)
    if truth:
        header["truth"] = {"landmarks": [[0, 1.0, 2.0], [1, 2.0, 0.5], [2, 0.5, 0.5]],
                           "poses": [[0.1 * t, 0.0, 0.0] for t in range(6)]}
    steps = [{"t": 0, "bearings": [[0, 0.5], [1, -0.5], [2, 1.0]]}] + [
        {"t": t, "odom": [0.1, 0.0, 0.05], "bearings": [[0, 0.5 + 0.05 * t], [1, -0.5],
                                                        [2, 1.0 - 0.1 * t]]}
        for t in range(1, 6)]
    stream = write_jsonl(tmp_path / "s.jsonl", header, steps)
    est = _estimate_with_landmarks(tmp_path, stream, [[0, 1e308, -1e308], [1, -1e308, 1e308],
                                                      [2, 1e308, 1e308]])
    proc = bomgraph("plot", est, stream, "--out", tmp_path / "o.png")
    one_error(proc, *(["e.json: the final map: the estimate's landmark coordinates reach "
                       "1e+308 m", "a diverged map, not scored"] if truth else  # h136: as
                      ["e.json: the final map: a point", "beyond the 1e+100 m plot accepts"]))
    assert not (tmp_path / "o.png").exists()


def test_checkpoints_read_back_share_one_trajectory(tmp_path: Path) -> None:
    """A version-2 file of n checkpoints each adding one pose (``run --checkpoint-every 1``)
    was read into n copies of the trajectory so far: n^2/2 poses, 8,000 checkpoints (a 700 kB
    file) 1.5 GB. Now each checkpoint's trajectory is a read-only view of one buffer."""
    from bomgraph.estimate_file import read_estimate

    n = 3000
    path = tmp_path / "e.json"
    lines = [json.dumps({"format": "bomgraph-estimate", "version": 2, "method": "x",
                         "checkpoint_every": 1})]
    lines += [json.dumps({"t": t, "landmarks": [[0, 1.0, 2.0]],
                          "new_poses": [[t, 0.1 * t, 0.0, 0.0]]}) for t in range(n)]
    lines.append(json.dumps({"timing_s": {"total": 1.0}}))
    path.write_text("\n".join(lines) + "\n")
    est = read_estimate(path)
    cps = est.checkpoints
    assert [len(c.estimate.pose_t) for c in cps[:3]] == [1, 2, 3]
    assert np.array_equal(cps[-1].estimate.pose_t, np.arange(n))
    assert cps[10].estimate.poses[10, 0] == pytest.approx(1.0)
    owners = {id(_base(c.estimate.poses)) for c in cps}
    assert len(owners) < 20, len(owners)   # a few doubling buffers, not one per checkpoint
    assert not cps[5].estimate.poses.flags.writeable


def _base(a: np.ndarray) -> np.ndarray:
    while a.base is not None and isinstance(a.base, np.ndarray):
        a = a.base
    return a
