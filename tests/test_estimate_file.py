"""The estimate file: exact round trip and a strict reader."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from baselines.triangulate import TriangulateMapper
from bomgraph.errors import StreamFormatError
from bomgraph.estimate_file import estimate_to_json, read_estimate, write_estimate
from bomgraph.mapper import run
from bomgraph.sim import SimConfig, paper_design, simulate_run


def test_estimate_file_round_trip(tmp_path: Path) -> None:
    s = simulate_run(paper_design(0)[1], SimConfig(n_steps=25))
    result = run(TriangulateMapper(s.header), s.steps, method="triangulate")
    write_estimate(result, tmp_path / "e.json")
    back = read_estimate(tmp_path / "e.json")
    assert back.method == "triangulate"
    np.testing.assert_array_equal(back.final.landmark_ids, result.final.landmark_ids)
    np.testing.assert_array_equal(back.final.landmarks_xy, result.final.landmarks_xy)
    np.testing.assert_array_equal(back.final.poses, result.final.poses)
    assert [c.t for c in back.checkpoints] == [10, 20, 25]
    assert estimate_to_json(result)["timing_s"]["total"] == result.total_s
    (tmp_path / "bad.json").write_text('{"format": "bomgraph-estimate", "version": 1, '
                                       '"landmarks": [[1, 2]]}')
    with pytest.raises(StreamFormatError, match="landmarks"):
        read_estimate(tmp_path / "bad.json")


@pytest.mark.parametrize("body,key", [
    ('"landmarks": [[0, 1, 2, 3, 4, 5]]', "landmarks[0]"),
    ('"landmarks": [["3", "1.5", "2.5"]]', "landmarks[0]"),
    ('"landmarks": [[true, 1.5, 2.5]]', "landmarks[0]"),
    ('"landmarks": [[1e30, 1.5, 2.5]]', "landmarks[0]"),
    ('"landmarks": [], "poses": [[2.7, 0, 0, 0]]', "poses[0]"),
    ('"landmarks": [], "poses": [[1, 0, 0, 0], [1, 0, 0, 0]]', "poses"),
    ('"landmarks": [], "checkpionts": []', "checkpionts"),
    ('"landmarks": [], "checkpoints": 5', "checkpoints"),
    ('"landmarks": [], "checkpoints": [{"t": true, "landmarks": []}]', "checkpoints[0].t"),
    ('"landmarks": [], "timing_s": [1, 2]', "timing_s"),
    ('"landmarks": [], "landmarks": []', "landmarks"),
])
def test_estimate_reader_is_strict(tmp_path: Path, body: str, key: str) -> None:
    p = tmp_path / "e.json"
    p.write_text('{"format": "bomgraph-estimate", "version": 1, "method": "m", ' + body + "}")
    with pytest.raises(StreamFormatError) as info:
        read_estimate(p)
    assert f"'{key}'" in str(info.value) and str(p) in str(info.value)
