"""Estimates where some variables have no covariance (an all-NaN block: the marginal is not
defined, ``baselines.lm_report.marginal_covariances``), through every consumer: the estimate
file (``null`` for such a block, read back as NaN), evaluate's NEES (the mean over the
landmarks that have one; NaN for a pose that has none), compare's per-checkpoint NEES and the
run figure. Before helper h32-marginals' change ``MapEstimate`` refused such an estimate outright
("must be finite"), so a method could only drop every covariance of the run.

The expected NEES is computed here by hand from the alignment the evaluator reports.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from bomgraph import create_mapper
from bomgraph.estimate_file import read_estimate, stream_identity, write_estimate
from bomgraph.evaluate import landmark_nees, pose_nees, score_checkpoints, score_estimate
from bomgraph.file_evaluation import evaluate_files, format_evaluation
from bomgraph.mapper import Checkpoint, run
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream


@pytest.fixture(scope="module")
def partial() -> tuple:
    """A gtsam-batch run with covariances, its third landmark and latest pose then marked
    undefined (NaN blocks) as ``marginal_covariances`` marks a variable its Jacobian's null
    space moves."""
    stream = simulate(SimConfig(n_steps=30, n_landmarks=12), np.random.default_rng(7))
    result = run(create_mapper("gtsam-batch", stream.header, covariances=True), stream.steps,
                 checkpoint_every=10, method="gtsam-batch")
    final = result.final
    assert final.landmark_cov is not None and np.isfinite(final.landmark_cov).all()
    lc = final.landmark_cov.copy()
    pc = final.pose_cov.copy()
    k = 2                     # the third landmark mapped
    lc[k] = np.nan
    pc[-1] = np.nan
    marked = dataclasses.replace(final, landmark_cov=lc, pose_cov=pc,
                                 info={**final.info, "covariances": "partial"})
    checkpoints = result.checkpoints[:-1] + (Checkpoint(result.checkpoints[-1].t, marked,
                                                        result.checkpoints[-1].estimate_s),)
    return stream, dataclasses.replace(result, checkpoints=checkpoints), marked, k


def test_map_estimate_takes_all_nan_blocks_but_not_partly_nan_ones(partial: tuple) -> None:
    _, _, marked, k = partial
    assert np.isnan(marked.landmark_cov[k]).all()
    bad = marked.landmark_cov.copy()
    bad[0, 0, 1] = np.nan
    with pytest.raises(Exception, match="finite, or a block all NaN"):
        dataclasses.replace(marked, landmark_cov=bad)


def test_estimate_file_writes_null_for_an_undefined_block_and_reads_it_back(
        partial: tuple, tmp_path: Path) -> None:
    stream, result, marked, k = partial
    path = tmp_path / "e.est"
    write_estimate(result, path, stream=stream_identity(stream.steps))
    last = json.loads(path.read_text().splitlines()[-2])
    assert last["landmark_cov"][k] is None and last["pose_cov"][-1] is None
    assert all(c is not None for i, c in enumerate(last["landmark_cov"]) if i != k)
    back = read_estimate(path).final
    np.testing.assert_array_equal(back.landmark_cov, marked.landmark_cov)   # NaN where NaN
    np.testing.assert_array_equal(back.pose_cov, marked.pose_cov)
    # a block partly null or partly NaN is still refused
    lines = path.read_text().splitlines()
    obj = json.loads(lines[-2])
    obj["landmark_cov"][0] = [obj["landmark_cov"][0][0], None, None, 1.0]
    (tmp_path / "bad.est").write_text("\n".join(lines[:-2] + [json.dumps(obj), lines[-1]])
                                      + "\n")
    with pytest.raises(Exception, match=r"landmark_cov\[0\]"):
        read_estimate(tmp_path / "bad.est")


def test_nees_leaves_out_the_undefined_blocks_and_says_none_for_the_pose(
        partial: tuple, tmp_path: Path) -> None:
    stream, result, marked, k = partial
    score = score_estimate(marked, stream.truth)
    a = score.alignment
    common, ie, it = np.intersect1d(marked.landmark_ids, stream.truth.landmark_ids,
                                    return_indices=True)
    want = []
    for i, j in zip(ie, it):
        if i == k:
            continue
        e = a.scale * a.rotation @ marked.landmarks_xy[i] + a.translation \
            - stream.truth.landmarks_xy[j]
        sr = a.scale * a.rotation
        want.append(float(e @ np.linalg.solve(sr @ marked.landmark_cov[i] @ sr.T, e)))
    per = landmark_nees(marked, stream.truth, a)
    assert math.isnan(per[list(ie).index(k)])
    np.testing.assert_allclose(per[np.isfinite(per)], want, rtol=1e-12)
    assert math.isnan(pose_nees(marked, stream.truth, a))
    # compare's per-checkpoint NEES: the mean over the landmarks that have a covariance
    rows = score_checkpoints(result.checkpoints, stream.truth, nees=True)
    assert rows[-1].nees_landmark == pytest.approx(np.mean(want), rel=1e-12)
    assert math.isnan(rows[-1].nees_pose)
    assert math.isfinite(rows[0].nees_pose)          # an earlier checkpoint keeps its own
    # evaluate on the files: the same numbers, no error
    write_estimate(result, tmp_path / "e.est", stream=stream_identity(stream.steps))
    write_stream(stream, tmp_path / "s.jsonl")
    ev = evaluate_files(tmp_path / "e.est", tmp_path / "s.jsonl")
    assert ev.nees_landmark == pytest.approx(np.mean(want), rel=1e-12)
    assert math.isnan(ev.nees_pose)
    assert ev.nees_undefined == (1, True)
    text = format_evaluation(ev)
    assert "landmark (mean; 1 without a covariance left out)" in text
    assert "latest pose none (it has no covariance)" in text


def test_run_figure_draws_no_ellipse_for_an_undefined_block(partial: tuple) -> None:
    pytest.importorskip("matplotlib")
    from bomgraph.plots import run_figure

    stream, _, marked, _ = partial
    score = score_estimate(marked, stream.truth)
    fig = run_figure(stream.truth, marked, score.alignment, label="gtsam-batch",
                     landmark_cov=marked.landmark_cov)
    lines = [ln for ax in fig.axes for ln in ax.get_lines()
             if len(ln.get_xdata()) > 20 and ln.get_linewidth() == 0.6]
    assert len(lines) == len(marked.landmark_ids) - 1
    assert all(np.isfinite(ln.get_xdata()).all() for ln in lines)

