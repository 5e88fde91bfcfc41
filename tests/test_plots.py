"""Figures take arrays: plots.py imports no mapper, dataset, scorer, runner or report."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np

from bomgraph import plots
from bomgraph.mapper import MapEstimate
from bomgraph.stream import Truth


def test_plots_imports_only_numpy_and_matplotlib() -> None:
    imported = set()
    for node in ast.walk(ast.parse(Path(plots.__file__).read_text())):  # in functions too
        if isinstance(node, ast.ImportFrom):
            imported.add(("." * node.level) + (node.module or ""))
        elif isinstance(node, ast.Import):
            imported.update(a.name for a in node.names)
    assert imported <= {"__future__", "warnings", "dataclasses", "typing", "numpy",
                        "textwrap", "zlib", "matplotlib.figure", "matplotlib.ticker"}, imported


def test_figure_builders_draw_arrays() -> None:
    truth = Truth(np.arange(4), np.array([[0.0, 0], [1, 0], [0, 1], [1, 1]]),
                  np.array([[0.0, 0, 0], [0.5, 0.5, 1.0]]))
    t = np.array([10, 20])
    fig = plots.error_vs_time_figure({"a": (t, np.array([[0.1, 0.05], [0.2, 0.04]]))},
                                     title="x", robot_curves={"a": (t, np.ones((2, 2)))})
    assert len(fig.axes) == 2
    est = MapEstimate(truth.landmark_ids, truth.landmarks_xy + 0.01, pose_t=np.array([0, 1]),
                      poses=truth.poses)
    assert len(plots.map_figure(truth, est, title="m").axes) == 1
    panels = [plots.MapPanel("ok", np.column_stack([truth.landmark_ids, truth.landmarks_xy]),
                             np.array([[0, 0.0, 0.0], [1, 0.5, 0.5]]), mpe_m=0.01),
              plots.MapPanel("bad", None, failure="ValueError: no")]
    fig = plots.final_maps_figure(truth, panels, title="rec")
    assert [ax.get_title() for ax in fig.axes[:2]] == ["ok: MPE 1.0 cm", "bad"]
