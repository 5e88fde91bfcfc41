"""The EKF option benchmarks (``bench_ekf_robust.py``, ``bench_variance_scale.py``,
``bench_ekf_range.py``, sharing ``_ekf_options.py``) end to end on small simulated streams named
as the generality imports are: every run is written, the threshold is chosen on the selection
family alone, and the README's oracle column is read."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from _scripts import ROOT, load_script

from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream


@pytest.fixture(scope="module")
def streams(tmp_path_factory) -> Path:
    """m6_r1..r5 and m1_r1..r5: 40-step simulated streams (the names are all that matters)."""
    folder = tmp_path_factory.mktemp("gen")
    for i, name in enumerate([f"{f}_r{r}" for f in ("m6", "m1") for r in range(1, 6)]):
        s = simulate(SimConfig(n_steps=40, n_landmarks=12), np.random.default_rng(100 + i))
        write_stream(s, folder / f"{name}.jsonl")
    return folder


def test_oracle_table_reads_the_readme_generality_table() -> None:
    table = load_script("bench_variance_scale").oracle_table(ROOT / "README.md")
    assert len(table) == 20                                  # the MRCLAM6 streams have truth
    assert all(k.startswith("m6") for k in table) and all(v > 0 for v in table.values())


def test_ekf_robust_chooses_on_the_selection_family_only(streams: Path, tmp_path: Path,
                                                        capsys) -> None:
    load_script("bench_variance_scale")                      # the oracle table's module
    mod = load_script("bench_ekf_robust")
    out = tmp_path / "r.json"
    assert mod.main([str(streams), "--jobs", "1", "--ks", "1.5,3", "--families", "m6,m1",
                     "--out", str(out)]) == 0
    got = json.loads(out.read_text())
    rows = got["rows"]
    # selection: 5 streams x 2 methods x (off + 2 k); then m1: 5 x 2 x (off + chosen)
    assert len(rows) == 5 * 2 * 3 + 5 * 2 * 2
    m1_ks = {(r["method"], r["k"]) for r in rows if r["stream"].startswith("m1")}
    for m in ("ekf", "ekf-invdepth"):
        sums = {k: sum(r["mpe_cm"] for r in rows if r["method"] == m and r["k"] == k
                       and r["stream"].startswith("m6")) for k in (1.5, 3.0)}
        assert got["chosen"][m] == min(sums, key=sums.__getitem__)
        assert m1_ks >= {(m, None), (m, got["chosen"][m])}
    assert all(np.isfinite(r["mpe_cm"]) for r in rows)
    assert "chosen k:" in capsys.readouterr().out


def test_variance_scale_runs_every_stream_both_ways(streams: Path, tmp_path: Path) -> None:
    mod = load_script("bench_variance_scale")
    out = tmp_path / "v.json"
    assert mod.main([str(streams), "--jobs", "1", "--families", "m1", "--out", str(out)]) == 0
    rows = json.loads(out.read_text())["rows"]
    assert {(r["stream"], r["method"], r["mode"]) for r in rows} == {
        (f"m1_r{r}", m, o) for r in range(1, 6) for m in ("ekf", "ekf-invdepth")
        for o in ("fixed", "innovation")}
    assert all(r["scale"] >= 1.0 for r in rows if r["mode"] == "innovation")


def test_ekf_range_runs_every_variant_and_the_shared_run(streams: Path, tmp_path: Path,
                                                         capsys) -> None:
    """``bench_ekf_range.py``: the selection family under the four header ranges, the other at
    the stated one; each row is what the shared scored run gives for that header."""
    mod = load_script("bench_ekf_range")
    out = tmp_path / "g.json"
    assert mod.main([str(streams), "--jobs", "1", "--families", "m6,m1",
                     "--out", str(out)]) == 0
    rows = json.loads(out.read_text())
    keys = {(r["stream"], r["method"], r["prior"], r["variant"]) for r in rows}
    assert len(rows) == len(keys) == 5 * 2 * 2 * 4 + 5 * 2 * 2
    assert {v for s, _, _, v in keys if s.startswith("m1")} == {"as is"}
    shared = load_script("_ekf_options")
    path = str(streams / "m6_r2.jsonl")
    ref = shared.scored_run(path, "ekf-invdepth", {"preset": "real", "rho_prior": "range"},
                            {"sensor_range_m": None})
    row = next(r for r in rows if (r["stream"], r["method"], r["prior"], r["variant"])
               == ("m6_r2", "ekf-invdepth", "range", "None"))
    assert (row["mpe_cm"], row["mapped"]) == (ref["mpe_cm"], ref["mapped"])
    assert ref["info"]["rho_prior_from"] != "sensor_range_m"      # the header's range is gone
    assert "worst" in capsys.readouterr().out
