"""``StmdsConfig`` built directly (a factory's ``config=``): an integer option given NaN,
infinity, None, a string or a bool is a one-line ``ConfigError`` naming the option, not the
``ValueError`` / ``OverflowError`` / ``TypeError`` of an ``int()`` (found by h145's review)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bomgraph.errors import ConfigError
from bomgraph.stmds.config import StmdsConfig

WINDOWED = {"tri_window": 6, "tri_method": "ba"}
CASES = [("tri_max_poses", {}), ("tri_prefixes", {}), ("tri_grow", {}),
         ("tri_window", {"tri_method": "ba"}), ("tri_stride", WINDOWED)]


@pytest.mark.parametrize("bad", [math.nan, math.inf, None, "x", True, 2.5])
@pytest.mark.parametrize("name, base", CASES)
def test_a_bad_integer_option_is_a_config_error_naming_it(name, base, bad) -> None:
    if bad is None and name == "tri_stride":
        bad = math.nan           # None is tri_stride's default (tri_window - 1)
    with pytest.raises(ConfigError, match=name):
        StmdsConfig(**{**base, name: bad})


@pytest.mark.parametrize("bad", [(math.nan,), (math.inf,), (None,), ("x",), (True,), 3, None])
def test_bad_baseline_steps_are_a_config_error(bad) -> None:
    with pytest.raises(ConfigError, match="baseline_steps"):
        StmdsConfig(baseline_steps=bad)


def test_whole_floats_and_numpy_integers_still_pass() -> None:
    cfg = StmdsConfig(tri_window=6.0, tri_method="ba", tri_stride=np.int64(2), tri_grow=3.0,
                      tri_max_poses=np.int32(40))
    assert (cfg.tri_window, cfg.tri_stride) == (6, 2) and isinstance(cfg.tri_window, int)
    assert StmdsConfig(baseline_steps=(np.int64(4), 2.0)).baseline_steps == (4, 2)
