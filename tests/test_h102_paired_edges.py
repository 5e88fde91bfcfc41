"""The paired comparison at its edges (h102's mutation audit): zero differences beside
nonzero ones, a failed and an unmatched run in one pair, the default reference among three
arms, exactly the fewest pairs for an interval and for a p-value, and each arm's own
bootstrap stream. Each of these was changed in bomgraph.paired and test_paired passed."""

from __future__ import annotations

import itertools
import math

import numpy as np

from bomgraph.paired import MIN_NONZERO_WILCOXON, MIN_PAIRS_CI, paired_comparison


def _rows(arm: str, mpe: list[float], ok: list[bool] | None = None, skip: int = -1) -> list[dict]:
    ok = ok or [True] * len(mpe)
    return [{"experiment": "e", "arm": arm, "run": f"r{k}", "ok": o, "mpe_m": m}
            for k, (m, o) in enumerate(zip(mpe, ok)) if k != skip]


def _exact_p(d: np.ndarray) -> float:
    """Two-sided exact signed-rank p over every sign pattern (no ties, no zeros)."""
    ranks = np.argsort(np.argsort(np.abs(d))) + 1
    w, centre = ranks[d > 0].sum(), len(d) * (len(d) + 1) / 4
    all_w = [sum(r for r, s in zip(ranks, signs) if s)
             for signs in itertools.product((0, 1), repeat=len(d))]
    return float(np.mean([abs(x - centre) >= abs(w - centre) - 1e-9 for x in all_w]))


REF = [0.10, 0.20, 0.30, 0.40, 0.50, 0.60, 0.70, 0.80, 0.90]


def test_zero_differences_are_dropped_before_the_exact_test() -> None:
    """Two ties and seven differences 0.011, -0.022, ...: the p of the seven, exactly."""
    d = np.array([0.0, 0.011, -0.022, 0.033, 0.0, 0.044, 0.055, -0.066, 0.077])
    out, = paired_comparison(_rows("ref", REF) + _rows("arm", list(np.add(REF, d))))
    assert out.ties == 2
    assert math.isclose(out.wilcoxon_p, _exact_p(d[d != 0]), rel_tol=1e-12)


def test_a_failed_run_and_an_unmatched_run_are_counted_apart() -> None:
    ok = [True] * 9
    ok[2] = False
    rows = _rows("ref", REF, skip=5) + _rows("arm", REF, ok=ok)
    out, = paired_comparison(rows)
    assert (out.runs, out.n_pairs, out.failed, out.unscored, out.unmatched) == (9, 7, 1, 0, 1)


def test_the_default_reference_is_the_first_arm_of_the_rows() -> None:
    rows = _rows("b", REF) + _rows("a", REF) + _rows("c", REF)
    assert [(r.arm, r.reference) for r in paired_comparison(rows)] == [("a", "b"), ("c", "b")]


def test_the_fewest_pairs_give_an_interval_and_a_p_value() -> None:
    n = max(MIN_PAIRS_CI, MIN_NONZERO_WILCOXON)
    assert (MIN_PAIRS_CI, MIN_NONZERO_WILCOXON) == (5, 6)
    five, = paired_comparison(_rows("ref", REF[:5]) + _rows("arm", [m * 1.1 for m in REF[:5]]))
    assert five.n_pairs == 5 and five.ratio_ci_low is not None and five.ratio_ci_high is not None
    six, = paired_comparison(_rows("ref", REF[:n])
                             + _rows("arm", [m + 0.001 * (k + 1) * (-1) ** k
                                             for k, m in enumerate(REF[:n])]))
    assert six.wilcoxon_p is not None


def test_each_arm_draws_its_own_bootstrap() -> None:
    """PairedConfig: each pair draws from a stream of the seed and the experiment's and both
    arms' names: two arms with the same runs get intervals from different resamples."""
    arm = [m * (1.0 + 0.3 * math.sin(7 * k)) for k, m in enumerate(REF)]
    b, c = paired_comparison(_rows("ref", REF) + _rows("b", arm) + _rows("c", arm))
    assert b.ratio_of_means == c.ratio_of_means
    assert (b.ratio_ci_low, b.ratio_ci_high) != (c.ratio_ci_low, c.ratio_ci_high)


def test_a_huge_ratio_is_shown_in_exponent_form_in_its_column() -> None:
    """h152: against a plugin bound that returns the truth (errors of 1e-16 m) the printed
    table showed ``896680534985135.25 1537981266303791.50``, overrunning its columns."""
    from bomgraph.paired import format_paired

    out, = paired_comparison(_rows("bound", [1e-16 * (1 + k) for k in range(9)])
                             + _rows("mine", REF))
    assert out.ratio_of_means > 1e9
    line = next(ln for ln in format_paired([out]).splitlines() if ln.startswith("mine "))
    assert f"{out.ratio_of_means:.3e}" in line and f"{out.ratio_median:.3e}" in line, line
    assert not any(len(tok) > 12 and "." in tok and "e" not in tok for tok in line.split()), line
    # h154: so did a ratio of 1e6 to 1e9 (below the 1e9 from which tables use exponents):
    # "100000000.00" in the 9-character column of the median ratio
    out, = paired_comparison(_rows("bound", [1e-9 * (1 + k) for k in range(9)])
                             + _rows("mine", REF))
    line = next(ln for ln in format_paired([out]).splitlines() if ln.startswith("mine "))
    assert 1e6 <= out.ratio_median < 1e9 and f"{out.ratio_median:.3e}" in line, line
    assert not any(len(tok.strip("[],")) > 9 for tok in line.split()[2:]), line
