"""``bomgraph evaluate --format/--align/--reference`` and ``bomgraph plot`` (issue 17, points
3 and 4): outputs parse, figures are non-empty with the right size and colours."""

from __future__ import annotations

import csv
import io
import json
import re
from pathlib import Path

import numpy as np
import pytest

from bomgraph.cli import main
from bomgraph.estimate_file import write_estimate
from bomgraph.mapper import Checkpoint, MapEstimate, RunResult
from bomgraph.plots import method_colour, run_figure, results_figure
from bomgraph.stream import Step, Stream, StreamHeader, Truth
from bomgraph.stream_file import write_stream


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> tuple[Path, Path, Path]:
    d = tmp_path_factory.mktemp("ev")
    s, e, r = d / "s.jsonl", d / "e.json", d / "r.json"
    assert main(["simulate", "--seed", "1", "--steps", "40", "--landmarks", "20",
                 "--out", str(s)]) == 0
    assert main(["run", str(s), "--method", "ekf", "--out", str(e)]) == 0
    assert main(["run", str(s), "--method", "triangulate", "--out", str(r)]) == 0
    return s, e, r


def _out(capsys, argv) -> str:
    capsys.readouterr()
    assert main(argv) == 0
    return capsys.readouterr().out


def test_formats_parse_or_hold_the_rows(files, capsys) -> None:
    s, e, _ = files
    obj = json.loads(_out(capsys, ["evaluate", str(e), str(s), "--format", "json"]))
    assert obj["checkpoints"]["t"] == [10, 20, 30, 40] and obj["align_on"] == "landmarks"
    assert obj["n_rpe_pairs"] > 0 and obj["bearing_n"] > 0
    rows = list(csv.DictReader(io.StringIO(_out(capsys, ["evaluate", str(e), str(s),
                                                         "--format", "csv"]))))
    assert [r["t"] for r in rows] == ["10", "20", "30", "40"]
    assert float(rows[-1]["mpe_m"]) == pytest.approx(obj["mpe_m"])
    md = _out(capsys, ["evaluate", str(e), str(s), "--format", "markdown"])
    assert "| 40 |" in md and "| t | mapped |" in md
    tex = _out(capsys, ["evaluate", str(e), str(s), "--format", "latex"])
    assert "\\begin{tabular}" in tex and "\n40 & " in tex
    assert f"{100 * obj['mpe_m']:.2f}" in tex.splitlines()[-4]


def test_align_trajectory_and_reference(files, capsys) -> None:
    s, e, r = files
    lm = json.loads(_out(capsys, ["evaluate", str(e), str(s), "--json"]))
    tr = json.loads(_out(capsys, ["evaluate", str(e), str(s), "--json", "--align",
                                  "trajectory", "--delta", "2"]))
    assert tr["ape_trans_rmse_m"] <= lm["ape_trans_rmse_m"] + 1e-12
    assert tr["rpe_delta"] == 2
    ref = json.loads(_out(capsys, ["evaluate", str(e), str(s), "--json", "--reference", str(r)]))
    assert ref["reference"] == "triangulate" and ref["reference_bearing_n"] > 0
    self_ = json.loads(_out(capsys, ["evaluate", str(r), str(s), "--json", "--reference", str(r)]))
    assert self_["mpe_m"] < 1e-9 and self_["ape_trans_rmse_m"] < 1e-9


def _png_pixels(path: Path) -> np.ndarray:
    from matplotlib.image import imread

    return imread(str(path))


def test_plot_writes_png_pdf_svg(files, tmp_path, capsys) -> None:
    s, e, _ = files
    for ext in ("png", "pdf", "svg"):
        out = tmp_path / f"p.{ext}"
        assert main(["plot", str(e), str(s), "--out", str(out)]) == 0
        assert out.stat().st_size > 1000
    assert (tmp_path / "p.pdf").read_bytes()[:5] == b"%PDF-"
    assert b"<svg" in (tmp_path / "p.svg").read_bytes()[:500]
    img = _png_pixels(tmp_path / "p.png")
    assert img.shape[0] == 900 and img.shape[1] > 900   # 6 in high at 150 dpi
    assert np.allclose(img[2, 2, :3], 1.0)               # white background
    want = np.array([int(method_colour("ekf")[k:k + 2], 16) for k in (1, 3, 5)]) / 255
    assert np.any(np.all(np.abs(img[..., :3] - want) < 0.02, axis=-1))  # the ekf trajectory
    assert main(["plot", str(e), str(s), "--out", str(tmp_path / "x.gif")]) == 2
    assert main(["plot", str(e), str(s), "--t", "7", "--out", str(tmp_path / "y.png")]) == 2


def test_plot_results_folder(tmp_path) -> None:
    t = [10, 20]
    res = [{"experiment": "exp1", "arm": arm, "method": arm.split(" ")[0], "run": f"r{k}",
            "ok": True, "checkpoints": [{"t": tt, "mpe_m": 0.01 * (k + 1) * (i + 1) / tt}
                                        for tt in t]}
           for i, arm in enumerate(["gtsam-batch", "stmds-smacof (improved)"]) for k in range(4)]
    (tmp_path / "results.json").write_text(json.dumps({"experiments": [
        {"name": "exp1", "title": "Exp. 1", "runs": 4}], "results": res}))
    for kind in ("box", "violin"):
        out = tmp_path / f"r_{kind}.png"
        assert main(["plot", "--results", str(tmp_path), "--kind", kind, "--out", str(out)]) == 0
        img = _png_pixels(out)
        want = np.array([int(method_colour("gtsam-batch")[k:k + 2], 16) for k in (1, 3, 5)]) / 255
        assert np.any(np.all(np.abs(img[..., :3] - want) < 0.02, axis=-1))
    assert main(["plot", "--results", str(tmp_path / "none"), "--out", str(out)]) == 2



@pytest.mark.parametrize("content", ['{"results": [1, 2]}', '{"results": [{"experiment": "e"}]}',
                                     "[" * 100_000 + "]" * 100_000])
def test_plot_results_of_the_wrong_shape_is_one_line(tmp_path, capsys, content: str) -> None:
    # rows of the wrong shape and deep nesting were tracebacks (session 12)
    (tmp_path / "results.json").write_text(content)
    assert main(["plot", "--results", str(tmp_path), "--out", str(tmp_path / "r.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a compare results file" in err[0], err

def test_plot_results_of_another_format_says_what_is_missing_and_what_to_do(
        tmp_path, capsys) -> None:
    """A results.json whose results have no ``arm`` (not one bomgraph's ``compare`` ever wrote:
    every format since the first has it; h92 drew those of 7efaa1f and of before the
    ``self_scored`` marks correctly) was refused as ``not a compare results file
    (KeyError)``, naming neither the key nor what to do. Fails before h92."""
    rows = [{"experiment": "e", "method": "triangulate", "run": "r", "ok": True,
             "checkpoints": [{"t": 10, "mpe_m": 0.1}]}]
    (tmp_path / "results.json").write_text(json.dumps({"method": "triangulate",
                                                       "results": rows}))
    assert main(["plot", "--results", str(tmp_path), "--out", str(tmp_path / "r.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a compare results file (KeyError 'arm')" in err[0], err
    assert "bomgraph compare --out" in err[0], err
    assert not (tmp_path / "r.png").exists()


def test_palette_is_per_method_and_ellipses_are_drawn() -> None:
    assert method_colour("ekf") == method_colour("ekf")
    assert method_colour("stmds-smacof (improved)") != method_colour("stmds-smacof")
    assert method_colour("stmds-smacof-loc") != method_colour("stmds-smacof")
    truth = Truth(np.arange(3), np.array([[0.0, 0], [1, 0], [0, 1]]))
    est = MapEstimate(np.arange(3), truth.landmarks_xy, landmark_cov=np.tile(np.eye(2) * 1e-3,
                                                                           (3, 1, 1)))
    fig = run_figure(truth, est, None, label="ekf", landmark_cov=est.landmark_cov)
    labels = fig.axes[0].get_legend_handles_labels()[1]
    assert "95 % ellipses" in labels
    fig = results_figure({"e": {"a": np.array([0.1, np.nan])}}, {}, kind="violin")
    assert len(fig.axes) == 2


def test_a_stream_without_truth_gets_the_truth_free_measures(files, tmp_path, capsys) -> None:
    """No truth, no --reference: per checkpoint the landmarks mapped and the RMS bearing
    residual of the map and trajectory against the stream's own bearings, checked here by
    an independent computation; the alignment options are refused in one line."""
    from bomgraph.angles import angle_residual
    from bomgraph.estimate_file import read_estimate
    from bomgraph.stream_file import read_stream

    s, e, _ = files
    lines = s.read_text().splitlines()
    head = json.loads(lines[0])
    del head["truth"]
    bare = tmp_path / "bare.jsonl"
    bare.write_text("\n".join([json.dumps(head), *lines[1:]]) + "\n")
    text = _out(capsys, ["evaluate", str(e), str(bare)])
    assert "no ground truth" in text and "bearing residual RMS" in text
    obj = json.loads(_out(capsys, ["evaluate", str(e), str(bare), "--json"]))
    assert obj["truth"] is False and obj["checkpoints"]["t"] == [10, 20, 30, 40]
    steps = read_stream(bare).steps
    for k, c in enumerate(read_estimate(e).checkpoints):
        pos = {int(i): xy for i, xy in zip(c.estimate.landmark_ids, c.estimate.landmarks_xy)}
        pose = dict(zip(c.estimate.pose_t.tolist(), c.estimate.poses))
        r = [angle_residual(np.arctan2(*(pos[i] - pose[st.t][:2])[::-1]) - pose[st.t][2], b)
             for st in steps[: c.t + 1] for i, b in zip(st.landmark_ids.tolist(),
                                                        st.bearings_rad.tolist())
             if i in pos and st.t in pose]
        assert obj["checkpoints"]["n_bearings"][k] == len(r) > 0
        assert obj["checkpoints"]["bearing_rms_rad"][k] == pytest.approx(
            float(np.sqrt(np.mean(np.square(r)))), rel=1e-9)
        assert obj["checkpoints"]["n_mapped"][k] == len(c.estimate)
    assert obj["bearing_rms_rad"] == obj["checkpoints"]["bearing_rms_rad"][-1]
    rows = list(csv.DictReader(io.StringIO(_out(capsys, ["evaluate", str(e), str(bare),
                                                         "--format", "csv"]))))
    assert [int(r["t"]) for r in rows] == [10, 20, 30, 40] and "bearing_rms_rad" in rows[0]
    capsys.readouterr()
    assert main(["evaluate", str(e), str(bare), "--similarity"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nothing to align to" in err[0]


def test_plot_of_an_earlier_checkpoint_claims_no_robot_ape_of_revised_poses(
        files, tmp_path, monkeypatch) -> None:
    """``bomgraph plot --t T`` of a method that revises its poses (gtsam-batch): the file keeps
    each pose of an earlier checkpoint as first estimated, so the title's "robot APE" and the
    pose-error panel at T were of a trajectory the method never held; they are left out
    there and the title says why. A method that keeps its poses (ekf) keeps them."""
    import bomgraph.figures as figures

    s, e, _ = files
    g = tmp_path / "g.est"
    assert main(["run", str(s), "--method", "gtsam-batch", "--out", str(g)]) == 0
    seen = []
    real = figures.run_figure
    monkeypatch.setattr(figures, "run_figure",
                        lambda *a, **k: seen.append(k) or real(*a, **k))
    for est, revised in ((g, True), (e, False)):
        seen.clear()
        assert main(["plot", str(est), str(s), "--t", "20", "--out",
                     str(tmp_path / "p.png")]) == 0
        title, pe = seen[0]["title"], seen[0]["pose_errors"]
        assert (re.search(r"robot APE \d", title) is None) == revised
        assert (pe is None) == revised
        assert ("first estimated" in title) == revised
    assert main(["plot", str(g), str(s), "--align", "trajectory", "--t", "20", "--out",
                 str(tmp_path / "p.png")]) == 2


# ---- evaluate on awkward estimate files (h37 audit) -----------------------------------------

def _line_world(tmp_path: Path) -> tuple[Path, Stream]:
    """12 poses along y = -0.5 heading +x (a collinear trajectory whose headings lie along
    it), 6 landmarks off the line, bearings exact."""
    lm = np.array([[0.0, 1.0], [1.0, 2.0], [2.0, 0.8], [3.0, 1.7], [1.5, -2.0], [2.5, -1.1]])
    poses = np.column_stack([np.linspace(0.0, 3.0, 12), np.full(12, -0.5), np.zeros(12)])
    steps = tuple(Step(t, None if t == 0 else [3 / 11, 0.0, 0.0], np.arange(6),
                       np.arctan2(lm[:, 1] - poses[t, 1], lm[:, 0] - poses[t, 0]))
                  for t in range(12))
    stream = Stream(StreamHeader(0.01, (0.01, 0.0, 0.01)), steps,
                    Truth(np.arange(6), lm, poses))
    write_stream(stream, tmp_path / "line.jsonl")
    return tmp_path / "line.jsonl", stream


def _est_file(path: Path, est: MapEstimate, t: int) -> Path:
    write_estimate(RunResult("mine", (Checkpoint(t, est, 0.0),), np.zeros(1), 0.0), path)
    return path


def _evaluate(capsys, *argv) -> tuple[int, str, list[str]]:
    capsys.readouterr()
    code = main(["evaluate", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err.strip().splitlines()


def test_too_few_common_landmarks_names_the_file_the_map_and_whom(tmp_path, capsys) -> None:
    """A final map sharing 2 landmarks with the truth, or with a --reference estimate: one
    line naming the estimate file and the final map, and the truth or the reference (it
    said "with the truth" against a reference, and named no file)."""
    s, stream = _line_world(tmp_path)
    t = stream.truth
    two = _est_file(tmp_path / "two.est", MapEstimate(t.landmark_ids[:2], t.landmarks_xy[:2]), 11)
    full = _est_file(tmp_path / "full.est", MapEstimate(t.landmark_ids, t.landmarks_xy), 11)
    code, out, err = _evaluate(capsys, two, s)
    assert code == 2 and out == "" and len(err) == 1, err
    assert str(two) in err[0] and "final map (t = 11)" in err[0]
    assert "2 landmarks with the truth" in err[0]
    code, out, err = _evaluate(capsys, full, s, "--reference", two)
    assert code == 2 and len(err) == 1 and str(full) in err[0], err
    assert "with the reference estimate" in err[0] and "truth" not in err[0], err
    code, _, err = _evaluate(capsys, full, s, "--align", "trajectory")
    assert code == 2 and "the estimate has no poses: align on landmarks" in err[0], err
    assert main(["plot", str(two), str(s), "--out", str(tmp_path / "p.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{two}: the final map: the estimate shares 2" in err[0], err


def test_coincident_and_collinear_fits_say_what_is_undefined(tmp_path, capsys) -> None:
    """Rank 0 (every landmark of the estimate at one point) leaves the rotation undetermined,
    not a mirror tie; a collinear trajectory fit whose tie nothing breaks leaves the landmark
    errors undefined, not the robot's (which it prints)."""
    s, stream = _line_world(tmp_path)
    t = stream.truth
    one_point = _est_file(tmp_path / "p.est", MapEstimate(t.landmark_ids, np.ones((6, 2)),
                                                         np.arange(12), t.poses), 11)
    code, out, _ = _evaluate(capsys, one_point, s)
    assert code == 0
    assert "rotation is undetermined" in out and "mirror tie" not in out, out
    assert "robot position error" not in out  # undefined: not printed
    # the trajectory alone (no common landmark, headings along the line): the mirror tie stays
    line = _est_file(tmp_path / "l.est", MapEstimate(np.arange(100, 103), t.landmarks_xy[:3],
                                                     np.arange(12), t.poses), 11)
    code, out, _ = _evaluate(capsys, line, s, "--align", "trajectory")
    assert code == 0 and "robot position error: last 0.00 cm" in out, out
    assert "landmark errors undefined" in out and "robot errors undefined" not in out, out


def test_duplicate_and_foreign_landmark_ids(tmp_path, capsys) -> None:
    """An estimate line with a landmark id twice is refused by file, line and key; ids the
    truth lacks are counted in the estimate and left out of the score."""
    s, stream = _line_world(tmp_path)
    t = stream.truth
    good = _est_file(tmp_path / "g.est", MapEstimate(
        np.r_[t.landmark_ids, 50, 51], np.vstack([t.landmarks_xy, [[9.0, 9.0], [8.0, 1.0]]])), 11)
    code, out, _ = _evaluate(capsys, good, s)
    assert code == 0 and "6 of 6 landmarks of the truth mapped (8 in the estimate)" in out, out
    assert "landmark MPE 0.00 cm" in out
    lines = good.read_text().splitlines()
    row = json.loads(lines[1])
    row["landmarks"].append(row["landmarks"][0])
    dup = tmp_path / "dup.est"
    dup.write_text("\n".join([lines[0], json.dumps(row), *lines[2:]]) + "\n")
    code, out, err = _evaluate(capsys, dup, s)
    assert code == 2 and len(err) == 1 and f"{dup}, line 2: 'landmarks'" in err[0], err
    assert "appears twice" in err[0]


def test_similarity_with_an_earlier_map_at_one_point_scores_the_rest(tmp_path, capsys) -> None:
    """``evaluate --similarity``: a checkpoint whose landmarks all sit at one point has no
    scale; its row is '-' like a map of too few landmarks, and the rest is scored (the whole
    evaluation stopped at it with "align(): all source points coincide", naming neither the
    file nor the checkpoint)."""
    s, stream = _line_world(tmp_path)
    t = stream.truth
    first = MapEstimate(t.landmark_ids, np.ones((6, 2)))
    final = MapEstimate(t.landmark_ids, 2.0 * t.landmarks_xy)
    est = tmp_path / "e.est"
    write_estimate(RunResult("mine", (Checkpoint(5, first, 0.0), Checkpoint(11, final, 0.0)),
                             np.zeros(1), 0.0), est)
    code, out, err = _evaluate(capsys, est, s, "--similarity", "--format", "csv")
    assert code == 0, err
    rows = list(csv.DictReader(io.StringIO(out)))
    assert [r["t"] for r in rows] == ["5", "11"] and rows[0]["mpe_m"] == ""
    assert float(rows[1]["mpe_m"]) < 1e-12  # the final map is the truth at twice the scale
    one = _est_file(tmp_path / "one.est", first, 11)
    code, _, err = _evaluate(capsys, one, s, "--similarity")
    assert code == 2 and len(err) == 1 and f"{one}: the final map (t = 11)" in err[0], err
    assert "scale is undefined" in err[0]


def test_results_figure_labels_an_arm_whose_runs_failed_as_failed(tmp_path) -> None:
    """h152: `bomgraph plot --results` labelled an arm whose every run raised "(no map)", as
    if it had run and mapped too little; compare's tables say FAILED."""
    from bomgraph.figures import _failed_runs

    rows = [{"experiment": "e", "arm": a, "ok": ok} for a, ok in (
        ("crash", False), ("crash", False), ("few", True), ("few", True), ("mixed", False),
        ("mixed", True), ("good", True), ("good", True), ("mixed3", False), ("mixed3", True),
        ("mixed3", True))]
    failed = _failed_runs({"results": rows})
    assert failed == {"e": {"crash": 2, "few": 0, "mixed": 1, "good": 0, "mixed3": 1}}
    nan = np.nan
    final = {"e": {"crash": np.array([nan, nan]), "few": np.array([nan, nan]),
                   "mixed": np.array([nan, nan]), "good": np.array([0.1, 0.2]),
                   "mixed3": np.array([nan, nan, nan])}}
    fig = results_figure(final, {}, failed=failed)
    ticks = [t.get_text() for t in fig.axes[0].get_xticklabels()]
    assert ticks == ["crash (FAILED)", "few (no map)",        # h154: "the other", one run
                     "mixed (1 of 2 FAILED, the other no map)", "good",
                     "mixed3 (1 of 3 FAILED, the others no map)"], ticks
