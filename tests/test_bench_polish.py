"""scripts/bench_polish.py: the run list and the two-tree summary (issue 14)."""

from __future__ import annotations

from _scripts import load_script  # tests/_scripts.py

bench = load_script("bench_polish")


def _row(tree: str, run: str, cpu: float, hashes: list[str], mpe: list[float]) -> dict:
    return {"tree": tree, "method": "gtsam-isam2", "run": run, "cpu_s": cpu, "polish_s": cpu / 2,
            "polish_calls": 3, "linearize": 6, "t": [10, 20, 30], "mpe_m": mpe,
            "hashes": hashes, "converged": True}


def test_runs_are_read_as_ranges_and_lists() -> None:
    assert bench.parse_runs("0-2,5") == [0, 1, 2, 5]
    assert bench.parse_runs("7") == [7]


def test_summary_pairs_the_trees_run_by_run() -> None:
    mpe = [0.02, 0.015, 0.01]
    rows = [_row("/a", "r0", 2.0, ["h1", "h2", "h3"], mpe),
            _row("/a", "r0", 4.0, ["h1", "h2", "h3"], mpe),
            _row("/b", "r0", 1.5, ["h1", "h2", "h3"], mpe),
            _row("/b", "r0", 1.5, ["h1", "h2", "h3"], mpe),
            _row("/a", "r1", 2.0, ["g1", "g2", "g3"], mpe),
            _row("/b", "r1", 2.0, ["g1", "g2", "x3"], [0.02, 0.015, 0.0101])]
    text = bench.summary(rows, ["/a", "/b"]).splitlines()
    assert len(text) == 2 and text[0].startswith("gtsam-isam2") and "/a:" in text[0]
    # medians: /a 3.0 + 2.0, /b 1.5 + 2.0; ratios 0.5 and 1.0
    assert "cpu    5.00 s" in text[0] and "cpu    3.50 s" in text[1]
    assert "x0.750" in text[1]
    assert "identical 2/2" in text[0] and "identical 1/2" in text[1]
    assert "worst MPE change 1.00e-02" in text[1]
