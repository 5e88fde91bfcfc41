"""scripts/check_rounding.py: a method's final map as is and with rounding-level bearing
moves."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from bomgraph.evaluate import score_estimate
from bomgraph.mapper import create_mapper, run
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream

from _scripts import load_script  # noqa: E402  (tests/_scripts.py)

check = load_script("check_rounding")


def test_perturbed_moves_only_the_bearings_by_about_eps() -> None:
    s = simulate(SimConfig(n_steps=30), np.random.default_rng(0))
    moved = check.perturbed(s.steps, 1e-9, 1)
    assert len(moved) == len(s.steps)
    d = np.concatenate([m.bearings_rad - st.bearings_rad for m, st in zip(moved, s.steps)])
    assert 0 < np.abs(d).max() < 1e-8 and np.abs(d).mean() > 1e-10
    for m, st in zip(moved, s.steps):
        assert m.t == st.t and np.array_equal(m.landmark_ids, st.landmark_ids)
        assert np.array_equal(m.odom, st.odom)
    again = check.perturbed(s.steps, 1e-9, 1)          # seeded: the same draw
    assert all(np.array_equal(a.bearings_rad, b.bearings_rad) for a, b in zip(moved, again))


def test_main_reports_the_unperturbed_run_and_each_draw(tmp_path: Path, capsys) -> None:
    s = simulate(SimConfig(n_steps=60), np.random.default_rng(4))
    path = tmp_path / "s.jsonl"
    write_stream(s, path)
    out = tmp_path / "r.json"
    assert check.main([str(path), "--method", "stmds-smacof", "--draws", "2", "--jobs", "1",
                       "--out", str(out)]) == 0
    rows = json.loads(out.read_text())["rows"]
    assert [(r["eps"], r["seed"]) for r in rows] == [(0.0, 0), (1e-12, 1), (1e-12, 2)]
    direct = run(create_mapper("stmds-smacof", s.header), s.steps).final
    assert rows[0]["mpe_cm"] == 100 * score_estimate(direct, s.truth).mpe_m
    assert "streams moved by more than 1%" in capsys.readouterr().out
