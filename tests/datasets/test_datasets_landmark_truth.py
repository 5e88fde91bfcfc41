"""The landmark table checked against the detections' range-bearing pair distances, and the
known erratum of MRCLAM Dataset 1 (landmarks 11 and 17 exchanged) corrected on import."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from dataset_excerpts import BARCODES, DATA, LANDMARKS, make_mrclam, needs_data

from bomgraph.cli import main as bomgraph_main
from bomgraph.datasets.landmark_truth import (KNOWN_ERRATA, MAX_PAIR_ERROR_M, apply_errata,
                                              check_landmark_table, pair_distance_residuals)
from bomgraph.datasets.mrclam import import_mrclam
from bomgraph.datasets.mrclam_files import read_mrclam_robot
from bomgraph.errors import DatasetError
from bomgraph.stream_file import read_stream

ERRATUM = KNOWN_ERRATA[0]
#: Dataset 1 as the measurements place them: 11 and 17 at each other's listed positions.
TRUE_11_17 = {11: ERRATUM.listed[17], 17: ERRATUM.listed[11]}


def test_pair_distances_are_pose_free_and_only_within_one_frame():
    ids = np.array([6, 7, 8])
    xy = np.array([[0.0, 0.0], [3.0, 0.0], [0.0, 4.0]])
    robot = np.array([1.0, -2.0, 0.7])  # any pose: the pair distance does not depend on it
    rel = xy - robot[:2]
    rng = np.hypot(*rel.T)
    brg = np.arctan2(rel[:, 1], rel[:, 0]) - robot[2]
    time = np.array([5.0, 5.0, 5.0, 6.0, 6.0])
    subj = np.array([6, 7, 8, 7, 2])        # subject 2 (a robot) is ignored
    a, b, r = pair_distance_residuals(time, subj, np.r_[rng, 9.0, 1.0], np.r_[brg, 0.0, 0.0],
                                      ids, xy)
    assert sorted(zip(ids[a].tolist(), ids[b].tolist())) == [(6, 7), (6, 8), (7, 8)]
    np.testing.assert_allclose(r, 0.0, atol=1e-12)
    # a mirrored bearing convention gives the same distances
    _, _, r2 = pair_distance_residuals(time[:3], subj[:3], rng, -brg, ids, xy)
    np.testing.assert_allclose(r2, 0.0, atol=1e-12)


def test_apply_errata_matches_the_listed_values_only():
    ids = np.array([9, 11, 17])
    listed = np.array([[1.0, 2.0], ERRATUM.listed[11], ERRATUM.listed[17]])
    fixed, applied = apply_errata(ids, listed)
    np.testing.assert_array_equal(fixed[1:], listed[[2, 1]])
    np.testing.assert_array_equal(fixed[0], listed[0])
    assert applied and applied[0]["swapped"] == [11, 17]
    assert np.all(listed[1] == ERRATUM.listed[11])  # the input is not mutated
    # an already corrected table (or any other) is left alone
    again, none = apply_errata(ids, fixed)
    np.testing.assert_array_equal(again, fixed)
    assert none == []


def test_a_table_with_two_landmarks_exchanged_is_refused_naming_the_swap(tmp_path: Path):
    make_mrclam(tmp_path, listed={6: LANDMARKS[9], 9: LANDMARKS[6]})
    with pytest.raises(DatasetError, match=r"landmarks 6 and 9 explains") as info:
        import_mrclam(tmp_path, 1)
    assert "--no-landmark-check" in str(info.value)
    # taken as read on request: the faulty positions reach the truth
    s = import_mrclam(tmp_path, 1, landmark_check=False)
    k = list(s.truth.landmark_ids).index(6)
    np.testing.assert_array_equal(s.truth.landmarks_xy[k], LANDMARKS[9])
    assert s.header.meta["landmark_truth"] == {"checked": False}


def test_a_consistent_table_passes_with_zero_pair_error(tmp_path: Path):
    make_mrclam(tmp_path)
    s = import_mrclam(tmp_path, 1)
    check = s.header.meta["landmark_truth"]["check"]
    assert check["failing"] == [] and check["swap"] is None
    assert check["max_pair_error_m"] == pytest.approx(0.0, abs=1e-9)
    assert s.header.meta["landmark_truth"]["errata_applied"] == []


def test_the_dataset1_erratum_is_corrected_on_import(tmp_path: Path):
    world = {k: v for k, v in LANDMARKS.items() if k != 11} | TRUE_11_17
    codes = BARCODES | {17: 61}
    make_mrclam(tmp_path, landmarks=world, listed=dict(ERRATUM.listed), barcodes=codes)
    s = import_mrclam(tmp_path, 1)
    lt = s.header.meta["landmark_truth"]
    assert [e["swapped"] for e in lt["errata_applied"]] == [[11, 17]]
    assert lt["check"]["failing"] == []
    for lid in (11, 17):
        k = list(s.truth.landmark_ids).index(lid)
        np.testing.assert_array_equal(s.truth.landmarks_xy[k], TRUE_11_17[lid])
    # the CLI does the same, and --no-landmark-check keeps the listed (wrong) rows
    out = tmp_path / "o.jsonl"
    assert bomgraph_main(["import", "mrclam", str(tmp_path), "--robot", "1", "--out", str(out),
                          "-q", "--no-landmark-check"]) == 0
    t = read_stream(out).truth
    np.testing.assert_array_equal(t.landmarks_xy[list(t.landmark_ids).index(11)],
                                  ERRATUM.listed[11])


@needs_data
@pytest.mark.parametrize("robot", [1, 2, 3, 4, 5])
def test_mrclam1_table_as_published_contradicts_every_robot(robot: int):
    """The evidence for the erratum: as published, 11 and 17 fail on every robot and
    exchanging them (and nothing else) makes every landmark consistent."""
    raw = read_mrclam_robot(DATA / "mrclam1", robot)
    me = raw.measurements
    subj = np.array([raw.barcode_subject.get(b, -1) for b in me["barcode"].tolist()])
    args = (me["time_s"], subj, me["range_m"], me["bearing_rad"], raw.landmark_ids)
    as_read = check_landmark_table(*args, raw.landmarks_xy)
    assert as_read["failing"] == [11, 17] and as_read["swap"] == [11, 17]
    fixed = check_landmark_table(*args, apply_errata(raw.landmark_ids, raw.landmarks_xy)[0])
    assert fixed["failing"] == [] and fixed["max_pair_error_m"] < MAX_PAIR_ERROR_M


@needs_data
def test_mrclam6_needs_no_erratum_and_passes():
    s = import_mrclam(DATA / "mrclam6", 3)
    lt = s.header.meta["landmark_truth"]
    assert lt["errata_applied"] == [] and lt["check"]["failing"] == []
    assert lt["check"]["max_pair_error_m"] < 0.2


def test_the_cli_refuses_a_contradicting_table_in_one_line(tmp_path: Path, capsys):
    make_mrclam(tmp_path, listed={6: LANDMARKS[9], 9: LANDMARKS[6]})
    out = tmp_path / "o.jsonl"
    assert bomgraph_main(["import", "mrclam", str(tmp_path), "--robot", "1",
                          "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("bomgraph: error:"), err
    assert "landmarks 6 and 9" in err[0] and "--no-landmark-check" in err[0]
    assert not out.exists()
