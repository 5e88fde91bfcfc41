"""scripts/bench_finish.py: the paired runs with and without ``finish()``."""

from __future__ import annotations

import json
from pathlib import Path

from _scripts import load_script  # noqa: E402  (tests/_scripts.py)

bench = load_script("bench_finish")


def test_a_short_run_is_the_same_with_and_without_finish(tmp_path: Path) -> None:
    """120 steps never reach the long mode (500): both variants give the same map and cost,
    the JSON holds every run and one summary row per method and variant."""
    out = tmp_path / "f.json"
    assert bench.main(["--steps", "120", "--methods", "gtsam-batch,gtsam-isam2",
                       "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["steps"] == 121 and len(data["rows"]) == 4 and len(data["summary"]) == 4
    by = {(r["method"], r["finish"]): r for r in data["summary"]}
    assert by["gtsam-batch", True]["mpe_cm"] == by["gtsam-batch", False]["mpe_cm"]
    assert by["gtsam-batch", True]["cost"] == by["gtsam-batch", False]["cost"]
    assert by["gtsam-isam2", True]["mpe_cm"] == by["gtsam-isam2", False]["mpe_cm"]
    assert by["gtsam-isam2", True]["cost"] is None and by["gtsam-batch", True]["converged"]
