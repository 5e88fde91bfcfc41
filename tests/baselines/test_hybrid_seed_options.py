"""A hybrid's ``seed_method`` and ``seed_options`` are checked where its configuration is
made, so ``compare`` refuses a typo before anything runs (one line, exit 2). Before (h20),
``--option hybrid:seed_method=nosuch`` or ``seed_options={"bogus": 1}`` ran the sweep and
marked every hybrid run FAILED (exit 1), and ``bomgraph methods``-style checks passed them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bomgraph.cli import main
from bomgraph.errors import ConfigError
from bomgraph.mapper import check_method_options
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream


@pytest.mark.parametrize("method", ["hybrid", "hybrid-isam2"])
def test_an_unknown_seed_method_or_seed_option_is_refused_by_the_config(method: str) -> None:
    with pytest.raises(ConfigError, match=r"seed_method='nosuch'.*unknown method 'nosuch'"):
        check_method_options(method, {"seed_method": "nosuch"})
    with pytest.raises(ConfigError, match=r"seed_options=\{'bogus': 1\}: StmdsConfig: unknown"):
        check_method_options(method, {"seed_options": {"bogus": 1}})
    with pytest.raises(ConfigError, match=r"unknown EkfConfig preset 'fast'"):
        check_method_options(method, {"seed_method": "ekf", "seed_options": {"preset": "fast"}})
    check_method_options(method, {"preset": "real"})  # the presets' own seeds pass
    check_method_options(method, {"seed_method": "ekf", "seed_options": {"preset": "real"}})


def test_compare_refuses_a_bad_seed_before_anything_runs(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=20), np.random.default_rng(0)), stream)
    out = tmp_path / "out"
    code = main(["compare", "--streams", str(stream), "--methods", "hybrid,triangulate",
                 "--option", "hybrid:seed_method=stmds-smacfo", "--no-progress",
                 "--no-figures", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and "seed_method='stmds-smacfo'" in err[0]
    assert not (out / "results.json").exists()


def test_a_seed_checked_once_is_not_taken_for_another() -> None:
    """Each seed and its options are checked once per process (the warm solve replaces the
    configuration at every checkpoint); options the checks tell apart (None and nan, a tuple
    and a list) are not taken for one another (helper-26's review: nan passed after None)."""
    import math

    from baselines.hybrid import HybridConfig, check_seed

    check_seed("X", "stmds-smacof", {"tri_parallax_rad": None})
    with pytest.raises(ConfigError, match="nan"):
        check_seed("X", "stmds-smacof", {"tri_parallax_rad": math.nan})
    with pytest.raises(ConfigError):
        HybridConfig(seed_method="stmds-smacof", seed_options={"tri_parallax_rad": math.nan})


@pytest.mark.parametrize("method", ["hybrid", "hybrid-isam2"])
def test_a_seed_that_needs_the_truth_is_refused_by_the_config(
        method: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Only "oracle" was refused by name: a run-time method or plugin whose factory needs the
    truth passed the check and failed every hybrid run, advising ``create_mapper(truth=)``,
    which the hybrid cannot follow (h49 noticed)."""
    from bomgraph import mapper

    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    mapper.register_method("bound-seed", "baselines.factor_graph:OracleMapper", "a bound",
                           needs_truth=True)
    with pytest.raises(ConfigError, match=r"seed_method='bound-seed' is a bound \(it needs "
                                          r"the truth"):
        check_method_options(method, {"seed_method": "bound-seed"})


@pytest.mark.parametrize("method", ["hybrid", "hybrid-isam2"])
@pytest.mark.parametrize("seed", ["hybrid", "hybrid-isam2"])
def test_a_hybrid_is_no_seed(method: str, seed: str) -> None:
    """HybridConfig refused "hybrid" but took "hybrid-isam2" as its seed, though its message
    says a seed is a non-hybrid mapper (h51 noticed)."""
    with pytest.raises(ConfigError, match="non-hybrid mapper"):
        check_method_options(method, {"seed_method": seed})
