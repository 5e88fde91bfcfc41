"""scripts/bench_generality.py: the like-for-like ratio on the landmarks both maps hold."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np

from bomgraph.stream import Truth

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("bench_generality",
                                               ROOT / "scripts" / "bench_generality.py")
bench = importlib.util.module_from_spec(_spec)
sys.modules["bench_generality"] = bench
_spec.loader.exec_module(bench)

TRUE_XY = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0], [2.0, 6.0]])
TRUTH = Truth(np.arange(5, dtype=np.int64), TRUE_XY, np.zeros((1, 3)))


def _row(stream: str, method: str, ids: list[int], xy: np.ndarray, mpe_m: float) -> dict:
    return {"stream": stream, "method": method, "checkpoint_every": 10, "mpe_m": mpe_m,
            "landmark_ids": ids, "landmarks_xy": np.asarray(xy).tolist()}


def test_common_set_leaves_out_the_landmark_the_bound_did_not_map() -> None:
    """A map exact up to a rigid motion except for landmark 4 (1 m off), against a bound that
    did not map landmark 4 and has every landmark 0.1 m off along x then y alternately: on
    the common set the method is exact (ratio 0), though its whole-map MPE is not."""
    c, s = math.cos(0.3), math.sin(0.3)
    moved = TRUE_XY @ np.array([[c, -s], [s, c]]).T + [5.0, -2.0]
    moved[4] += [1.0, 0.0]
    bound_xy = TRUE_XY[:4] + np.array([[0.1, 0], [0, 0.1], [-0.1, 0], [0, -0.1]])
    a = _row("m6_r4", "stmds-smacof", [0, 1, 2, 3, 4], moved, 0.2)
    b = _row("m6_r4", "oracle", [0, 1, 2, 3], bound_xy, 0.1)
    mine, theirs, n = bench.common_set_mpe(a, b, TRUTH)
    assert n == 4
    assert mine < 1e-12
    assert theirs > 0.05  # an alternating 0.1 m offset does not align away
    ratios = bench.common_set_ratios([a, b], {"m6_r4": TRUTH})
    assert ratios["stmds-smacof"]["m6_r4"]["n_common"] == 4
    assert ratios["stmds-smacof"]["m6_r4"]["ratio"] < 1e-9
    assert "oracle" not in ratios  # the bound is not compared with itself


def test_mrclam1_bound_is_the_best_method_and_too_few_common_is_nan() -> None:
    wiggle = 0.01 * np.array([[1, 0], [0, 1], [-1, 0], [0, -1], [1, 1]])
    ok = _row("m1_r1", "ekf", [0, 1, 2, 3, 4], TRUE_XY + wiggle, 0.01)
    worse = _row("m1_r1", "gtsam-batch", [0, 1, 2, 3, 4], TRUE_XY * 1.05, 0.05)
    few = _row("m1_r1", "stmds-smacof", [0, 1], TRUE_XY[:2], 0.0)  # mpe from 2: not a bound
    few["mpe_m"] = 0.5
    out = bench.common_set_ratios([ok, worse, few], {"m1_r1": TRUTH})
    assert out["gtsam-batch"]["m1_r1"]["bound"] == "ekf"
    # a 5 % scale error on a 4 m x 6 m map is ~0.1 m after a rigid fit; the wiggle ~0.01 m
    assert 3 < out["gtsam-batch"]["m1_r1"]["ratio"] < 30
    assert math.isnan(out["stmds-smacof"]["m1_r1"]["ratio"])
    assert out["stmds-smacof"]["m1_r1"]["n_common"] == 2


def test_summarise_reads_the_key_it_is_given() -> None:
    """The similarity summary ranks by the shape error, not the rigid one: on MRCLAM1 the
    bound is the best method by that key."""
    rows = [{"stream": "m1_r1", "method": m, "checkpoint_every": 10, "mpe_m": rig,
             "mpe_similarity_m": sim} for m, rig, sim in
            (("ekf", 0.10, 0.08), ("gtsam-batch", 0.30, 0.04))]
    rigid = bench.summarise(rows, ["ekf", "gtsam-batch"], [1], ("m1",))
    shape = bench.summarise(rows, ["ekf", "gtsam-batch"], [1], ("m1",), key="mpe_similarity_m")
    assert math.isclose(rigid["gtsam-batch"]["max_vs_bound"], 3.0)
    assert math.isclose(rigid["ekf"]["max_vs_bound"], 1.0)
    assert math.isclose(shape["gtsam-batch"]["max_vs_bound"], 1.0)
    assert math.isclose(shape["ekf"]["max_vs_bound"], 2.0)
