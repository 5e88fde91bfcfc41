"""``bomgraph evaluate`` reads the stream once without keeping its steps (h62): the bearing
residual RMS is summed as the stream is read, exactly (:class:`bomgraph.trajectory.ExactSum`),
so it does not depend on how the bearings were batched; the steps read are let go."""

from __future__ import annotations

import json
import math
import weakref
from pathlib import Path

import numpy as np
import pytest

import bomgraph.file_evaluation as fe
from bomgraph.cli import main
from bomgraph.estimate_file import read_estimate
from bomgraph.stream_file import StreamReader, read_stream
from bomgraph.trajectory import ExactSum, bearing_residuals


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> tuple[Path, Path, Path]:
    d = tmp_path_factory.mktemp("evs")
    s, e, bare = d / "s.jsonl", d / "e.json", d / "bare.jsonl"
    assert main(["simulate", "--seed", "4", "--steps", "120", "--landmarks", "20",
                 "--out", str(s)]) == 0
    assert main(["run", str(s), "--method", "ekf", "--out", str(e)]) == 0
    lines = s.read_text().splitlines()
    head = json.loads(lines[0])
    del head["truth"]
    bare.write_text("\n".join([json.dumps(head), *lines[1:]]) + "\n")
    return s, e, bare


def test_exact_sum_is_fsum_however_batched() -> None:
    rng = np.random.default_rng(5)
    for trial in range(40):
        v = rng.standard_normal(int(rng.integers(0, 500))) * 10.0 ** rng.integers(-300, 300)
        if trial % 3 == 0:   # subnormals, zeros, the largest finite, signs
            v = np.concatenate([v, [5e-324, -5e-324, 2.2e-308, 0.0, -0.0, 1.7e308, -1.7e308]])
        rng.shuffle(v)
        whole, parts = ExactSum(), ExactSum()
        whole.add(v)
        for part in np.array_split(v, int(rng.integers(1, 9))):
            parts.add(part)
        assert whole.value == parts.value == math.fsum(v.tolist())
    assert ExactSum().value == 0.0


def test_the_bearing_rms_is_the_exactly_summed_rms_of_the_residuals(files) -> None:
    s, e, _ = files
    final = read_estimate(e).final
    steps = read_stream(s).steps
    args = (final.landmark_ids, final.landmarks_xy, final.pose_t, final.poses, steps)
    r, m = bearing_residuals(*args), bearing_residuals(*args, mirrored=True)
    b = fe.bearing_consistency(final, steps)
    assert b.n == r.size > 0
    assert b.rms_rad == math.sqrt(math.fsum((r ** 2).tolist()) / r.size)
    assert b.mirrored_rms_rad == math.sqrt(math.fsum((m ** 2).tolist()) / m.size)
    # numpy's pairwise sum (the value before h62) differs by rounding only
    assert b.rms_rad == pytest.approx(float(np.sqrt(np.mean(r ** 2))), rel=1e-14, abs=0)


@pytest.mark.parametrize("bare", [False, True], ids=["truth", "truth-free"])
def test_evaluate_keeps_no_more_steps_than_a_batch(files, monkeypatch, bare) -> None:
    """The reader's steps are let go once fed to the sums (at most a batch alive, here 5
    steps), and the numbers are those of the whole stream in memory, bit for bit."""
    s, e, free = files
    stream = free if bare else s
    whole = fe.evaluate_files(e, stream)
    alive: list[weakref.ref] = []
    most = [0]
    plain_iter = StreamReader.__iter__

    def watched(self):
        for st in plain_iter(self):
            # no cycles: CPython frees a step when its last reference goes
            most[0] = max(most[0], sum(w() is not None for w in alive))
            alive.append(weakref.ref(st))
            yield st

    monkeypatch.setattr(StreamReader, "__iter__", watched)
    monkeypatch.setattr(fe, "_BATCH_STEPS", 5)
    batched = fe.evaluate_files(e, stream)
    assert len(alive) == 121 and most[0] <= 5
    assert fe.format_evaluation(batched, "json") == fe.format_evaluation(whole, "json")
    got = batched.as_dict()
    steps = read_stream(stream).steps
    assert got["bearing_rms_rad"] == fe.bearing_consistency(read_estimate(e).final,
                                                            steps).rms_rad
    if bare:  # each checkpoint's over the steps up to it
        for k, c in enumerate(read_estimate(e).checkpoints):
            b = fe.bearing_consistency(c.estimate, steps[: c.t + 1])
            assert got["checkpoints"]["bearing_rms_rad"][k] == b.rms_rad
            assert got["checkpoints"]["n_bearings"][k] == b.n


def test_exact_sum_of_nonfinite_or_overflowing_values_is_not_a_finite_number() -> None:
    """h70: a NaN or infinity went through frexp's NaN mantissa cast to int64 and gave a
    finite garbage sum (-1023.0 for [nan, 1.0]); a sum past the float range raised
    OverflowError. They are NaN and infinities, as numpy's sum (the old RMS) gives them."""
    def total(*batches: list[float]) -> float:
        s = ExactSum()
        for b in batches:
            s.add(np.array(b))
        return s.value
    with np.errstate(invalid="raise"):   # no cast of a NaN either
        assert math.isnan(total([math.nan, 1.0]))
        assert math.isnan(total([1.0], [math.inf], [-math.inf, 2.0]))
        assert total([1.0, math.inf], [3.0]) == math.inf
        assert total([-math.inf], [1e308]) == -math.inf
    assert total([1.7e308, 1.7e308]) == math.inf
    assert total([-1.7e308], [-1.7e308, 1.0]) == -math.inf
    assert total([1.7e308, 1.7e308, -1.7e308]) == 1.7e308   # exact: no intermediate overflow


def test_sums_without_the_mirror_give_the_same_rms_and_no_mirrored_one() -> None:
    """compare's per-checkpoint bearing RMS keeps no mirrored sums (h70: half its work); the
    RMS is the same bit for bit."""
    from bomgraph.sim import SimConfig, simulate
    from bomgraph.trajectory import BearingResidualSums

    s = simulate(SimConfig(n_steps=40), np.random.default_rng(3))
    ids, xy = np.asarray(s.truth.landmark_ids), np.asarray(s.truth.landmarks_xy) + 0.01
    poses = np.asarray(s.truth.poses)
    both = BearingResidualSums(ids, xy, np.arange(len(poses)), poses)
    plain = BearingResidualSums(ids, xy, np.arange(len(poses)), poses, mirrored=False)
    both.add_steps(s.steps)
    plain.add_steps(s.steps)
    assert plain.n == both.n > 0 and plain.rms_rad == both.rms_rad
    assert math.isnan(plain.mirrored_rms_rad) and not math.isnan(both.mirrored_rms_rad)
