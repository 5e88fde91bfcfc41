"""h103's review of h101's leads.

- Library refusals of an output file named the parameter ``path`` in functions whose
  parameter is ``out`` (``run_file(..., out=...)``, ``plot_run``, ``plot_results``): h101 made
  them name the library's parameters, but :func:`bomgraph.stdio.check_output_path` (and the
  estimate writer under ``run_file``) named their own. ``run_file`` also read the whole stream
  (and warned of it) before refusing its output.
- :func:`bomgraph.out_folder.unique_slugs` counted each name's repeats with ``list.count``,
  quadratic (h101 fixed the same in ``Experiment``): 5.1 s for 20,000 runs of a ``compare
  --estimates``. Counted here as calls of ``list.count`` (no timing).
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import numpy as np
import pytest

from bomgraph.figures import plot_results, plot_run
from bomgraph.file_run import run_file
from bomgraph.out_folder import unique_slugs
from bomgraph.sim import SimConfig, simulate
from bomgraph.stdio import OutputPathError
from bomgraph.stream_file import write_stream


@pytest.fixture()
def stream(tmp_path: Path) -> Path:
    path = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=20), np.random.default_rng(1)), path)
    return path


def _said(call, *args, **kw) -> str:
    with pytest.raises(OutputPathError) as info:
        call(*args, **kw)
    return str(info.value)


def test_library_output_refusals_name_the_parameter_out(
        tmp_path: Path, stream: Path, caplog: pytest.LogCaptureFixture) -> None:
    """Fails before: each said ``path='...'``; and run_file read the stream first."""
    missing = tmp_path / "no" / "x.est"
    with caplog.at_level(logging.INFO, logger="bomgraph"):
        said = _said(run_file, stream, "triangulate", out=missing)
    assert said == f"out='{missing}': the folder {missing.parent} does not exist", said
    assert not [r for r in caplog.records if "running triangulate" in r.getMessage()]
    assert _said(run_file, stream, "triangulate", out=tmp_path).startswith(
        f"out='{tmp_path}': is a directory")
    est = tmp_path / "e.est"
    run_file(stream, "triangulate", out=est)
    png = tmp_path / "no" / "x.png"
    assert _said(plot_run, est, stream, out=png).startswith(f"out='{png}': the folder")
    assert _said(plot_results, tmp_path, out=png).startswith(f"out='{png}': the folder")
    assert _said(plot_results, tmp_path, out="") == "out is empty; give a file name"


def test_unique_slugs_counts_each_name_once() -> None:
    names = [f"d{k % 10}-run{k}" for k in range(2_000)] + ["EKF", "ekf"]
    calls = 0

    def profile(frame, event, arg) -> None:
        nonlocal calls
        if event == "c_call" and getattr(arg, "__name__", "") == "count":
            calls += 1

    sys.setprofile(profile)
    try:
        slugs = unique_slugs(names)
    finally:
        sys.setprofile(None)
    assert calls == 0, calls   # before: 2,002 scans of the whole list
    assert slugs["d3-run3"] == "d3-run3"
    assert slugs["EKF"] != slugs["ekf"] and slugs["EKF"].startswith("EKF-")
