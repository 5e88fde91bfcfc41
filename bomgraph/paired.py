"""Paired comparison of two arms of an experiment (paper section IV's comparisons, run for run).

Every arm of an experiment runs on the same runs (the same seeds, or the same stream files),
so two arms are compared run by run: over the runs where both have a finite final landmark
MPE, the ratio of their mean MPEs with a bootstrap confidence interval that resamples runs
jointly, the median of the per-run ratios and differences, wins / ties / losses and the
Wilcoxon signed-rank p-value of the differences.

Input rows are those of :func:`bomgraph.summaries.final_by_run` (``experiment``, ``arm``,
``run``, ``ok``, ``mpe_m``); :func:`paired_comparison` is pure (no files, no printing) and
:func:`format_paired` renders its rows for the command line.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import asdict, dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from .checks import instance, integer, real
from .errors import ConfigError, PairingError, UnknownMethodError
from .experiments import Experiment
from .mapper import method_info
from .run_scoring import self_scored, self_scored_arms
from .tables import fixed_or_exponent

#: Fewest pairs for a confidence interval: below it the bootstrap has too few distinct
#: resamples to mean anything (2 runs have 3).
MIN_PAIRS_CI = 5
#: Fewest nonzero differences for a Wilcoxon p-value: with 5 the exact two-sided p is at least
#: 2 / 2**5 = 0.0625 whatever the data, so the test cannot tell anything apart.
MIN_NONZERO_WILCOXON = 6
#: Resampled run indices drawn at once by :func:`paired_comparison` (resamples of ``n`` runs
#: in chunks of ``RESAMPLE_CHUNK // n``): the whole ``(n_bootstrap, n)`` draw and its two
#: gathers held 24 bytes a resample and run (peak 330 MB for 2,000 runs, 10,000 resamples;
#: now 37 MB, most of it scipy's import); the chunks draw the same stream, so the interval
#: is the same bits (h41: 25, 400 and 2,000 runs).
RESAMPLE_CHUNK = 1 << 20


@dataclass(frozen=True)
class PairedConfig:
    """How the paired statistics are computed.

    Attributes
    ----------
    n_bootstrap : int
        Bootstrap resamples of the runs per pair of arms.
    confidence : float
        Coverage of the interval of the ratio of means, in (0, 1).
    seed : int
        Seed of the bootstrap; each pair of arms draws from its own stream, derived from the
        seed and the experiment's and both arms' names, so a pair's interval does not depend
        on the other arms or on the order of the rows.
    """

    n_bootstrap: int = 10_000
    confidence: float = 0.95
    seed: int = 0

    def __post_init__(self) -> None:
        integer(self.n_bootstrap, "PairedConfig.n_bootstrap", ConfigError, minimum=100)
        c = real(self.confidence, "PairedConfig.confidence", ConfigError)
        if not 0 < c < 1:
            raise ConfigError(f"PairedConfig.confidence must be in (0, 1), got {c}")
        integer(self.seed, "PairedConfig.seed", ConfigError)


@dataclass(frozen=True)
class PairedRow:
    """One arm against its experiment's reference arm, over the runs both scored.

    ``runs``: runs either arm has a row for; of these, ``failed`` were left out because
    either arm raised, ``unscored`` because either had no finite final MPE (no map, or
    nothing to score it by), ``unmatched`` because only one arm ran them; ``n_pairs`` remain.
    Statistics that cannot be computed are None, and ``note`` says why. Lower MPE wins:
    ``wins`` counts runs where the arm's MPE is below the reference's.
    """

    experiment: str
    arm: str
    reference: str
    runs: int
    n_pairs: int
    failed: int
    unscored: int
    unmatched: int
    mean_m: float | None
    reference_mean_m: float | None
    ratio_of_means: float | None
    ratio_ci_low: float | None
    ratio_ci_high: float | None
    ratio_median: float | None
    diff_median_m: float | None
    wins: int
    ties: int
    losses: int
    wilcoxon_p: float | None
    note: str

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def ratio_of_means_ci(a: np.ndarray, b: np.ndarray, idx: np.ndarray, confidence: float
                      ) -> tuple[float, float]:
    """Expanded percentile bootstrap interval of ``mean(a) / mean(b)`` (Hesterberg, "What
    teachers should know about the bootstrap", The American Statistician 69, 2015).

    The plain percentile interval of the resampled ratios is too narrow on a few runs (it
    takes the spread with divisor n, and normal quantiles); the expanded one reads the
    resampled ratios at the tail probability ``Phi(-sqrt(n / (n - 1)) t_{n-1})`` instead of
    ``(1 - confidence) / 2``. On 4,000 simulated experiments of 25 runs (log-normal per-run
    ratios, 2,000 resamples) a nominal 95 % covered 94.1 %, the plain percentile 92.6 %; a
    studentized (bootstrap-t) interval covered 94.6 % there, but on the paper's runs, where
    ``gtsam-batch`` is within 0.06 mm of the oracle on 23 runs and 5 mm off on 2, it gave
    [1.00, 47] for a ratio of 1.04 (resamples without those two have no spread), this one
    [1.00, 1.11]. ``tests/test_paired.py`` checks the coverage on 400 experiments.

    Parameters
    ----------
    a, b : ndarray, shape ``(n,)``
        Paired values, ``n >= 2`` (MPE [m] of the arm and of the reference, per run), with
        ``mean(b) > 0``.
    idx : ndarray of int, shape ``(B, n)``
        Bootstrap resamples: row k picks the runs of resample k (``a`` and ``b`` together).
    confidence : float
        Coverage, in (0, 1).

    Returns
    -------
    (low, high) : the interval's ends (both the ratio itself when ``a`` is ``b`` times a
        constant: no spread to resample).
    """
    return _expanded_interval(_resampled_ratios(a, b, idx), a.shape[0], confidence)


def _resampled_ratios(a: np.ndarray, b: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """``mean(a) / mean(b)`` of each resample (row) of ``idx``, shape ``(len(idx),)``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return a[idx].mean(axis=1) / b[idx].mean(axis=1)


def _expanded_interval(ratios: np.ndarray, n: int, confidence: float) -> tuple[float, float]:
    """:func:`ratio_of_means_ci` from the resampled ratios of ``n`` pairs."""
    from scipy.special import ndtr, stdtrit

    tail = float(ndtr(-math.sqrt(n / (n - 1)) * stdtrit(n - 1, (1 + confidence) / 2)))
    with np.errstate(invalid="ignore"):    # inf - inf between infinite ratios: NaN, no end
        low, high = np.quantile(ratios[~np.isnan(ratios)], [tail, 1 - tail])
    return float(low), float(high)


def wilcoxon_p(diff: np.ndarray) -> tuple[float | None, str]:
    """Two-sided Wilcoxon signed-rank p-value of paired differences ``(n,)`` and, when there
    is none, why. Zero differences (ties between the arms) are dropped first, as scipy's
    default ``zero_method="wilcox"`` does; scipy chooses the exact or the normal method."""
    nonzero = diff[diff != 0]
    if diff.size and not nonzero.size:
        return None, "Wilcoxon: every difference is 0"
    if nonzero.size < MIN_NONZERO_WILCOXON:
        return None, (f"Wilcoxon: {nonzero.size} nonzero differences, needs "
                      f"{MIN_NONZERO_WILCOXON}")
    from scipy.stats import wilcoxon  # here: scipy.stats takes a while to import

    return float(wilcoxon(nonzero).pvalue), ""


def _pair_rng(config: PairedConfig, experiment: str, arm: str, reference: str
              ) -> np.random.Generator:
    """The bootstrap's generator of one pair: the seed and a hash of the three names."""
    digest = hashlib.sha256("\0".join((experiment, arm, reference)).encode()).digest()
    return np.random.default_rng([config.seed, int.from_bytes(digest[:8], "little")])


def _pair_row(experiment: str, arm: str, reference: str, mine: Mapping[str, Mapping],
              ref: Mapping[str, Mapping], config: PairedConfig) -> PairedRow:
    # sorted (by name, so ids of mixed types from the Python API compare): the pairs' order
    # is the runs', not the rows'
    runs = sorted(set(mine) | set(ref), key=str)
    both = [r for r in runs if r in mine and r in ref]
    ran = [r for r in both if mine[r]["ok"] and ref[r]["ok"]]
    own = {(name, kind): sum(_own_kind(rs[r]) == kind for r in ran)
           for name, rs in ((reference, ref), (arm, mine)) for kind in ("itself", "method")}
    a = np.array([_mpe(mine[r]) for r in ran], dtype=float)
    b = np.array([_mpe(ref[r]) for r in ran], dtype=float)
    keep = np.isfinite(a) & np.isfinite(b)
    a, b = a[keep], b[keep]
    n = int(a.size)
    notes = []
    d = a - b
    stats: dict[str, Any] = dict.fromkeys(("mean_m", "reference_mean_m", "ratio_of_means",
                                           "ratio_ci_low", "ratio_ci_high", "ratio_median",
                                           "diff_median_m"))
    if n == 0:
        notes.append("no run scored by both")
    else:
        stats.update(mean_m=float(a.mean()), reference_mean_m=float(b.mean()),
                     diff_median_m=float(np.median(d)))
        pos = b > 0
        if pos.any():
            stats["ratio_median"] = float(np.median(a[pos] / b[pos]))
        if a.mean() > 0 and b.mean() > 0:
            stats["ratio_of_means"] = float(a.mean() / b.mean())
        else:
            notes.append("a mean MPE of 0: no ratio")
    notes += [(f"{name} is the --reference, scored against its own map" if kind == "itself"
               else f"{name} runs the --reference's method and options at another "
                    f"checkpoint cadence: scored against that run's map, its own but for the "
                    f"cadence,")
              + f" on {k} of {len(ran)} runs (no truth): no pair there" + (
                  " (the other arms are scored against its map: pair them with one another, "
                  "--paired-reference ARM)" if name == reference and k == len(ran) else "")
              for (name, kind), k in own.items() if k]
    if stats["ratio_of_means"] is not None and n < MIN_PAIRS_CI:
        notes.append(f"interval: {n} pairs, needs {MIN_PAIRS_CI}")
    elif stats["ratio_of_means"] is not None:
        rng, ratios = _pair_rng(config, experiment, arm, reference), []
        rows = max(RESAMPLE_CHUNK // n, 1)
        for start in range(0, config.n_bootstrap, rows):  # as one (n_bootstrap, n) draw
            k = min(rows, config.n_bootstrap - start)
            ratios.append(_resampled_ratios(a, b, rng.integers(0, n, size=(k, n))))
        low, high = _expanded_interval(np.concatenate(ratios), n, config.confidence)
        if math.isfinite(low) and math.isfinite(high):
            stats["ratio_ci_low"], stats["ratio_ci_high"] = low, high
        else:   # resamples of only the runs where the reference scored 0: no upper end
            notes.append("interval: unbounded (the reference's MPE is 0 on too many runs)")
    p, why = wilcoxon_p(d) if n else (None, "")
    notes += [why] if why else []
    return PairedRow(experiment, arm, reference, runs=len(runs), n_pairs=n,
                     failed=len(both) - len(ran),
                     unscored=len(ran) - n, unmatched=len(runs) - len(both),
                     **stats, wins=int(np.sum(d < 0)), ties=int(np.sum(d == 0)),
                     losses=int(np.sum(d > 0)), wilcoxon_p=p, note="; ".join(notes))


def _own_kind(row: Mapping[str, Any]) -> str:
    """A row's ``own_map``: ``"itself"``, ``"method"`` or ``""`` (True, as a caller's rows
    may have it: ``"itself"``)."""
    kind = row.get("own_map") or ""
    return "itself" if kind is True else str(kind)


def _mpe(row: Mapping[str, Any]) -> float:
    v = row.get("mpe_m")
    return math.nan if v is None else float(v)


def paired_comparison(rows: Sequence[Mapping[str, Any]],
                      references: Mapping[str, str] | None = None,
                      config: PairedConfig = PairedConfig()) -> list[PairedRow]:
    """Every arm of every experiment against the experiment's reference arm, run by run.

    Parameters
    ----------
    rows : sequence of mapping
        One per (experiment, arm, run), as :func:`bomgraph.summaries.final_by_run` makes them:
        ``experiment``, ``arm``, ``run``, ``ok`` and the final ``mpe_m`` [m] (NaN or None:
        no score), and ``own_map`` for a run scored against its own final map (its
        ``mpe_m`` is then no score: :func:`pairable`): ``"itself"``, the reference's own
        run, or ``"method"``, an arm of its method and options at another cadence (True:
        ``"itself"``). Their order does not matter.
    references : mapping, optional
        Experiment name -> the label of its reference arm; an experiment not named here is
        compared against its first arm (in the order of the rows).
    config : PairedConfig
        Bootstrap resamples, confidence and seed.

    Returns
    -------
    list of PairedRow
        Per experiment (in order of appearance), each arm but the reference, in order.

    Raises
    ------
    PairingError
        A run twice for one arm of an experiment, or a reference that is not an arm of its
        experiment.
    """
    instance(config, PairedConfig, "paired_comparison(): config", ConfigError)
    by_exp: dict[str, dict[str, dict[str, Mapping[str, Any]]]] = {}
    for r in rows:
        runs = by_exp.setdefault(r["experiment"], {}).setdefault(r["arm"], {})
        if r["run"] in runs:
            raise PairingError(f"experiment {r['experiment']!r}, arm {r['arm']!r}: run "
                               f"{r['run']!r} appears twice; a run is one row per arm")
        runs[r["run"]] = r
    out = []
    for exp, arms in by_exp.items():
        ref = (references or {}).get(exp, next(iter(arms)))
        if ref not in arms:
            raise PairingError(f"experiment {exp!r}: the reference arm {ref!r} is not one of "
                               f"its arms ({', '.join(arms)})")
        out += [_pair_row(exp, arm, ref, runs, arms[ref], config)
                for arm, runs in arms.items() if arm != ref]
    return out


def default_reference(experiment: Experiment, *, skip: Sequence[str] = ()) -> str:
    """The arm an experiment's arms are paired against: its ``reference`` method when that is
    one of its arms too, else its first benchmark bound (a method that reads the truth, like
    ``oracle``), else its first arm; of the arms not labelled in ``skip`` (all skipped: the
    first arm)."""
    labels = [a.label for a in experiment.arms if a.label not in skip] or [
        experiment.arms[0].label]
    if experiment.reference is not None and experiment.reference.label in labels:
        return experiment.reference.label
    for arm in (a for a in experiment.arms if a.label in labels):
        try:
            if method_info(arm.method).needs_truth:
                return arm.label
        except UnknownMethodError:
            continue
    return labels[0]


def references_for(experiments: Sequence[Experiment], label: str | None = None
                   ) -> dict[str, str]:
    """Each experiment's reference arm: ``label`` where it is an arm, else
    :func:`default_reference`.

    Raises
    ------
    ConfigError
        ``label`` is an arm of none of ``experiments``.
    """
    if label is not None and not any(label == a.label for e in experiments for a in e.arms):
        arms = sorted({a.label for e in experiments for a in e.arms})
        raise ConfigError(f"paired reference {label!r} is not an arm of any experiment; "
                          f"choose one of: {', '.join(arms)}")
    return {e.name: label if label in [a.label for a in e.arms] else default_reference(e)
            for e in experiments}


def pairable(by_run: Sequence[Mapping[str, Any]],
             experiments: Sequence[Experiment] = ()) -> list[dict[str, Any]]:
    """``by_run`` (rows of :func:`bomgraph.summaries.final_by_run`) with each run that was
    scored against its own final map (a stream without truth, the arm run as the sweep's
    ``--reference``: ``scored_against`` ``"itself (...)"``) marked ``own_map`` (``"itself"``,
    :func:`bomgraph.run_scoring.self_scored`) and its MPE
    NaN: its error there is rounding, and a ratio over it ~1e15 (h58; h59; a reference
    labelled otherwise than its arm, h63). So is, with the ``experiments``, a run scored
    against the reference's map by an arm of the reference's method and options at another
    checkpoint cadence (a reference with its own ``checkpoint_every``): the same map but
    for the cadence, whose error is rounding for a method the cadence does not change
    (ratios of 2e15, h68): ``own_map`` ``"method"``."""
    alike = self_scored_arms(experiments)
    return [{**r, "mpe_m": math.nan, "own_map": self_scored(r, alike)}
            if self_scored(r, alike) else dict(r) for r in by_run]


def scored_references(experiments: Sequence[Experiment], references: Mapping[str, str],
                      rows: Sequence[Mapping[str, Any]], label: str | None = None
                      ) -> dict[str, str]:
    """``references`` (from :func:`references_for`), where the reference was chosen by
    default and every run of it that ran was scored against its own map (streams without
    truth: it is the sweep's ``--reference``) while at least two other arms ran, turned to
    the next default (:func:`default_reference` without it): the others are paired with one
    another on their errors against its map, not with it on none. An arm named by ``label``
    (``--paired-reference``) stays. ``rows``: as :func:`paired_comparison`'s, after
    :func:`pairable`."""
    out = dict(references)
    for e in experiments:
        ref = out.get(e.name)
        if ref is None or ref == label:
            continue
        mine = [r for r in rows if r["experiment"] == e.name]
        ran = [r for r in mine if r["arm"] == ref and r["ok"]]
        others = {r["arm"] for r in mine if r["arm"] != ref and r["ok"]}
        if ran and all(r.get("own_map") for r in ran) and len(others) >= 2:
            out[e.name] = default_reference(e, skip=[ref])
    return out


#: From this magnitude a cell is shown in exponent form: ``999999.99`` and ``1.000e+06`` fill
#: the 9 characters of the narrowest column.
_HUGE_CELL = 1e6


def _num(v: float | None, fmt: str, scale: float = 1.0) -> str:
    """A cell: ``-`` for none, a fixed-point value of a million or more in exponent form (a
    ratio over a reference whose error is rounding: 896680534985135.25 overran its column,
    h152; so did 100000000.00 from 1e6 to 1e9, h154)."""
    return "-" if v is None else fixed_or_exponent(v, fmt, scale, _HUGE_CELL)


def format_paired(rows: Sequence[PairedRow], confidence: float = 0.95) -> str:
    """The paired rows as text: one block per experiment, one line per arm."""
    lines = []
    pct = f"{100 * confidence:g}%"
    for exp in dict.fromkeys(r.experiment for r in rows):
        rs = [r for r in rows if r.experiment == exp]
        lines.append(f"\n== {exp}, paired against {rs[0].reference} ==")
        aw = max([30] + [len(r.arm) for r in rs])
        lines.append(f"{'arm':{aw}s} {'pairs':>9s} {'ratio [CI]':>20s} {'med ratio':>9s} "
                     f"{'med diff':>9s} {'W/T/L':>9s} {'p':>8s}")
        for r in rs:
            out = r.runs - r.n_pairs
            pairs = f"{r.n_pairs}" + (f"[{out} out]" if out else "")
            ci = (f" [{_num(r.ratio_ci_low, '.2f')}, {_num(r.ratio_ci_high, '.2f')}]"
                  if r.ratio_ci_low is not None else "")
            lines.append(f"{r.arm:{aw}s} {pairs:>9s} {_num(r.ratio_of_means, '.2f') + ci:>20s} "
                         f"{_num(r.ratio_median, '.2f'):>9s} "
                         f"{_num(r.diff_median_m, '+.2f', 100):>9s} "
                         f"{f'{r.wins}/{r.ties}/{r.losses}':>9s} {_num(r.wilcoxon_p, '.2g'):>8s}"
                         + (f"  ({r.note})" if r.note else ""))
    if lines:   # the legend once, after the blocks
        lines.append(f"\npaired: final landmark MPE on the runs both arms scored; ratio of "
                     f"means (arm / reference) [{pct} CI], median per-run ratio, median "
                     f"difference [cm], wins/ties/losses (lower MPE wins), Wilcoxon p; "
                     f"[k out]: runs left out (failed, unscored or unmatched); paired.csv")
    return "\n".join(lines)


__all__ = ["MIN_NONZERO_WILCOXON", "MIN_PAIRS_CI", "PairedConfig", "PairedRow",
           "default_reference", "format_paired", "paired_comparison", "pairable",
           "ratio_of_means_ci", "references_for", "scored_references", "wilcoxon_p"]
