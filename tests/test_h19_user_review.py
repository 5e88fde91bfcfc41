"""What a new user met (nineteenth session's walkthrough of the README): names that shadow
each other, messages that did not say what to do, settings that were dropped silently."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bomgraph import mapper
from bomgraph.cli import main
from bomgraph.errors import ConfigError
from bomgraph.mapper import create_mapper, method_info, register_method
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream


@pytest.fixture()
def registry(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))


def test_register_method_refuses_a_taken_name_unless_asked_to_replace(registry) -> None:
    with pytest.raises(ConfigError, match=r"'ekf' is taken \(builtin method "
                                          r"baselines.ekf.mappers:EkfMapper\).*replace=True"):
        register_method("ekf", "baselines.triangulate:TriangulateMapper", "not the EKF")
    assert method_info("ekf").target == "baselines.ekf.mappers:EkfMapper"
    register_method("mine", "baselines.triangulate:TriangulateMapper", "d")
    register_method("mine", "baselines.triangulate:TriangulateMapper", "d")  # the same: kept
    with pytest.raises(ConfigError, match="'mine' is taken"):
        register_method("mine", "baselines.ekf.mappers:EkfMapper", "d")
    register_method("mine", "baselines.ekf.mappers:EkfMapper", "d", replace=True)
    assert method_info("mine").target == "baselines.ekf.mappers:EkfMapper"
    register_method("ekf", "baselines.triangulate:TriangulateMapper", "d", replace=True)
    assert method_info("ekf").target == "baselines.triangulate:TriangulateMapper"


def test_a_method_that_reads_the_truth_says_how_to_give_it(tmp_path: Path, capsys) -> None:
    s = simulate(SimConfig(n_steps=12, n_landmarks=6), np.random.default_rng(1))
    with pytest.raises(ConfigError, match=r"truth=stream\.truth"):
        create_mapper("oracle", s.header)
    from bomgraph.stream import Stream

    write_stream(Stream(s.header, s.steps, None), tmp_path / "nt.jsonl")
    assert main(["run", str(tmp_path / "nt.jsonl"), "--method", "oracle", "--allow-truth",
                 "--out", str(tmp_path / "o.est")]) == 2
    err = capsys.readouterr().err
    assert "nt.jsonl: method 'oracle' reads the ground truth, and this stream has none" in err
