"""The paired comparison of arms (bomgraph.paired), against computations written apart from it:
interval coverage by Monte Carlo, the Wilcoxon p by scipy and by enumerating every sign
pattern, the bootstrap interval by a loop over resamples, pairing by run identity."""

from __future__ import annotations

import itertools
import json
import math
import random

import numpy as np
import pytest
from scipy.stats import binom, wilcoxon

from bomgraph.errors import ConfigError, PairingError
from bomgraph.experiments import Arm, Experiment
from bomgraph.jsonio import jsonable
from bomgraph.paired import (PairedConfig, default_reference, paired_comparison,
                             ratio_of_means_ci, references_for)


def _rows(exp: str, arm: str, mpe: np.ndarray, ok: np.ndarray | None = None) -> list[dict]:
    """final_by_run-like rows of one arm, runs named r00, r01, ..."""
    ok = np.ones(len(mpe), bool) if ok is None else ok
    return [{"experiment": exp, "arm": arm, "run": f"r{k:02d}", "ok": bool(o),
             "mpe_m": float(m) if o else math.nan} for k, (m, o) in enumerate(zip(mpe, ok))]


def _pair(rng: np.random.Generator, n: int, ratio: float = 1.3, spread: float = 0.3
          ) -> tuple[np.ndarray, np.ndarray]:
    """Paired MPEs [m] whose true ratio of means is ``ratio``: the reference's runs vary
    (gamma), the arm's are the reference's times an independent log-normal factor of mean
    ``ratio``."""
    b = rng.gamma(4.0, 0.01, n)
    a = b * np.exp(rng.normal(math.log(ratio) - spread ** 2 / 2, spread, n))
    return a, b


def test_the_interval_covers_the_true_ratio_of_means_about_95_percent_of_the_time() -> None:
    """400 synthetic experiments of 25 runs with a known ratio of means (1.3): the 95 %
    interval covers it in a count inside the central 99.8 % of Binomial(400, 0.95). On 4,000
    such experiments it covered 94.1 %, the plain percentile interval 92.6 % (why it is the
    expanded one); 400 cannot tell those two apart, only a badly wrong interval."""
    rng = np.random.default_rng(2024)
    rows = []
    for k in range(400):
        a, b = _pair(rng, 25)
        rows += _rows(f"e{k}", "ref", b) + _rows(f"e{k}", "arm", a)
    out = paired_comparison(rows, {f"e{k}": "ref" for k in range(400)},
                            PairedConfig(n_bootstrap=2000, seed=7))
    assert len(out) == 400 and all(r.n_pairs == 25 for r in out)
    covered = sum(r.ratio_ci_low <= 1.3 <= r.ratio_ci_high for r in out)
    low, high = binom.ppf([0.001, 0.999], 400, 0.95)
    assert low <= covered <= high, covered
    # and the interval is not trivially wide: it excludes 1 in most experiments
    assert sum(r.ratio_ci_low > 1 for r in out) > 300


def test_the_interval_is_the_loop_over_resamples_it_vectorises() -> None:
    """The (B, n) vectorised interval against one resample at a time, written out, with the
    expanded tail probability from the t quantile (scipy.stats here, scipy.special there)."""
    from scipy.stats import norm, t

    rng = np.random.default_rng(3)
    a, b = _pair(rng, 12)
    idx = rng.integers(0, 12, size=(500, 12))
    ratios = [sum(a[k] for k in row) / sum(b[k] for k in row) for row in idx]
    tail = norm.cdf(-math.sqrt(12 / 11) * t.ppf(0.975, 11))
    assert 0.01 < tail < 0.012       # 1.1 %, not the plain 2.5 %: 12 runs
    want = tuple(np.quantile(ratios, [tail, 1 - tail]))
    assert ratio_of_means_ci(a, b, idx, 0.95) == pytest.approx(want, rel=1e-12)


def _exact_signed_rank_p(d: np.ndarray) -> float:
    """Two-sided exact p of the signed-rank statistic by enumerating all 2**n sign patterns
    (no ties, no zeros)."""
    ranks = np.argsort(np.argsort(np.abs(d))) + 1
    w = ranks[d > 0].sum()
    centre = len(d) * (len(d) + 1) / 4
    all_w = [sum(r for r, s in zip(ranks, signs) if s)
             for signs in itertools.product((0, 1), repeat=len(d))]
    return float(np.mean([abs(x - centre) >= abs(w - centre) - 1e-9 for x in all_w]))


def test_the_wilcoxon_p_is_scipys_and_the_enumerated_exact_one() -> None:
    rng = np.random.default_rng(11)
    a, b = _pair(rng, 12, ratio=1.1)
    out, = paired_comparison(_rows("e", "ref", b) + _rows("e", "arm", a), {"e": "ref"})
    d = a - b  # computed here, from the arrays
    assert out.wilcoxon_p == wilcoxon(d).pvalue
    assert out.wilcoxon_p == pytest.approx(_exact_signed_rank_p(d), rel=1e-12)
    assert (out.wins, out.ties, out.losses) == (int(np.sum(d < 0)), 0, int(np.sum(d > 0)))
    assert out.ratio_median == pytest.approx(np.median(a / b), rel=1e-15)
    assert out.diff_median_m == pytest.approx(np.median(d), rel=1e-15)
    assert out.ratio_of_means == pytest.approx(a.mean() / b.mean(), rel=1e-15)


def test_ties_and_too_few_differences_give_no_p_and_say_why() -> None:
    b = np.linspace(0.01, 0.02, 8)
    same, = paired_comparison(_rows("e", "ref", b) + _rows("e", "arm", b), {"e": "ref"})
    assert same.wilcoxon_p is None and "every difference is 0" in same.note
    assert (same.wins, same.ties, same.losses) == (0, 8, 0)
    assert same.ratio_of_means == 1.0 and same.ratio_ci_low == same.ratio_ci_high == 1.0
    a = b.copy()
    a[:5] += 0.001   # 5 nonzero differences, 3 ties
    few, = paired_comparison(_rows("e", "ref", b) + _rows("e", "arm", a), {"e": "ref"})
    assert few.wilcoxon_p is None and "5 nonzero differences, needs 6" in few.note
    assert (few.wins, few.ties, few.losses) == (0, 3, 5)
    two, = paired_comparison(_rows("e", "ref", b[:2]) + _rows("e", "arm", a[:2]), {"e": "ref"})
    assert two.ratio_ci_low is None and "interval: 2 pairs, needs 5" in two.note


def _as_dicts(rows: list) -> list[dict]:
    return sorted((r.as_dict() for r in rows), key=lambda r: (r["experiment"], r["arm"]))


def test_pairing_is_by_run_not_by_row_order() -> None:
    rng = np.random.default_rng(5)
    rows = []
    for exp in ("e1", "e2"):
        a, b = _pair(rng, 15)
        c, _ = _pair(rng, 15, ratio=0.8)
        rows += _rows(exp, "ref", b) + _rows(exp, "arm", a) + _rows(exp, "other", c)
    refs = {"e1": "ref", "e2": "ref"}
    want = _as_dicts(paired_comparison(rows, refs))
    shuffled = rows.copy()
    random.Random(1).shuffle(shuffled)
    assert _as_dicts(paired_comparison(shuffled, refs)) == want  # bit for bit, interval too
    # one arm without run r04: one pair fewer, and r04 is out of both arms' means
    a = np.array([r["mpe_m"] for r in rows if r["experiment"] == "e1" and r["arm"] == "arm"])
    b = np.array([r["mpe_m"] for r in rows if r["experiment"] == "e1" and r["arm"] == "ref"])
    dropped = [r for r in shuffled if (r["experiment"], r["arm"], r["run"]) != ("e1", "arm", "r04")]
    got = {(r.experiment, r.arm): r for r in paired_comparison(dropped, refs)}
    one = got[("e1", "arm")]
    keep = np.arange(15) != 4
    assert (one.n_pairs, one.runs, one.unmatched) == (14, 15, 1)
    assert one.mean_m == pytest.approx(a[keep].mean(), rel=1e-14)
    assert one.reference_mean_m == pytest.approx(b[keep].mean(), rel=1e-14)
    assert one.wilcoxon_p == wilcoxon(a[keep] - b[keep]).pvalue
    assert got[("e1", "other")].n_pairs == 15  # the other arms keep the run


def test_failed_runs_and_runs_without_a_map_are_left_out_and_counted() -> None:
    rng = np.random.default_rng(8)
    a, b = _pair(rng, 10)
    ok = np.ones(10, bool)
    ok[2] = False                    # the arm raised on r02
    b_nomap = b.copy()
    b_nomap[6] = math.nan            # the reference had no map on r06
    rows = _rows("e", "ref", b_nomap) + _rows("e", "arm", a, ok)
    rows[6]["mpe_m"] = None          # as results.json gives it back
    out, = paired_comparison(rows, {"e": "ref"})
    keep = ~np.isin(np.arange(10), [2, 6])
    assert (out.runs, out.n_pairs, out.failed, out.unscored, out.unmatched) == (10, 8, 1, 1, 0)
    assert out.ratio_of_means == pytest.approx(a[keep].mean() / b[keep].mean(), rel=1e-14)
    assert out.wilcoxon_p == wilcoxon(a[keep] - b[keep]).pvalue


def test_the_bootstrap_is_reproducible_bit_for_bit_and_seeded() -> None:
    rng = np.random.default_rng(9)
    a, b = _pair(rng, 20)
    rows = _rows("e", "ref", b) + _rows("e", "arm", a)
    first, = paired_comparison(rows, {"e": "ref"}, PairedConfig(seed=4))
    again, = paired_comparison(rows, {"e": "ref"}, PairedConfig(seed=4))
    other, = paired_comparison(rows, {"e": "ref"}, PairedConfig(seed=5))
    assert first == again
    assert (first.ratio_ci_low, first.ratio_ci_high) != (other.ratio_ci_low, other.ratio_ci_high)
    assert first.ratio_of_means == other.ratio_of_means and first.wilcoxon_p == other.wilcoxon_p


def test_rows_are_strict_json_and_bad_input_is_refused() -> None:
    b = np.array([0.01, 0.02, math.nan])
    rows = _rows("e", "ref", b) + _rows("e", "arm", np.array([math.nan] * 3))
    out, = paired_comparison(rows, {"e": "ref"})
    assert out.n_pairs == 0 and out.mean_m is None and out.note == "no run scored by both"
    text = json.dumps(jsonable([r.as_dict() for r in paired_comparison(
        _rows("e", "ref", np.array([0.01, 0.0])) + _rows("e", "arm", np.array([0.0, 0.0])),
        {"e": "ref"})]), allow_nan=False)
    assert json.loads(text)[0]["ratio_of_means"] is None   # a mean of 0: no ratio, null
    with pytest.raises(PairingError, match="appears twice"):
        paired_comparison(rows + rows[:1], {"e": "ref"})
    with pytest.raises(PairingError, match="'nope' is not one of its arms"):
        paired_comparison(rows, {"e": "nope"})
    with pytest.raises(ConfigError, match="n_bootstrap"):
        PairedConfig(n_bootstrap=10)


def test_the_default_reference_is_the_bound_or_the_reference_arm_else_the_first() -> None:
    tri, smacof, oracle = (Arm("tri", "triangulate"), Arm("smacof", "stmds-smacof"),
                           Arm("oracle", "oracle"))
    assert default_reference(Experiment("a", "a", (tri, smacof, oracle))) == "oracle"
    assert default_reference(Experiment("b", "b", (tri, smacof))) == "tri"
    assert default_reference(Experiment("c", "c", (tri, smacof, oracle),
                                        reference=Arm("smacof", "stmds-smacof"))) == "smacof"
    exps = [Experiment("a", "a", (tri, smacof, oracle)), Experiment("b", "b", (tri, smacof))]
    assert references_for(exps, "smacof") == {"a": "smacof", "b": "smacof"}
    assert references_for(exps, "oracle") == {"a": "oracle", "b": "tri"}
    with pytest.raises(ConfigError, match="'ekf' is not an arm of any experiment"):
        references_for(exps, "ekf")


def test_compare_writes_paired_csv_and_prints_the_table(tmp_path, capsys) -> None:
    """End to end through the command line: six short simulated streams, three methods, the
    oracle as the default reference; then the same runs (from the cache) paired against
    another arm, and an arm that is none refused before anything runs."""
    import csv

    from bomgraph.cli import main

    streams = []
    for seed in range(6):
        streams.append(str(tmp_path / f"s{seed}.jsonl"))
        assert main(["simulate", "--seed", str(seed), "--steps", "40", "--landmarks", "15",
                     "--out", streams[-1]]) == 0
    out = tmp_path / "out"
    cmd = ["compare", "--streams", *streams, "--methods", "triangulate,stmds-smacof,oracle",
           "--jobs", "1", "--no-figures", "--no-progress", "--out", str(out)]
    capsys.readouterr()
    assert main(cmd) == 0
    printed = capsys.readouterr().out
    assert "paired against oracle" in printed
    with open(out / "paired.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["arm"], r["reference"], r["n_pairs"]) for r in rows] == [
        ("triangulate", "oracle", "6"), ("stmds-smacof", "oracle", "6")]
    assert all(float(r["ratio_ci_low"]) <= float(r["ratio_of_means"]) <= float(r["ratio_ci_high"])
               for r in rows)

    def refuse(token: str) -> None:
        raise AssertionError(f"results.json holds the non-JSON constant {token}")

    data = json.loads((out / "results.json").read_text(), parse_constant=refuse)
    assert [r["arm"] for r in data["paired"]["rows"]] == ["triangulate", "stmds-smacof"]
    assert data["paired"]["rows"][0]["ratio_of_means"] == float(rows[0]["ratio_of_means"])
    manifest = json.loads((out / ".bomgraph-compare-files").read_text())
    assert "paired.csv" in [f["path"] for f in manifest["files"]]

    assert main(cmd + ["--paired-reference", "triangulate"]) == 0
    with open(out / "paired.csv", newline="") as fh:
        assert [(r["arm"], r["reference"]) for r in csv.DictReader(fh)] == [
            ("stmds-smacof", "triangulate"), ("oracle", "triangulate")]
    assert main(cmd + ["--paired-reference", "ekf"]) == 2
    assert "'ekf' is not an arm of any experiment" in capsys.readouterr().err
    # --dry-run refuses it too (it ran the plan before)
    assert main(cmd + ["--paired-reference", "ekf", "--dry-run"]) == 2
    assert "'ekf' is not an arm of any experiment" in capsys.readouterr().err


def test_run_ids_of_mixed_types_pair_without_a_traceback() -> None:
    """Rows from the Python API may name runs by int in one arm and str in another (a raw
    TypeError from sorting them before); they pair by equality, as given."""
    from bomgraph.paired import paired_comparison

    rows = ([{"experiment": "e", "arm": "a", "run": k, "ok": True, "mpe_m": 0.02} for k in
             range(3)] + [{"experiment": "e", "arm": "b", "run": str(k), "ok": True,
                           "mpe_m": 0.01} for k in range(3)])
    (row,) = paired_comparison(rows, {"e": "a"})
    assert row.n_pairs == 0 and row.unmatched == 6


def test_an_unbounded_interval_is_none_with_a_note_in_csv_and_json_alike() -> None:
    """With the reference's MPE exactly 0 on 4 of 6 runs, about 9 % of the resamples have a
    reference mean of 0 and an infinite ratio: the interval's upper end was ``inf``, written
    as inf in paired.csv and as null in results.json. Now both ends are None and the note
    says why."""
    from bomgraph.paired import paired_comparison

    mpe_ref = [0.0, 0.0, 0.0, 0.0, 0.01, 0.02]
    rows = ([{"experiment": "e", "arm": "ref", "run": f"r{k}", "ok": True, "mpe_m": v}
             for k, v in enumerate(mpe_ref)]
            + [{"experiment": "e", "arm": "a", "run": f"r{k}", "ok": True, "mpe_m": 0.01}
               for k in range(6)])
    (row,) = paired_comparison(rows, {"e": "ref"})
    assert row.n_pairs == 6 and row.ratio_of_means == pytest.approx(0.01 / 0.005)
    assert row.ratio_ci_low is None and row.ratio_ci_high is None
    assert "unbounded" in row.note


@pytest.mark.parametrize("n, chunk", [(25, 50), (25, 77), (400, 1 << 20), (12, 1)])
def test_the_resamples_drawn_in_chunks_give_the_interval_of_one_draw(
        n: int, chunk: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """paired_comparison draws the resamples in chunks of RESAMPLE_CHUNK // n (at least one
    resample a chunk): the bits of the one (n_bootstrap, n) draw it made before (h41)."""
    from bomgraph import paired

    a, b = _pair(np.random.default_rng(n), n)
    rows = _rows("e", "ref", b) + _rows("e", "arm", a)
    config = PairedConfig(n_bootstrap=1001, seed=11)
    idx = paired._pair_rng(config, "e", "arm", "ref").integers(0, n, size=(1001, n))
    order = sorted(range(n), key=lambda k: f"r{k:02d}")  # the runs in the order of their names
    want = ratio_of_means_ci(a[order], b[order], idx, config.confidence)
    monkeypatch.setattr(paired, "RESAMPLE_CHUNK", chunk)
    (row,) = paired_comparison(rows, {"e": "ref"}, config)
    assert (row.ratio_ci_low, row.ratio_ci_high) == want


def test_the_bootstrap_memory_is_bounded_by_the_chunk_not_the_runs() -> None:
    """2,000 runs and 10,000 resamples drew a (10,000, 2,000) index array and gathered two
    more of that shape (160 MB each; 330 MB peak measured); now a chunk of about
    RESAMPLE_CHUNK values at a time, whatever the runs (h41)."""
    import tracemalloc

    from bomgraph import paired

    a, b = _pair(np.random.default_rng(0), 400)
    rows = _rows("e", "ref", b) + _rows("e", "arm", a)
    paired_comparison(rows[:10] + rows[400:410], {"e": "ref"})  # scipy imported first
    tracemalloc.start()
    try:
        (row,) = paired_comparison(rows, {"e": "ref"}, PairedConfig(n_bootstrap=10_000))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert row.ratio_ci_low is not None
    whole = 3 * 10_000 * 400 * 8  # the draw and its two gathers, at once
    assert peak < 4 * paired.RESAMPLE_CHUNK * 8 < whole / 2, (peak, whole)
