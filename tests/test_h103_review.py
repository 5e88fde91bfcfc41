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

import json
import logging
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bomgraph.bench import Executor
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.figures import plot_results, plot_run
from bomgraph.file_run import run_file
from bomgraph.out_folder import unique_slugs
from bomgraph.report import compare
from bomgraph.result_cache import read_cached
from bomgraph.sim import SimConfig, make_priors, simulate, with_priors
from bomgraph.stdio import OutputPathError
from bomgraph.stream_file import StreamReader, read_stream, write_stream


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


def _short_runs_with_priors(folder: Path, n: int) -> list[Path]:
    """``n`` simulated runs of 50 steps with Exp. 3's priors (drawn over every landmark, as
    ``bomgraph simulate --steps 50 --prior-fraction 0.1`` does), so that a few name landmarks
    the short runs never see: the stream reader warns of those (h101)."""
    paths = []
    for seed in range(n):
        rng = np.random.default_rng(seed)
        s = simulate(SimConfig(n_steps=50), rng)
        path = folder / f"s{seed}.jsonl"
        write_stream(with_priors(s, make_priors(s.truth, 0.1, 0.03, rng)), path)
        paths.append(path)
    return paths


def _warned(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if "'priors'" in ln]


def test_compare_in_worker_processes_warns_once_per_stream(tmp_path: Path) -> None:
    """Fails before: each worker process that read a stream warned of it on its own stderr,
    unprefixed and under ``-q`` too, and the figures' reading warned again (6 lines for 2
    streams and 2 methods, 4 of them under -q)."""
    paths = _short_runs_with_priors(tmp_path, 2)
    expected = set()
    for p in paths:
        with StreamReader(p) as reader:
            list(reader)
    for quiet in ([], ["-q"]):
        out = tmp_path / f"cmp{len(quiet)}"
        done = subprocess.run(
            [sys.executable, "-m", "bomgraph", "compare", *quiet, "--streams", *map(str, paths),
             "--methods", "triangulate,stmds-smacof", "--jobs", "2", "--no-cache",
             "--estimates", "--out", str(out)], capture_output=True, text=True,
            env={**os.environ, "PYTHONPATH": str(Path(__file__).parents[1])})
        assert done.returncode == 0, done.stderr
        said = _warned(done.stderr)
        if quiet:
            assert said == [], said
            continue
        assert len(said) == len(set(said)) and all(
            ln.startswith("bomgraph: WARNING: ") for ln in said), said
        expected = {ln for ln in said}
        assert "_worker_warnings" not in (out / "results.json").read_text()
    assert len(expected) == sum(bool(_unobserved(p)) for p in paths) > 0


def _unobserved(path: Path) -> set[int]:
    s = read_stream(path)
    seen = {int(i) for st in s.steps for i in st.landmark_ids}
    return {i for p in s.header.priors for i in (p.i, p.j)} - seen


def test_a_serial_compare_of_many_streams_warns_once_per_stream(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """Fails before: the map figures read each stream again (8 are kept read), and warned
    again: 14 lines for 7 streams of 10."""
    paths = _short_runs_with_priors(tmp_path, 10)
    exp = Experiment("e", "e", (Arm("triangulate", "triangulate"),),
                     sources=tuple(FileSource(str(p)) for p in paths))
    with caplog.at_level(logging.WARNING, logger="bomgraph"):
        compare([exp], tmp_path / "cmp", executor=Executor("serial"), use_cache=False)
    said = [r.getMessage() for r in caplog.records if "'priors'" in r.getMessage()]
    assert len(said) == len(set(said)) == sum(bool(_unobserved(p)) for p in paths) > 0, said
    warned = next(p for p in paths if _unobserved(p))
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="bomgraph"):   # outside a sweep: each read
        read_stream(warned)
        read_stream(warned)
    assert len([r for r in caplog.records if "'priors'" in r.getMessage()]) == 2


def test_map_figures_of_runs_whose_names_slug_alike_are_two_files(tmp_path: Path) -> None:
    """Fails before: streams ``run 1`` and ``run_1`` (labels unique, h101) drew their map
    figures into one file, ``e_run_1_maps.png``, the first overwritten (compare listed it
    twice); ``RUN_1`` beside them is one file with it on a case-insensitive disk."""
    paths = []
    for k, name in enumerate(("run 1", "run_1", "RUN_1")):
        paths.append(tmp_path / f"{name}.jsonl")
        write_stream(simulate(SimConfig(n_steps=20), np.random.default_rng(k)), paths[-1])
    exp = Experiment("e", "e", (Arm("triangulate", "triangulate"),),
                     sources=tuple(FileSource(str(p)) for p in paths))
    result = compare([exp], tmp_path / "cmp", executor=Executor("serial"), use_cache=False)
    maps = sorted(p.name for p in (tmp_path / "cmp").glob("*_maps.png"))
    assert len(maps) == 3 and len({m.casefold() for m in maps}) == 3, maps
    written = [Path(p).name for p in result.files if str(p).endswith("_maps.png")]
    assert sorted(written) == maps


@pytest.mark.parametrize("converged", [True, False, None, "absent"])
def test_a_cached_converged_of_true_false_null_or_none_still_loads(
        tmp_path: Path, converged: object) -> None:
    """h101's check (a real bool or null) keeps every entry earlier versions wrote: run_task
    has written ``converged`` as true, false or null (or not at all) since the cache began."""
    entry = {"ok": True, "key": "key", "experiment": "e", "arm": "a", "method": "m", "run": "r",
             "checkpoints": [], "total_s": 0.0, "step_median_s": 0.0, "info": {}}
    if converged != "absent":
        entry["converged"] = converged
    path = tmp_path / "key.json"
    path.write_text(json.dumps(entry))
    assert read_cached(path) == entry
