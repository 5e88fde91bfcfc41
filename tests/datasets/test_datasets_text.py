"""The strict text helpers shared by the importers: the odometry chain."""

from __future__ import annotations

import pytest

from bomgraph.datasets._text import chain_order
from bomgraph.errors import DatasetError


def test_chain_order_follows_edges_not_ids():
    assert chain_order([(5, 2, 1), (9, 5, 2), (2, 7, 3)], "f") == [9, 5, 2, 7]
    assert chain_order([], "f") == []
    with pytest.raises(DatasetError, match="f, line 2: .*closed loop"):
        chain_order([(0, 1, 1), (2, 3, 2), (3, 2, 3)], "f")
    with pytest.raises(DatasetError, match="f, line 1: the odometry edges form a closed loop"):
        chain_order([(0, 1, 1), (1, 0, 2)], "f")
    with pytest.raises(DatasetError, match="f, line 2: pose 4 already has odometry from"):
        chain_order([(0, 4, 1), (1, 4, 2)], "f")
    with pytest.raises(DatasetError, match="to itself"):
        chain_order([(3, 3, 1)], "f")
