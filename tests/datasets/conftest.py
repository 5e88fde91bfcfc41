"""Fixtures of the importer tests (pytest finds them here; no test module imports them)."""

from __future__ import annotations

import numpy as np
import pytest

from bomgraph.sim import SimConfig, simulate


@pytest.fixture(scope="module")
def sim_stream():
    """A small simulated stream (25 steps, 20 landmarks) to write as g2o."""
    return simulate(SimConfig(n_steps=25, n_landmarks=20), np.random.default_rng(4))
