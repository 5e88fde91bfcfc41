"""Hostile input to ``bomgraph compare`` and to method options found by the eighteenth
session's audit (helper ``helper-12``): an input stream among compare's outputs, a bad Dask
scheduler address, huge numbers in a sweep file and in options, malformed stream files, an
infinite convergence tolerance. Each is one line and exit 2, nothing overwritten."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest

from hostile_helpers import bomgraph, one_error, snapshot

from bomgraph.bench import Executor
from bomgraph.errors import ConfigError
from bomgraph.sweep import scheduler_address_problem

COMPARE = ("--methods", "triangulate", "--jobs", "1", "--no-figures", "--no-progress")


@pytest.mark.parametrize("name", ["results.json", "summary.csv", "final_by_run.csv",
                                  "exp_error_vs_time.png", "cache/x.json",
                                  "estimates/a/b.jsonl"])
def test_an_input_stream_compare_would_overwrite_is_refused_before_any_run(
        work: Path, name: str) -> None:
    out = work / "out"
    target = out / name
    target.parent.mkdir(parents=True)
    shutil.copy(work / "s.jsonl", target)
    before = snapshot(work)
    one_error(bomgraph("compare", "--streams", target, *COMPARE, "--out", out),
              "refusing to overwrite an input", name.split("/")[-1])
    assert snapshot(work) == before                  # nothing written, the input intact


def test_a_link_to_an_input_is_refused_too(work: Path) -> None:
    out = work / "out"
    out.mkdir()
    os.symlink(work / "s.jsonl", out / "results.csv")
    before = snapshot(work)
    one_error(bomgraph("compare", "--streams", out / "results.csv", *COMPARE, "--out", out),
              "refusing to overwrite an input")
    assert snapshot(work) == before


def test_an_input_in_the_folder_under_another_name_is_kept(work: Path) -> None:
    out = work / "out"
    out.mkdir()
    shutil.copy(work / "s.jsonl", out / "mine.jsonl")
    proc = bomgraph("compare", "--streams", out / "mine.jsonl", *COMPARE, "--out", out)
    assert proc.returncode == 0, proc.stderr.decode()
    assert (out / "mine.jsonl").read_bytes() == (work / "s.jsonl").read_bytes()
    assert (out / "results.json").is_file()


@pytest.mark.parametrize("address", ["nonsense", "tcp://host", "tcp://:", "host:99999", ""])
def test_a_bad_scheduler_address_is_one_line(work: Path, address: str) -> None:
    if address:
        one_error(bomgraph("compare", "--streams", work / "s.jsonl", "--methods", "triangulate",
                           "--scheduler", address, "--out", work / "out"), "scheduler")
    (work / "sweep.toml").write_text(f'streams = ["s.jsonl"]\nmethods = ["triangulate"]\n'
                                     f'[executor]\nscheduler = "{address}"\n')
    one_error(bomgraph("compare", "--config", work / "sweep.toml", "--out", work / "out2"),
              "sweep.toml", "executor.scheduler")
    assert not (work / "out").exists() and not (work / "out2").exists()


@pytest.mark.parametrize("address", ["tcp://127.0.0.1:8786", "localhost:8786",
                                     "tls://h.example:1", "inproc://x"])
def test_good_scheduler_addresses_pass(address: str) -> None:
    assert scheduler_address_problem(address) == ""
    Executor("dask", scheduler=address)


def test_executor_refuses_a_bad_address_in_library_use() -> None:
    with pytest.raises(ConfigError, match="scheduler"):
        Executor("dask", scheduler="nonsense")


@pytest.mark.parametrize("field", ["noise_scale", "arena_m"])
def test_a_huge_integer_for_a_float_in_a_sweep_world_is_one_line(work: Path, field: str
                                                                  ) -> None:
    (work / "sweep.toml").write_text(f"[[worlds]]\nn_steps = 20\nseeds = 1\n{field} = "
                                     f"{'9' * 400}\n[[methods]]\nname = \"triangulate\"\n")
    line = one_error(bomgraph("compare", "--config", work / "sweep.toml", "--out", work / "o"),
                     f"worlds[0].{field}", "finite number")
    assert len(line) < 200                          # the number is not quoted whole


@pytest.mark.parametrize("method,option", [("gtsam-batch", "max_iterations=3000000000"),
                                           ("stmds-smacof", "smacof_max_iter=-3000000000"),
                                           ("gtsam-batch", "decrease_tol=inf")])
def test_an_option_beyond_what_the_solver_takes_is_one_line(work: Path, method: str,
                                                             option: str) -> None:
    one_error(bomgraph("run", "--method", method, "--option", option, "--out", work / "e.json",
                       work / "s.jsonl"), option.split("=")[0])
    assert sorted(os.listdir(work)) == ["s.jsonl"]


def test_streams_that_are_not_streams_are_refused_before_any_run(work: Path) -> None:
    (work / "bad.jsonl").write_text('{"format": "nope"}\n')
    (work / "garbage.jsonl").write_bytes(bytes(range(256)) * 4)
    one_error(bomgraph("compare", "--streams", work / "s.jsonl", work / "bad.jsonl",
                       *COMPARE, "--out", work / "o"), "--streams", "bad.jsonl", "line 1",
              "format")
    one_error(bomgraph("compare", "--streams", work / "garbage.jsonl", *COMPARE, "--out",
                       work / "o"), "garbage.jsonl", "line 1")
    (work / "sweep.toml").write_text('streams = ["bad.jsonl"]\nmethods = ["triangulate"]\n')
    one_error(bomgraph("compare", "--config", work / "sweep.toml", "--out", work / "o"),
              "sweep.toml", "streams", "bad.jsonl", "line 1")
    assert not (work / "o").exists()


def test_a_stream_malformed_further_in_ends_compare_with_exit_2(work: Path) -> None:
    lines = (work / "s.jsonl").read_text().splitlines(keepends=True)
    lines[7] = lines[7][:20] + "\n"                  # step 6 cut short
    (work / "late.jsonl").write_text("".join(lines))
    proc = bomgraph("compare", "--streams", work / "late.jsonl", work / "s.jsonl", *COMPARE,
                    "--out", work / "o", "--no-cache")
    one_error(proc, "1 run stopped", "late.jsonl", "line 8")
    assert "2 runs in" in proc.stdout.decode()      # the table and files are still written
    assert (work / "o" / "results.json").is_file()


def test_an_empty_stream_name_is_named(work: Path) -> None:
    one_error(bomgraph("run", "--method", "triangulate", "--out", work / "e.json", ""),
              "empty file name", "cannot open")


@pytest.mark.parametrize("method", ["stmds-smacof", "stmds-smacof-loc", "stmds-cs"])
def test_stmds_refuses_an_odometry_step_beyond_double_precision_squares(work: Path,
                                                                         method: str) -> None:
    lines = (work / "s.jsonl").read_text().splitlines(keepends=True)
    step = json.loads(lines[11])
    step["odom"] = [1e200, 0.0, 0.0]
    lines[11] = json.dumps(step) + "\n"
    (work / "huge.jsonl").write_text("".join(lines))
    one_error(bomgraph("run", "--method", method, "--out", work / "e.json", work / "huge.jsonl"),
              "huge.jsonl, line 12: 'odom': step 10:", "1e+200 m", "fix the stream's odometry")
    assert not (work / "e.json").exists()
