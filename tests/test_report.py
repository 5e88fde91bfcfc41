"""Reports: summaries, the per-run table, the files and figures of compare, file evaluation."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from bomgraph.bench import Executor, execute
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.out_folder import MANIFEST, drop_earlier_outputs, unique_slugs
from bomgraph.report import (compare, error_curves, final_by_run, format_by_run,
                             format_summary, results_to_csv_rows, summarise)
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream

SMALL = SimConfig(n_steps=40, n_landmarks=20)


def _exp(arms: tuple[Arm, ...]) -> Experiment:
    return Experiment("t", "test", arms, SMALL, seed=3, n_layouts=2, n_starts=2)


def test_a_failing_method_is_reported_not_dropped() -> None:
    # an EKF state limit too small for one pose clone fails every run as it runs
    # (StateLimitError at t = 1); options refused before any run (min_parallax_rad=-1, h148;
    # a start pose of two values, h151) cannot make a run fail
    exp = _exp((Arm("tri", "triangulate"), Arm("bad", "ekf", {"max_state": 6})))
    results = execute(exp.tasks(), Executor("serial"))
    assert len(results) == 8
    bad = [r for r in results if r["arm"] == "bad"]
    assert all(not r["ok"] and "StateLimitError" in r["error"] for r in bad)
    rows = {r["arm"]: r for r in summarise(results)}
    assert rows["bad"]["failed"] == 4 and rows["tri"]["failed"] == 0
    # the per-run table names each failure and each run's own final score
    per_run = final_by_run(results)
    assert len(per_run) == 8
    assert all(not r["ok"] and "StateLimitError" in r["error"] for r in per_run
               if r["arm"] == "bad")
    tri = [r for r in per_run if r["arm"] == "tri"]
    assert all(r["t"] == 40 and 0 < r["mpe_m"] < 1.0 and r["n_mapped"] >= 3 for r in tri)
    text = format_by_run(per_run)
    bad_line = next(line for line in text.splitlines() if line.startswith("bad "))
    assert bad_line.split()[1:] == ["FAILED"] * 4
    assert f"{100 * tri[0]['mpe_m']:.1f} ({tri[0]['n_mapped']})" in text
    summary_text = format_summary(summarise(results))
    assert "FAILED 4" in summary_text and "== t ==" in summary_text


def test_error_curves_and_long_rows() -> None:
    results = execute(_exp((Arm("tri", "triangulate"),)).tasks(), Executor("serial"))
    (t, vals), = error_curves(results).values()
    assert t.tolist() == [10, 20, 30, 40] and vals.shape == (4, 4)
    assert np.all(np.isfinite(vals[:, -1]))
    rows = results_to_csv_rows(results)
    assert len(rows) == 16 and all(r["ok"] for r in rows)


def test_compare_writes_tables_and_figures(tmp_path: Path) -> None:
    exp = _exp((Arm("tri", "triangulate"),))
    res = compare([exp], tmp_path, executor=Executor("serial"))
    for name in ("results.json", "results.csv", "summary.csv", "t_error_vs_time.png"):
        assert (tmp_path / name).exists(), name
    assert res.summary[0]["runs"] == 4
    assert (tmp_path / "t_error_vs_time.png").stat().st_size > 10_000
    assert (tmp_path / "example_map.png").exists() or (tmp_path / "example_map.txt").exists()
    assert (tmp_path / "final_by_run.csv").exists()


def test_a_later_compare_leaves_no_figure_of_an_earlier_one(tmp_path: Path) -> None:
    """The figures of an earlier compare in the same folder (another experiment, or none
    drawn now) were left beside a results.json they no longer matched."""
    exp = _exp((Arm("tri", "triangulate"),))
    compare([exp], tmp_path, executor=Executor("serial"))
    mine = tmp_path / "notes.png"   # not a name compare writes: left alone
    mine.write_bytes(b"mine")
    drawn = {p.name for p in tmp_path.iterdir() if p.name.startswith(("t_", "example_map"))}
    assert "t_error_vs_time.png" in drawn and len(drawn) == 2
    other = Experiment("u", "other", exp.arms, SMALL, seed=3, n_layouts=1, n_starts=1)
    compare([other], tmp_path, executor=Executor("serial"))
    assert not (tmp_path / "t_error_vs_time.png").exists()
    assert (tmp_path / "u_error_vs_time.png").exists()
    compare([other], tmp_path, executor=Executor("serial"), figures=False)
    assert sorted(p.name for p in tmp_path.iterdir() if p.suffix in (".png", ".txt")) == [
        "notes.png"]


def _listed(folder: Path) -> dict[str, dict]:
    return {e["path"]: e for e in json.loads((folder / MANIFEST).read_text())["files"]}


def test_a_later_compare_removes_only_files_an_earlier_compare_wrote(tmp_path: Path) -> None:
    """A user's own file named as compare names its figures (``victoria_park_maps.png``) is
    not compare's to remove: only the files the earlier compare listed in its manifest go,
    and of those only the ones nobody changed since."""
    exp = _exp((Arm("tri", "triangulate"),))
    mine = tmp_path / "victoria_park_maps.png"
    mine.write_bytes(b"mine")
    compare([exp], tmp_path, executor=Executor("serial"))
    listed = _listed(tmp_path)
    assert "t_error_vs_time.png" in listed and "victoria_park_maps.png" not in listed
    edited = tmp_path / "example_map.png"                # compare's, then changed by the user
    edited.write_bytes(b"my annotated version")
    compare([exp], tmp_path, executor=Executor("serial"), figures=False)
    assert mine.read_bytes() == b"mine" and not (tmp_path / "t_error_vs_time.png").exists()
    assert edited.read_bytes() == b"my annotated version"


def test_a_manifest_never_reaches_outside_its_folder_or_through_a_link(tmp_path: Path
                                                                       ) -> None:
    out = tmp_path / "out"
    (out / "other").mkdir(parents=True)
    outside = tmp_path / "outside.png"
    for f in (outside, out / "other" / "r.est"):
        f.write_bytes(b"x")
    (out / "estimates").mkdir()
    (out / "estimates" / "e").symlink_to(out / "other")  # a folder link inside OUT
    entries = [{"path": p, "size": 1, "mtime_ns": f.stat().st_mtime_ns}
               for p, f in (("../outside.png", outside), (str(outside), outside),
                            ("estimates/e/r.est", out / "other" / "r.est"))]
    (out / MANIFEST).write_text(json.dumps({"format": "bomgraph-compare-files", "version": 1,
                                            "files": entries}))
    drop_earlier_outputs(out, [], [])
    assert outside.exists() and (out / "other" / "r.est").exists()
    assert _listed(out) == {}                            # and this compare wrote nothing
    for text in ("estimates/e/r.est\n", "[1, 2]", "null", '{"format": 3}'):  # not manifests
        (out / MANIFEST).write_text(text)
        drop_earlier_outputs(out, [], [])
        assert (out / "other" / "r.est").exists()


def test_names_make_files_without_separators_and_differ_beyond_case(tmp_path: Path) -> None:
    """A run labelled with a newline made a figure name of two lines; arms differing in case
    only shared one folder on a case-insensitive disk."""
    got = unique_slugs(["EKF", "ekf", "tri"])
    assert got["tri"] == "tri" and got["EKF"].casefold() != got["ekf"].casefold()
    src = tmp_path / "s.jsonl"
    write_stream(simulate(SMALL, np.random.default_rng(3)), src)
    exp = Experiment("e", "e", (Arm("tri", "triangulate"),),
                     sources=(FileSource(str(src), "thesis.tex\nz"),))
    compare([exp], tmp_path / "out", executor=Executor("serial"))
    names = [p.name for p in (tmp_path / "out").iterdir()]
    assert "e_thesis.tex_z_maps.png" in names and not [n for n in names if "\n" in n]


def test_error_curves_of_streams_of_different_lengths_do_not_depend_on_their_order(
        tmp_path: Path) -> None:
    """The curves span every run's checkpoints, whatever run comes first; a run that has ended
    is NaN after its last checkpoint (it was cut at the first run's times before)."""
    from bomgraph.experiments import FileSource
    from bomgraph.sim import simulate
    from bomgraph.stream_file import write_stream

    paths = []
    for steps in (25, 45):
        path = tmp_path / f"s{steps}.jsonl"
        write_stream(simulate(SimConfig(n_steps=steps, n_landmarks=15),
                              np.random.default_rng(steps)), path)
        paths.append(str(path))
    curves = []
    for order in (paths, paths[::-1]):
        exp = Experiment("f", "files", (Arm("tri", "triangulate"),),
                         sources=tuple(FileSource(p) for p in order))
        curves.append(error_curves(execute(exp.tasks(), Executor("serial"))))
    (t, vals), = curves[0].values()
    assert t.tolist() == [10, 20, 25, 30, 40, 45]
    assert np.isnan(vals[0, 3:]).all() and np.isfinite(vals[1, 1:]).all()
    (t2, vals2), = curves[1].values()
    assert t2.tolist() == t.tolist()
    np.testing.assert_array_equal(vals2[::-1], vals)


def test_a_map_with_nothing_to_score_it_by_is_not_called_no_map() -> None:
    """``final_by_run``'s text: a run on a stream without truth or reference whose method
    mapped landmarks but has no poses (so no bearing residual) was shown ``no map (50)``,
    which the legend defines as fewer than 3 landmarks. It now reads ``unscored (50)``;
    a run with fewer than 3 landmarks stays ``no map``."""
    def result(run: str, n: int) -> dict:
        nan = float("nan")
        return {"experiment": "streams", "arm": "stmds-smacof", "run": run, "ok": True,
                "scored_against": "none", "converged": None, "total_s": 0.1,
                "checkpoints": [{"t": 120, "n_mapped": n, "mpe_m": nan, "robot_last_m": nan,
                                 "bearing_rms_rad": nan}]}
    text = format_by_run(final_by_run([result("a", 50), result("b", 2)]))
    line = next(s for s in text.splitlines() if s.startswith("stmds-smacof "))
    assert line.split()[1:] == ["unscored", "(50)", "no", "map", "(2)"]
    assert "'unscored'" in text


def test_long_arm_and_run_names_are_not_cut_into_the_same_label() -> None:
    """The text tables cut arm labels to 30 characters and run names to their last 14, so
    two arms or two streams differing only beyond the cut got the same label and their
    numbers could not be told apart; the columns now widen to the longest name."""
    arms = ("stmds-smacof-loc@window-ba-long", "stmds-smacof-loc@window-ba-lon")
    runs = ("lab-a-mrclam6-robot3-keyframed", "lab-b-mrclam6-robot3-keyframed")

    def result(arm: str, run: str, mpe: float) -> dict:
        return {"experiment": "streams", "arm": arm, "method": "stmds-smacof-loc", "run": run,
                "ok": True, "converged": None, "total_s": 0.1,
                "checkpoints": [{"t": 100, "n_mapped": 15, "mpe_m": mpe, "robot_last_m": 0.1,
                                 "nees_pose": float("nan"), "nees_landmark": float("nan")}]}
    results = [result(a, r, 0.01 * (i + 1) * (j + 2)) for i, a in enumerate(arms)
               for j, r in enumerate(runs)]
    by_run = format_by_run(final_by_run(results)).splitlines()
    head = next(s for s in by_run if s.startswith("arm "))
    assert all(r in head.split() for r in runs)
    for a in arms:
        assert sum(s.split()[:1] == [a] for s in by_run) == 1
    summary = format_summary(summarise(results)).splitlines()
    for a in arms:
        assert sum(s.split()[:1] == [a] for s in summary) == 1


def test_results_json_gives_no_simulated_design_for_stream_experiments(tmp_path: Path) -> None:
    """results.json's ``experiments`` entries: an experiment on stream files said ``n_steps``
    300 and ``seed`` 0 (the default simulation's, which it never ran) whatever its streams
    held; they are now null there, and the design's for the paper's experiments."""
    src = tmp_path / "s25.jsonl"
    write_stream(simulate(SimConfig(n_steps=25, n_landmarks=12), np.random.default_rng(5)), src)
    exp = Experiment("f", "files", (Arm("tri", "triangulate"),),
                     sources=(FileSource(str(src)),))
    compare([exp, _exp((Arm("tri", "triangulate"),))], tmp_path / "out",
            executor=Executor("serial"), figures=False)
    files, design = json.loads((tmp_path / "out" / "results.json").read_text())["experiments"]
    assert files["n_steps"] is None and files["seed"] is None and files["runs"] == 1
    assert design["n_steps"] == 40 and design["seed"] == 3 and design["runs"] == 4


def test_robot_conv_and_nees_cells_say_when_only_some_runs_have_one() -> None:
    """The MPE cells say ``[k/n]`` when only k of the n runs that ran had a map; the robot,
    conv and NEES cells averaged over the runs that had a value without saying so (two ekf
    runs, one without a map at the end: its robot error 3.20 cm was shown as the row's)."""
    nan = float("nan")

    def result(run: str, robot: float, nees: float, conv) -> dict:
        return {"experiment": "e", "arm": "m", "method": "m", "run": run, "ok": True,
                "converged": conv, "total_s": 0.1,
                "checkpoints": [{"t": 50, "n_mapped": 15, "mpe_m": 0.05 if robot == robot
                                 else nan, "robot_last_m": robot, "nees_pose": nees,
                                 "nees_landmark": nan}]}
    rows = summarise([result("a", 0.032, 1.5, True), result("b", nan, nan, None)])
    line = format_summary(rows).splitlines()[-1].split()
    assert line[:3] == ["m", "2", "5.00/5.00±-[1/2]"]
    assert line[3:6] == ["3.20[1/2]", "100%[1/2]", "1.50[1/2]"]
    full = format_summary(summarise([result("a", 0.032, 1.5, True),
                                     result("b", 0.04, 2.5, False)])).splitlines()[-1]
    assert "[" not in full and " 3.60 " in full and " 50% " in full


def test_results_json_is_strict_json(tmp_path: Path) -> None:
    """results.json held bare ``NaN`` for every value that is not a number (1,976 of them in
    ``compare --quick --experiments exp1``: robot errors of runs without robot NEES, scores
    before a map), which jq, JavaScript's JSON.parse and R's jsonlite refuse. They are null
    now; the figures read null as a missing value."""
    src = tmp_path / "s25.jsonl"
    write_stream(simulate(SimConfig(n_steps=25, n_landmarks=12), np.random.default_rng(5)), src)
    exp = Experiment("f", "files", (Arm("tri", "triangulate"), Arm("bad", "ekf",
                                                                    {"max_state": 6})),
                     sources=(FileSource(str(src)),))
    compare([exp], tmp_path / "out", executor=Executor("serial"), figures=False)

    def refuse(token: str) -> None:
        raise AssertionError(f"results.json holds the non-JSON constant {token}")

    data = json.loads((tmp_path / "out" / "results.json").read_text(), parse_constant=refuse)
    rows = {r["arm"]: r for r in data["summary"]}
    assert rows["bad"]["failed"] == 1 and rows["tri"]["failed"] == 0
    # the values that were NaN are there, as null (nothing dropped)
    nulls = [k for r in data["summary"] for k, v in r.items() if v is None]
    assert nulls, "the summary of a run without robot NEES has missing values"


def test_a_diverged_map_prints_in_exponent_form_in_both_tables() -> None:
    """A map 8.7e8 m away (the hybrid once kept such landmarks on Victoria Park) printed as
    87000000000.00 cm in the summary and the per-run table."""
    def result(run: str, mpe: float) -> dict:
        return {"experiment": "e", "arm": "m", "method": "m", "run": run, "ok": True,
                "converged": True, "total_s": 0.1,
                "checkpoints": [{"t": 50, "n_mapped": 15, "mpe_m": mpe, "robot_last_m": 0.1,
                                 "nees_pose": float("nan"), "nees_landmark": float("nan")}]}
    results = [result("a", 8.7e8), result("b", 0.05)]
    summary = format_summary(summarise(results)).splitlines()[-1]
    assert "4.4e+10/4.4e+10±6.2e+10" in summary, summary
    by_run = format_by_run(final_by_run(results))
    assert "8.7e+10 (15)" in by_run and "5.0 (15)" in by_run, by_run


def test_the_summary_says_when_landmark_nees_values_were_left_out() -> None:
    """The landmark NEES of summary.csv is a mean over the values there are: runs without one
    (no covariances, a singular one) and landmarks without a covariance in a run's map
    (``info["covariances"] == "partial"``) were left out without a word (h41); a note line
    under the table now says which, and summary.csv counts the runs with one."""
    nan = float("nan")

    def result(arm: str, run: str, nees_landmark: float, covariances) -> dict:
        return {"experiment": "e", "arm": arm, "method": arm, "run": run, "ok": True,
                "converged": True, "total_s": 0.1, "info": {"covariances": covariances},
                "checkpoints": [{"t": 50, "n_mapped": 15, "mpe_m": 0.05, "robot_last_m": 0.03,
                                 "nees_pose": 2.0, "nees_landmark": nees_landmark}]}
    rows = summarise([result("g", "a", 1.0, True), result("g", "b", 3.0, "partial"),
                      result("g", "c", nan, False), result("k", "a", 2.0, None),
                      result("k", "b", 2.0, None)])
    g, k = rows
    assert (g["nees_landmark_mean"], g["n_nees_landmark"], g["n_nees_landmark_partial"]) == (
        2.0, 2, 1)
    assert (k["n_nees_landmark"], k["n_nees_landmark_partial"]) == (2, 0)
    note = format_summary(rows).splitlines()[-1]
    assert note == ("note: the landmark NEES (summary.csv nees_landmark_mean) is the mean over "
                    "the values there are; left out: g: 1 of 3 runs without one, 1 run "
                    "leaving out landmarks without a covariance (info covariances_undefined)")
    every = summarise([result("k", "a", 2.0, None), result("k", "b", 2.0, None)])
    assert not format_summary(every).splitlines()[-1].startswith("note:")


def test_a_stream_file_removed_during_compare_fails_its_runs_not_the_compare(
        tmp_path: Path) -> None:
    """A stream file removed while compare runs (after the first result) fails its runs in
    execute (h42/h43); compare then read it again for its map figure and, with estimates,
    for the names of the estimate files, and raised StreamFormatError after every run: no
    summary and the command's exit 2 (h45). Now those runs are failed runs in the outputs,
    the other sources' figures and estimates are written, and the removed one has no map
    figure."""
    streams = []
    for seed in range(3):
        streams.append(tmp_path / f"s{seed}.jsonl")
        write_stream(simulate(SMALL, np.random.default_rng(seed)), streams[-1])
    exp = Experiment("e", "e", (Arm("tri", "triangulate"),),
                     sources=tuple(FileSource(str(p)) for p in streams))

    def progress(done: int, total: int) -> None:
        if done >= 1 and streams[2].exists():
            streams[2].unlink()

    result = compare([exp], tmp_path / "out", executor=Executor("serial"), progress=progress,
                     estimates=True)
    by_run = {r["run"]: r for r in result.results}
    assert by_run["s0"]["ok"] and by_run["s1"]["ok"], by_run
    assert not by_run["s2"]["ok"] and by_run["s2"]["error"].startswith("StreamFormatError")
    out = tmp_path / "out"
    assert (out / "e_s0_maps.png").exists() and (out / "e_s1_maps.png").exists()
    assert not (out / "e_s2_maps.png").exists()
    assert len(list((out / "estimates").rglob("*.est"))) == 2


def test_an_arm_whose_every_run_failed_shows_no_nan_wall_time() -> None:
    """An arm every run of which raised showed ``nan`` in the table's ``wall s`` cell where
    its robot, conv and NEES cells show ``-``; it shows ``-`` now. summary.csv keeps ``nan``
    there, as in its other columns without a value."""
    ok = {"experiment": "e", "arm": "tri", "method": "triangulate", "run": "a", "ok": True,
          "converged": None, "total_s": 0.25,
          "checkpoints": [{"t": 50, "n_mapped": 15, "mpe_m": 0.05, "robot_last_m": 0.1,
                           "nees_pose": float("nan"), "nees_landmark": float("nan")}]}
    bad = {"experiment": "e", "arm": "crasher", "method": "crasher", "run": "a", "ok": False,
           "error": "ValueError: boom at 5"}
    rows = summarise([bad, ok])
    text = format_summary(rows).splitlines()
    head = next(s for s in text if s.startswith("arm "))
    failed = next(s for s in text if s.startswith("crasher "))
    assert "nan" not in failed.lower()
    wall_end = head.index("wall s") + len("wall s")
    assert failed[wall_end - 7:wall_end].strip() == "-"
    good = next(s for s in text if s.startswith("tri "))
    assert good[wall_end - 7:wall_end].strip() == "0.250"
    assert np.isnan(rows[0]["wall_s_mean"]) and rows[1]["wall_s_mean"] == 0.25


def test_an_arm_whose_every_run_failed_is_scored_against_nothing() -> None:
    """On streams without truth the table's last column said ``truth`` for an arm whose
    every run failed (no run was scored against anything), and its row brought back the MPE
    columns that a table of truth-free runs without a reference leaves out (every cell
    ``-``); it shows ``-`` now, as the other cells of that row do, and counts for neither."""
    free = {"experiment": "e", "arm": "tri", "method": "triangulate", "run": "a", "ok": True,
            "converged": None, "total_s": 0.25, "scored_against": "none",
            "checkpoints": [{"t": 50, "n_mapped": 15, "mpe_m": float("nan"),
                             "robot_last_m": float("nan"), "bearing_rms_rad": 0.01,
                             "nees_pose": float("nan"), "nees_landmark": float("nan")}]}
    bad = {"experiment": "e", "arm": "crasher", "method": "crasher", "run": "a", "ok": False,
           "error": "ValueError: boom at 5"}
    text = format_summary(summarise([bad, free])).splitlines()
    failed = next(s for s in text if s.startswith("crasher "))
    cells = failed.split("FAILED")[0].split()[2:]
    assert "truth" not in failed and cells == ["-"] * len(cells), failed
    head = next(s for s in text if s.startswith("arm "))
    assert "t=50" not in head  # no truth, no reference: no MPE column, as without the failure
