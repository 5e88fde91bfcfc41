"""Audit h19 of the public Python API: the writers (export, the estimate file, the stream
file), the experiments' constructors and what ``bomgraph`` exports, misused from Python as a
library user would. Each misuse is refused where it enters with a BomgraphError naming the
argument and the fix, never a raw TypeError/AttributeError/ValueError from deep inside, a
silently written file that our own readers then refuse, or a file left half written."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bomgraph.errors import BomgraphError, ConfigError
from bomgraph.map_estimate import MapEstimate
from bomgraph.stream import Stream


# ---- MapEstimate: ids are non-negative, as in the stream ------------------------------------

@pytest.mark.parametrize("ids", [[-1, 2], np.array([3, -7])])
def test_map_estimate_refuses_negative_landmark_ids(ids: object) -> None:
    """A negative id was kept; the estimate file's writer then wrote a file its reader
    refuses, and export wrote it into g2o and csv."""
    with pytest.raises(ConfigError, match="landmark_ids must be non-negative"):
        MapEstimate(ids, [[0.0, 0.0], [1.0, 1.0]])
