"""Hostile-input faults helper h151 fixed: each test failed before its fix. The rule: bad input
gets one line naming the file, the line and the field, exit status 2; never a traceback;
nothing overwritten or lost; solver failures reported, never called converged."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hostile_helpers import HEADER, bomgraph, odd_steps, one_error, write_jsonl

from bomgraph.errors import ConfigError
from bomgraph.mapper import check_method_options, create_mapper
from bomgraph.stream import StreamHeader

GTSAM = ["gtsam-batch", "gtsam-isam2", "hybrid", "oracle"]


def _run(stream: Path, method: str, out: Path, *options: str):
    truth = ("--allow-truth",) if method == "oracle" else ()
    return bomgraph("run", stream, "--method", method, "--out", out, *truth,
                    *(a for o in options for a in ("--option", o)))


def _with_truth(header: dict, n: int = 8) -> dict:
    """``header`` with truth poses (one per step) and landmarks, for the oracle."""
    return {**header, "truth": {"landmarks": [[0, 1.0, 1.0], [1, 1.0, -1.0], [2, -1.0, 1.0]],
                                "poses": [[0.1 * t, 0.0, 0.05 * t] for t in range(n)]}}


@pytest.mark.parametrize("method", GTSAM + ["triangulate"])
def test_a_move_no_graph_can_represent_is_refused_at_its_line(tmp_path: Path,
                                                               method: str) -> None:
    """A GTSAM method (and ``triangulate``) took a step of 1e200 m (the reader warns and
    accepts it) and reported only "did not converge" (triangulate: a map); the EKFs and
    STMDS refused it at its line. Now every one does."""
    stream = write_jsonl(tmp_path / "odd.jsonl", _with_truth(HEADER),
                         odd_steps(odom=[1e200, 0.0, 0.1]))
    est = tmp_path / "e.json"
    est.write_text("kept\n")
    one_error(_run(stream, method, est), f"{stream}, line 6: 'odom': step 4: ",
              "cannot use", "1e+200 m, beyond 1e+09 m", "fix the stream's odometry")
    assert est.read_text() == "kept\n"


def test_the_graphs_refuse_the_step_that_carries_the_robot_too_far(tmp_path: Path) -> None:
    """The bound is on the distance from the map origin the graph must represent (measured:
    docs/measurements.md), not on one move: two moves of 6e8 m (each under the bound, so
    STMDS takes them) put the robot 1.2e9 m out, refused at the second move's line."""
    steps = odd_steps(odom=[6e8, 0.0, 0.0])
    steps[5]["odom"] = [6e8, 0.0, 0.0]
    stream = write_jsonl(tmp_path / "odd.jsonl", HEADER, steps)
    one_error(_run(stream, "gtsam-isam2", tmp_path / "e.json"),
              f"{stream}, line 7: 'odom': step 5: gtsam-isam2 cannot use", "1.2e+09 m")


@pytest.mark.parametrize("method", ["gtsam-batch", "gtsam-isam2"])
def test_a_graph_refuses_a_bearing_sigma_that_carries_no_information(tmp_path: Path,
                                                                    method: str) -> None:
    """bearing_sigma_rad = 1e200: gtsam-batch mapped no landmark and called its solve
    converged (every landmark out of reach); the EKFs refused it at line 1."""
    stream = write_jsonl(tmp_path / "odd.jsonl", {**HEADER, "bearing_sigma_rad": 1e200},
                         odd_steps())
    one_error(_run(stream, method, tmp_path / "e.json"),
              f"{stream}, line 1: 'bearing_sigma_rad': {method} cannot use", "(0, pi]")


@pytest.fixture(scope="module")
def simulated(tmp_path_factory: pytest.TempPathFactory) -> list[str]:
    path = tmp_path_factory.mktemp("sim") / "s.jsonl"
    proc = bomgraph("simulate", "--steps", "60", "--out", path)
    assert proc.returncode == 0, proc.stderr
    return path.read_text().splitlines()


@pytest.mark.parametrize("sigma,before", [
    (1e100, "line 31: 'odom': step 29"),          # the predict overflowed 18 steps later
    (3e5, "estimate file: the checkpoint at t = 20"),  # covariances lost their precision
])
def test_an_ekf_refusal_names_the_sigma_that_caused_it(tmp_path: Path, simulated: list[str],
                                                       sigma: float, before: str) -> None:
    """A huge ``odom_sigma`` at step 11 made ekf-invdepth fail later, at another step's
    line and field (``before``), or when its estimate was written (naming no line)."""
    lines = list(simulated)
    step = json.loads(lines[12])
    step["odom_sigma"] = [sigma, sigma, 0.05]
    lines[12] = json.dumps(step)
    stream = tmp_path / "s.jsonl"
    stream.write_text("\n".join(lines) + "\n")
    line = one_error(_run(stream, "ekf-invdepth", tmp_path / "e.json"),
                     f"{stream}, line 13: 'odom_sigma': step 11: ekf-invdepth cannot use")
    assert before not in line


@pytest.mark.parametrize("value,problem", [
    ("[1, 2]", "must be [x_m, y_m, psi_rad] (three numbers), got [1, 2]"),
    ('"abc"', "must be [x_m, y_m, psi_rad] (three numbers), got 'abc'"),
    ("[1, 2, \"x\"]", "(three numbers)"),
    ("5", "(three numbers), got 5"),
    ("[1e300, 0, 0]", "must be finite, with x and y within 1e+09 m of the origin"),
])
@pytest.mark.parametrize("method", ["triangulate", "ekf", "gtsam-isam2", "hybrid"])
def test_a_bad_start_pose_is_refused_before_any_run(tmp_path: Path, method: str, value: str,
                                                    problem: str) -> None:
    """compare ran every run and failed each with a ValueError or an IndexError (exit 1;
    1e300: "no map", exit 0); ``run`` of hybrid printed a traceback. Now compare refuses the
    option before anything runs or is written, naming it."""
    stream = write_jsonl(tmp_path / "odd.jsonl", HEADER, odd_steps())
    out = tmp_path / "cmp"
    proc = bomgraph("compare", "--streams", stream, "--methods", method, "--option",
                    f"{method}:start_pose={value}", "--out", out, "--jobs", "1",
                    "--no-progress", "--no-figures")
    one_error(proc, f"method '{method}': option start_pose: ", problem)
    assert not (out / "results.json").exists()
    one_error(_run(stream, method, tmp_path / "e.json", f"start_pose={value}"),
              "option start_pose: ", problem)


def test_a_seed_mapper_that_is_no_mapper_is_refused_before_any_run(tmp_path: Path) -> None:
    """``--option seed_mapper=5`` failed every run at its first step with an AttributeError."""
    stream = write_jsonl(tmp_path / "odd.jsonl", HEADER, odd_steps())
    proc = bomgraph("compare", "--streams", stream, "--methods", "hybrid", "--option",
                    "hybrid:seed_mapper=5", "--out", tmp_path / "cmp", "--jobs", "1",
                    "--no-progress", "--no-figures")
    one_error(proc, "method 'hybrid': option seed_mapper: must be a mapper object", "int 5")
    assert not (tmp_path / "cmp" / "results.json").exists()


def test_start_pose_is_checked_where_it_enters_the_library() -> None:
    header = StreamHeader(0.05, (0.03, 0.0, 0.05), None)
    for method in ("triangulate", "ekf-invdepth", "gtsam-batch", "hybrid-isam2"):
        with pytest.raises(ConfigError, match="option start_pose: must be"):
            create_mapper(method, header, start_pose=(1.0, 2.0))
        with pytest.raises(ConfigError, match="method '.*': option start_pose: .* 1e[+]09 m"):
            check_method_options(method, {"start_pose": [2e9, 0.0, 0.0]})
        check_method_options(method, {"start_pose": [1e8, -1e8, 3.0]})


@pytest.mark.parametrize("method", ["stmds-smacof", "gtsam-isam2", "ekf"])
def test_a_known_distance_no_method_can_square_is_refused_at_line_1(tmp_path: Path,
                                                                     method: str) -> None:
    """A prior of 1e300 m (the reader warns and accepts it): here every method ran on
    (exit 0); on a simulated 60-step run STMDS failed at t = 50 blaming its own distance
    matrix ("complete it first (shortest_path_completion)"), naming no file, line or field,
    and the graphs reported an unconverged solve."""
    header = {**HEADER, "priors": [{"i": 0, "j": 1, "distance_m": 1e300, "sigma_m": 0.03}]}
    stream = write_jsonl(tmp_path / "odd.jsonl", header, odd_steps(60))
    one_error(_run(stream, method, tmp_path / "e.json"),
              f"{stream}, line 1: 'priors[0].distance_m': ", "cannot use a known distance of "
              "1e+300 m, beyond 1e+09 m", "fix the stream's priors")


def test_an_initial_pose_sigma_the_filter_cannot_hold_is_refused_before_any_run(
        tmp_path: Path) -> None:
    """``initial_pose_sigma=[1e300, 1, 1]`` passed the configuration (finite, >= 0) and
    failed every run of compare ("BearingEkf: the initial pose and its covariance must be
    finite", exit 1): refused before any run now, with the odometry's bound."""
    stream = write_jsonl(tmp_path / "odd.jsonl", HEADER, odd_steps())
    proc = bomgraph("compare", "--streams", stream, "--methods", "ekf", "--option",
                    "ekf:initial_pose_sigma=[1e300, 1, 1]", "--out", tmp_path / "cmp",
                    "--jobs", "1", "--no-progress", "--no-figures")
    one_error(proc, "initial_pose_sigma must be 3 numbers in [0, 100000]")
    assert not (tmp_path / "cmp" / "results.json").exists()


def test_an_estimate_header_of_another_format_is_named_at_line_1(tmp_path: Path) -> None:
    """A version-2 estimate whose line-1 header had another ``format`` was read as one
    version-1 JSON object and refused as "line 2: not valid JSON (Extra data at column 1)"."""
    stream = write_jsonl(tmp_path / "odd.jsonl", HEADER, odd_steps())
    est = tmp_path / "e.json"
    assert bomgraph("run", stream, "--method", "triangulate", "--out", est).returncode == 0
    lines = est.read_text().splitlines()
    lines[0] = lines[0].replace('"bomgraph-estimate"', '"bomgraph-estimat"')
    est.write_text("\n".join(lines) + "\n")
    for args in (("evaluate", est, stream),
                 ("export", est, "--format", "csv", "--out", tmp_path / "x.csv")):
        one_error(bomgraph(*args), f"{est}, line 1: 'format': must be \"bomgraph-estimate\", "
                                   f"got \"bomgraph-estimat\"")


@pytest.mark.parametrize("method", ["gtsam-batch", "gtsam-isam2", "hybrid"])
def test_a_sigma_floor_that_removes_all_odometry_information_is_refused(method: str) -> None:
    """``sigma_floor_m=1e300`` made every odometry factor carry no information, and
    gtsam-batch reported its solve (of a graph whose scale is free) converged."""
    with pytest.raises(ConfigError, match=r"sigma floors must be in \(0, 1e\+06\]"):
        check_method_options(method, {"sigma_floor_m": 1e300})
    check_method_options(method, {"sigma_floor_m": 0.01})
