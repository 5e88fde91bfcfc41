"""Tests of ``hybrid-isam2`` (baselines/hybrid_isam2.py): the registry and presets, exact
recovery without noise, seeding that lets landmarks in before their rays have parallax, and a
small accuracy comparison with ``gtsam-isam2``."""

from __future__ import annotations

import math

import numpy as np
import pytest

from baselines.hybrid_isam2 import HybridIsam2Config, HybridIsam2Mapper, refine_on_rays
from baselines.isam2 import Isam2Mapper
from bomgraph.errors import ConfigError
from bomgraph.evaluate import score_estimate
from bomgraph.mapper import (MapEstimate, available_methods, create_mapper,
                             method_config_class, run)
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream import Step, Stream


@pytest.fixture(scope="module")
def noise_free() -> Stream:
    return simulate(SimConfig(n_steps=80, n_landmarks=20, noise_scale=0.0),
                    np.random.default_rng(41))


class TruthSeed:
    """A seed mapper that knows the map: the truth, mirrored, turned and shifted."""

    def __init__(self, stream: Stream) -> None:
        xy = stream.truth.landmarks_xy * np.array([1.0, -1.0])
        c, s = math.cos(1.1), math.sin(1.1)
        self.map = MapEstimate(stream.truth.landmark_ids,
                               xy @ np.array([[c, -s], [s, c]]).T + np.array([5.0, -2.0]))

    def step(self, step: Step) -> None:
        pass

    def estimate(self) -> MapEstimate:
        return self.map


def test_registered_with_its_config_and_presets() -> None:
    assert "hybrid-isam2" in [m.name for m in available_methods()]
    assert method_config_class("hybrid-isam2") is HybridIsam2Config
    assert set(HybridIsam2Config.preset_names()) == {"paper", "real"}
    assert HybridIsam2Config.preset("real").seed_options == {"preset": "real"}
    with pytest.raises(ConfigError, match="seed_method"):
        HybridIsam2Config(seed_method="hybrid-isam2")
    with pytest.raises(ConfigError, match="seed_sigma_m"):
        HybridIsam2Config(seed_sigma_m=0.0)


@pytest.mark.parametrize("seed", ["stmds-smacof", "truth"])
def test_noise_free_exact_recovery(seed: str, noise_free: Stream) -> None:
    kw = {"seed_mapper": TruthSeed(noise_free)} if seed == "truth" else {}
    mapper = HybridIsam2Mapper(noise_free.header, **kw)
    est = run(mapper, noise_free.steps, checkpoint_every=40).final
    score = score_estimate(est, noise_free.truth)
    assert score.n_common >= 18
    assert score.max_m < 1e-6 and score.robot_last_m < 1e-6


def test_seeded_landmarks_enter_before_their_rays_have_parallax() -> None:
    stream = simulate(SimConfig(n_steps=60, n_landmarks=30), np.random.default_rng(5))
    plain = run(Isam2Mapper(stream.header), stream.steps, checkpoint_every=5)
    seeded_mapper = HybridIsam2Mapper(stream.header, seed_mapper=TruthSeed(stream))
    seeded = run(seeded_mapper, stream.steps, checkpoint_every=5)
    n_plain = np.array([len(c.estimate) for c in plain.checkpoints])
    n_seeded = np.array([len(c.estimate) for c in seeded.checkpoints])
    assert np.all(n_seeded >= n_plain) and np.any(n_seeded > n_plain)
    assert seeded.final.info["seeded_landmarks"]
    # the seeded landmarks are where the truth is (up to the noise of the run)
    score = score_estimate(seeded.final, stream.truth)
    err = dict(zip(score.landmark_ids.tolist(), score.errors_m))
    assert max(err[i] for i in seeded.final.info["seeded_landmarks"]) < 0.15


def test_refine_on_rays_moves_a_seed_onto_its_rays_keeping_its_depth() -> None:
    poses = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]])
    target = np.array([1.0, 0.5])
    bearings = np.arctan2(target[1] - poses[:, 1], target[0] - poses[:, 0])
    seed = target + np.array([0.05, -0.08])
    xy = refine_on_rays(seed, poses, bearings, 0.01, 0.3)
    d = xy - poses[:, :2]
    assert np.allclose(np.arctan2(d[:, 1], d[:, 0]), bearings, atol=2e-3)
    assert np.linalg.norm(xy - target) < np.linalg.norm(seed - target)


def test_at_least_as_accurate_as_gtsam_isam2_on_small_runs() -> None:
    for seed in (11, 12):
        stream = simulate(SimConfig(n_steps=150), np.random.default_rng(seed))
        ref = run(create_mapper("gtsam-isam2", stream.header), stream.steps,
                  checkpoint_every=50)
        hyb = run(create_mapper("hybrid-isam2", stream.header), stream.steps,
                  checkpoint_every=50)
        for c_ref, c_hyb in zip(ref.checkpoints, hyb.checkpoints):
            s_ref = score_estimate(c_ref.estimate, stream.truth)
            s_hyb = score_estimate(c_hyb.estimate, stream.truth)
            assert s_hyb.n_mapped >= s_ref.n_mapped
            assert s_hyb.mpe_m <= 1.05 * s_ref.mpe_m + 1e-3, (seed, c_ref.t)
