"""h96's review of h91's cap on g2o files (16 MiB of text, the whole file): it refused a
simulated run's own export, 20,000 steps of the default world (`bomgraph simulate --steps
20000`, then `bomgraph export --truth ... --format g2o`: 29 MB, 94% of it bearings). A g2o
file is now bounded by the text of the records it holds as Python objects (vertices,
EDGE_SE2, FIX: ``MAX_G2O_HELD_BYTES``); its bearings are held 8 bytes a value. Each test
failed before the fix."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bomgraph.datasets import import_g2o


def _dense_run(path: Path, poses: int, landmarks: int) -> int:
    """A chain of ``poses`` poses each seeing every one of ``landmarks`` landmarks; the
    file's size."""
    with open(path, "w") as fh:
        for i in range(poses):
            fh.write(f"VERTEX_SE2 {landmarks + i} {0.1 * i} 0 0\n")
            if i:
                fh.write(f"EDGE_SE2 {landmarks + i - 1} {landmarks + i} 0.1 0 0.01 "
                         f"500 0 0 500 0 5000\n")
            fh.write("".join(f"EDGE_BEARING_SE2_XY {landmarks + i} {k} {0.001 * (k + i)} "
                             f"364.75\n" for k in range(landmarks)))
        return fh.tell()


def test_a_g2o_file_over_16_mib_of_mostly_bearings_imports(tmp_path: Path) -> None:
    path = tmp_path / "dense.g2o"
    size = _dense_run(path, 1_000, 500)
    assert size > 17 * 2**20
    stream = import_g2o(path)
    assert len(stream.steps) == 1_000
    assert all(len(s.landmark_ids) == 500 for s in stream.steps)
    last = stream.steps[-1]
    np.testing.assert_array_equal(last.landmark_ids, np.arange(500))
    assert float(last.bearings_rad[7]) == 0.001 * (7 + 999)


def test_a_repeated_bearing_is_still_refused_naming_both_lines(tmp_path: Path) -> None:
    """The bearings' checks, now over arrays, still name the first offending line."""
    import pytest

    from bomgraph.errors import DatasetError

    path = tmp_path / "rep.g2o"
    _dense_run(path, 3, 2)
    lines = path.read_text().splitlines(keepends=True)
    # line 3 is pose 2's bearing to landmark 1; repeat it after pose 3's bearings
    lines.insert(len(lines), lines[2])
    path.write_text("".join(lines))
    with pytest.raises(DatasetError, match=rf"rep\.g2o, line {len(lines)}: a second bearing "
                                           r"from pose 2 to landmark 1 \(first on line 3\)"):
        import_g2o(path)
