"""scripts/bench_sigma_sim.py: a method's final map with the header's bearing sigma halved
and doubled on simulated streams."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from bomgraph.evaluate import score_estimate
from bomgraph.mapper import create_mapper, run

from _scripts import load_script  # noqa: E402  (tests/_scripts.py)

sig = load_script("bench_sigma_sim")


def test_worlds_are_reproducible_and_sparse_is_recording_like() -> None:
    a, b = sig.world_stream("sparse", 0, 120), sig.world_stream("sparse", 0, 120)
    assert len(a.steps) == 121
    assert all(np.array_equal(x.bearings_rad, y.bearings_rad) for x, y in zip(a.steps, b.steps))
    per_step = np.mean([len(s.landmark_ids) for s in a.steps])
    assert 0.5 < per_step < 5                     # a few bearings a step, as the MRCLAM imports
    assert len(sig.world_stream("paper", 1, 40).steps) == 41
    assert not np.array_equal(sig.world_stream("sparse", 1, 40).truth.landmarks_xy,
                              a.truth.landmarks_xy)


def test_one_run_changes_only_the_stated_sigma() -> None:
    stream = sig.world_stream("paper", 0, 60)
    row = sig.one("paper", 0, "gtsam-batch", "paper", 1.0, 60)
    final = run(create_mapper("gtsam-batch", stream.header, preset="paper"), stream.steps,
                checkpoint_every=10).final
    assert math.isclose(row["mpe_cm"], 100 * score_estimate(final, stream.truth).mpe_m,
                        rel_tol=0, abs_tol=1e-12)
    # the same run with the sigma doubled is another map: the scale reaches the method
    doubled = sig.one("paper", 0, "gtsam-batch", "paper", 2.0, 60)
    assert doubled["mpe_cm"] != row["mpe_cm"] and doubled["mapped"] > 0


def test_summary_ratios_against_a_hand_count() -> None:
    rows = [{"world": "w", "preset": "p", "method": "m", "run": k, "scale": s, "mpe_cm": v,
             "mapped": 5}
            for k, vals in enumerate([(2.0, 4.0, 8.0), (3.0, 2.0, 1.0)])
            for s, v in zip(sig.SCALES, vals)]
    (s,) = sig.summarise(rows)
    assert s["mean_mpe_cm"] == {"0.5": 2.5, "1.0": 3.0, "2.0": 4.5}
    assert math.isclose(s["mean_ratio"]["0.5"], 2.5 / 3.0)
    assert math.isclose(s["mean_ratio"]["2.0"], 1.5)
    # per run, either way: run 0 x0.5 is 0.5 (2x), run 1 x2 is 0.5 (2x), run 0 x2 is 2x
    assert s["worst_run_ratio"] == {"0.5": 2.0, "2.0": 2.0}


def test_main_writes_every_run(tmp_path: Path, capsys) -> None:
    out = tmp_path / "s.json"
    assert sig.main(["--runs", "1", "--worlds", "sparse", "--methods", "stmds-smacof",
                     "--jobs", "1", "--steps", "150", "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert sorted(r["scale"] for r in data["rows"]) == [0.5, 1.0, 2.0]
    assert all(r["preset"] == "real" and r["mapped"] > 0 for r in data["rows"])
    assert "sparse  real   stmds-smacof" in capsys.readouterr().out
