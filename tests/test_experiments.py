"""Experiments as data: the paper's design, the real-data arms, arms that name presets."""

from __future__ import annotations

from pathlib import Path

import pytest

from bomgraph.errors import ConfigError
from bomgraph.experiments import (REAL_SKIPPED, REAL_VARIANTS, Arm, compare_experiments,
                                  paper_experiments, real_experiments, real_methods, select)
from bomgraph.mapper import available_methods
from bomgraph.sim import SimConfig


def test_paper_experiments_have_the_papers_design() -> None:
    exps = paper_experiments()
    assert set(exps) == {"exp1", "exp2", "exp3", "all"}
    assert all(len(e.runs()) == 25 and e.sim == SimConfig() for e in exps.values())
    assert {a.method for a in exps["exp2"].arms} >= {"stmds-cs-loc", "stmds-smacof-loc", "ekf",
                                                     "gtsam-batch", "gtsam-isam2", "hybrid"}
    assert any(a.prior_fraction == 0.1 for a in exps["exp3"].arms)
    quick = paper_experiments(quick=True)
    assert all(len(e.runs()) == 2 for e in quick.values())


def test_arms_name_presets_only() -> None:
    """No hand-written option dicts: an arm's options are a preset name (or the paper's
    fusion rule, which has no preset of its own)."""
    for exp in paper_experiments().values():
        for arm in exp.arms:
            assert set(arm.options) <= {"preset", "fusion"}, arm
    labels = {a.label: a for a in paper_experiments()["all"].arms}
    assert dict(labels["stmds-smacof (window ba)"].options) == {"preset": "window-ba"}
    assert dict(labels["stmds-smacof (window lsq)"].options) == {"preset": "window-lsq"}


def test_real_experiments_hold_every_method_and_its_real_variant(tmp_path: Path) -> None:
    for d in ("mrclam6", "bearing_only_sim_g2o"):
        (tmp_path / d).mkdir()
    exps = real_experiments(tmp_path)
    assert set(exps) == {"mrclam6", "g2o"} and len(exps["mrclam6"].sources) == 5
    labels = {a.label: a for a in exps["mrclam6"].arms}
    for method, variants in REAL_VARIANTS.items():
        for label, options in variants:
            assert method in labels and labels[label].method == method
            assert dict(labels[label].options) == options
            assert set(options) == {"preset"}
    assert {"ekf-invdepth", "gtsam-isam2", "oracle"} <= set(labels)
    # exactly each built-in method's defaults and the variants of the table, nothing more
    expected = [lab for m in real_methods() for lab in
                [m, *(label for label, _ in REAL_VARIANTS.get(m, ()))]]
    assert [a.label for a in exps["mrclam6"].arms] == expected and len(expected) == 22
    with pytest.raises(ConfigError, match="no dataset folders"):
        real_experiments(tmp_path / "nothing")


def test_compare_real_takes_a_method_list(tmp_path: Path) -> None:
    """``compare --real DIR --methods ekf,gtsam-batch``: those methods, each with its
    recording variants, on every recording."""
    for d in ("mrclam6", "bearing_only_sim_g2o"):
        (tmp_path / d).mkdir()
    chosen, _ = compare_experiments(real=str(tmp_path), methods="ekf, gtsam-batch",
                                    names=["g2o"])
    assert [e.name for e in chosen] == ["g2o"]
    assert [(a.label, a.method, dict(a.options)) for a in chosen[0].arms] == [
        ("ekf", "ekf", {}), ("ekf (real)", "ekf", {"preset": "real"}),
        ("gtsam-batch", "gtsam-batch", {}),
        ("gtsam-batch (real)", "gtsam-batch", {"preset": "real"})]


def test_real_methods_are_the_registry_less_the_skipped() -> None:
    names = [m.name for m in available_methods() if m.origin == "builtin"]
    assert real_methods() == [n for n in names if n not in REAL_SKIPPED]
    assert real_methods() == ["triangulate", "stmds-cs", "stmds-smacof", "stmds-smacof-loc",
                              "ekf", "ekf-invdepth", "gtsam-batch", "gtsam-isam2", "hybrid",
                              "hybrid-isam2", "oracle"]


def test_select_keeps_the_order_and_names_unknown_experiments() -> None:
    exps = paper_experiments(quick=True)
    assert [e.name for e in select(exps, ["exp3", "exp1"])] == ["exp3", "exp1"]
    assert [e.name for e in select(exps)] == list(exps)
    with pytest.raises(ConfigError, match="unknown experiment"):
        select(exps, ["exp9"])


def test_arm_options_must_be_plain_json() -> None:
    with pytest.raises(ConfigError, match="plain JSON"):
        Arm("bad", "triangulate", {"x": object()})


def test_a_simulated_run_is_made_once_per_process_and_is_the_fresh_simulation() -> None:
    import numpy as np

    from bomgraph.experiments import SIMULATED, SimSource, WorldSource
    from bomgraph.sim import paper_design, simulate_run

    SIMULATED.clear()
    spec = paper_design(0)[3]
    small = SimConfig(n_steps=40, n_landmarks=12)
    a, b = SimSource(spec, small), SimSource(spec, small)
    assert a.stream() is b.stream()                      # equal sources share the stream
    fresh = simulate_run(spec, small)
    kept = a.stream()
    assert kept.header == fresh.header
    for x, y in zip(kept.steps, fresh.steps):
        assert np.array_equal(x.odom, y.odom) and np.array_equal(x.landmark_ids, y.landmark_ids)
        assert np.array_equal(x.bearings_rad, y.bearings_rad)
    assert np.array_equal(kept.truth.poses, fresh.truth.poses)
    # another source (priors, another world seed) is another stream
    assert SimSource(spec, small, prior_fraction=0.1).stream() is not kept
    w = WorldSource(small, 5)
    assert w.stream() is WorldSource(small, 5).stream()
    assert WorldSource(small, 6).stream() is not w.stream()
    SIMULATED.clear()


def test_the_kept_streams_are_bounded_by_their_steps_least_recently_used_out() -> None:
    from bomgraph.experiments import SimulatedStreams, SimSource
    from bomgraph.sim import paper_design

    small = SimConfig(n_steps=40, n_landmarks=12)       # 41 steps each
    kept = SimulatedStreams(max_steps=100)               # room for two
    src = [SimSource(s, small) for s in paper_design(0)[:3]]
    made: list[int] = []

    def get(k: int):
        def make():
            made.append(k)
            return _simulate(src[k])
        return kept.get(src[k], make)

    get(0), get(1), get(0), get(2)           # 2 pushes out 1, the least recently used
    assert made == [0, 1, 2]
    get(0)
    assert made == [0, 1, 2]                 # still kept
    get(1)
    assert made == [0, 1, 2, 1]              # made again
    assert kept._steps <= 100
    huge = SimulatedStreams(max_steps=10)    # a stream larger than the bound is not kept
    huge.get(src[0], lambda: _simulate(src[0]))
    assert huge._steps == 0 and not huge._kept


def _simulate(source):
    from bomgraph.sim import simulate_run

    return simulate_run(source.spec, source.sim, prior_fraction=source.prior_fraction,
                        prior_sigma_xy_m=source.prior_sigma_xy_m)


def test_a_recording_has_one_cache_key_however_its_path_is_spelled(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``compare --real shared/data`` and ``--real /work/shared/data`` keyed the same files
    differently: the truth path went into the key as given and the files' stamp hashed their
    names as given, so results.json's keys differed and the cache was missed."""
    from bomgraph.sources import DatasetSource

    (tmp_path / "d").mkdir()
    for name in ("run.g2o", "truth.g2o"):
        (tmp_path / "d" / name).write_text("x\n")
    monkeypatch.chdir(tmp_path)
    rel = DatasetSource("g2o", "d/run.g2o", truth_path="d/truth.g2o")
    full = DatasetSource("g2o", str(tmp_path / "d" / "run.g2o"),
                         truth_path=str(tmp_path / "d" / "truth.g2o"))
    dotted = DatasetSource("g2o", "./d/../d/run.g2o", truth_path="d//truth.g2o")
    assert rel.key() == full.key() == dotted.key()
    folder = DatasetSource("mrclam", "d", robot=1)
    assert folder.key() == DatasetSource("mrclam", str(tmp_path / "d") + "/", robot=1).key()
    before = rel.key()
    (tmp_path / "d" / "truth.g2o").write_text("changed\n")   # a changed file still tells
    assert rel.key() != before
