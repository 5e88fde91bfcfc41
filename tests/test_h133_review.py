"""Review of h126's shared trajectory buffer in the version-2 estimate reader (h133)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bomgraph.errors import StreamFormatError
from bomgraph.estimate_file import read_estimate

HEAD = {"format": "bomgraph-estimate", "version": 2, "method": "x"}


def _write(path: Path, lines: list[dict]) -> Path:
    rows = [HEAD, *lines, {"timing_s": {"total": 1.0}}]
    path.write_text("".join(json.dumps(o) + "\n" for o in rows))
    return path


def test_new_poses_may_not_repeat_a_t_of_an_unsorted_trajectory(tmp_path: Path) -> None:
    """``poses`` [5, 2] then ``new_poses`` [5]: the reader compared the new poses with the
    trajectory's last row (t = 2), not its largest t (the writer's ``since_t``), and gave a
    checkpoint whose pose_t [5, 2, 5] repeats a step, which MapEstimate forbids."""
    path = _write(tmp_path / "e.est", [
        {"t": 1, "landmarks": [], "poses": [[5, 0, 0, 0], [2, 1, 0, 0]]},
        {"t": 2, "landmarks": [], "new_poses": [[5, 2, 0, 0]]}])
    with pytest.raises(StreamFormatError, match="line 3.*after the previous checkpoint's last "
                                                "pose t = 5"):
        read_estimate(path)


def _random_lines(rng: np.random.Generator) -> tuple[list[dict], list | None]:
    """Checkpoint lines of every kind, and each checkpoint's trajectory rebuilt naively
    (None: no poses yet), or None for a file the reader must refuse."""
    lines: list[dict] = []
    want: list = []
    ts: list[int] | None = None
    poses: list | None = None
    covs: list | None = None
    for c in range(int(rng.integers(1, 12))):
        o: dict = {"t": c, "landmarks": [[0, 1.0, 2.0]]}
        k = int(rng.integers(0, 4))
        new_t = [int(x) for x in rng.choice(40, k, replace=False)]
        p = [[float(rng.normal()), 0.0, 0.5] for _ in new_t]
        a = rng.normal(size=(k, 3, 3))
        cv = [(m @ m.T).ravel().tolist() for m in a]
        with_cov = rng.random() < 0.6
        kind = rng.choice(["none", "poses", "new"], p=[0.2, 0.2, 0.6])
        if kind != "none":
            key = "poses" if kind == "poses" else "new_poses"
            o[key] = [[t, *q] for t, q in zip(new_t, p)]
            if with_cov:
                o[key.replace("poses", "pose_cov")] = cv
            if kind == "poses" or ts is None:
                ts, poses, covs = [], [], []
            if kind == "new" and ts and new_t and min(new_t) <= max(ts):
                lines.append(o)
                return lines, None
            ts, poses = ts + new_t, poses + p
            covs = covs + cv if with_cov and covs is not None else None
        lines.append(o)
        want.append(None if ts is None else (ts, poses, covs))
    return lines, want


def test_checkpoints_read_back_as_rebuilt_naively(tmp_path: Path) -> None:
    """Every checkpoint's pose_t, poses and pose_cov equal the trajectory concatenated line
    by line (the reader before h126), on 300 random files, and a file whose new poses repeat
    or precede a t of the trajectory so far is refused."""
    rng = np.random.default_rng(133)
    refused = 0
    for n in range(300):
        lines, want = _random_lines(rng)
        path = _write(tmp_path / f"e{n}.est", lines)
        if want is None:
            refused += 1
            with pytest.raises(StreamFormatError, match="after the previous"):
                read_estimate(path)
            continue
        cps = read_estimate(path).checkpoints
        for c, w in zip(cps[:-1], want[:-1]):
            e = c.estimate
            if w is None:
                assert e.pose_t is None
                continue
            assert np.array_equal(e.pose_t, np.array(w[0], np.int64).reshape(-1))
            assert np.array_equal(e.poses, np.array(w[1], float).reshape(-1, 3))
            assert (e.pose_cov is None) == (w[2] is None)
            if w[2] is not None:
                assert np.array_equal(e.pose_cov, np.array(w[2], float).reshape(-1, 3, 3))
            assert not e.poses.flags.writeable and e.poses.dtype == np.float64
    assert 20 < refused < 250, refused
