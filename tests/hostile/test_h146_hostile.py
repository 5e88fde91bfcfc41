"""Hostile-input faults helper h146 fixed: each test failed before its fix. The EKF
baselines' refusals of a valid stream's values named the step only ("step 4: the predicted
pose or its covariance overflows ...") or no place at all ("BearingEkf: bearing_sigma_rad
must be in (0, pi]"); now they name the stream's file, line and field, as STMDS's do."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from hostile_helpers import (HEADER, bomgraph, odd_steps, one_error, refused_in_compare,
                              write_jsonl)

from bomgraph import tables



@pytest.mark.parametrize("method", ["ekf", "ekf-invdepth"])
@pytest.mark.parametrize("header,at_4,where", [
    ({}, {"odom_sigma": [1e200, 0.0, 0.1]}, "line 6: 'odom_sigma': step 4: {method} cannot use"),
    ({}, {"odom": [1e200, 0.0, 0.1]}, "line 6: 'odom': step 4: {method} cannot use"),
    ({"odometry_sigma": [1e200, 0.0, 0.1]}, {},        # refused as read (h151), not at step 1
     "line 1: 'odometry_sigma': {method} cannot use [1e+200, 0.0, 0.1]: a std. dev. above"),
    ({"bearing_sigma_rad": 4.0}, {}, "line 1: 'bearing_sigma_rad': {method} cannot use"),
])
def test_an_ekf_refusal_names_the_file_and_line(tmp_path: Path, method: str, header: dict,
                                                at_4: dict, where: str) -> None:
    """The reader accepts these values (with a warning); the EKF's predict overflows on them,
    or its filter refuses a bearing sigma above pi."""
    stream = write_jsonl(tmp_path / "odd.jsonl", {**HEADER, **header}, odd_steps(**at_4))
    est = tmp_path / "e.json"
    est.write_text("kept\n")
    proc = bomgraph("run", stream, "--method", method, "--out", est)
    one_error(proc, f"{stream}, {where.format(method=method)}", "fix the stream's")
    assert est.read_text() == "kept\n"


def test_an_ekf_refusal_in_compare_names_the_file_and_line(tmp_path: Path) -> None:
    """``compare --streams`` reported the EKF's refusal naming the step only."""
    stream = write_jsonl(tmp_path / "odd.jsonl", HEADER, odd_steps(odom=[1e200, 0.0, 0.1]))
    refused_in_compare(tmp_path, stream, "ekf",
                       f"{stream}, line 6: 'odom': step 4: ekf cannot use")


@pytest.mark.parametrize("value,fmt,scale,shown", [
    (math.inf, ".2f", 100.0, "-"), (-math.inf, ".2f", 1.0, "-"), (math.nan, ".2f", 1.0, "-"),
    (math.inf, ".4g", 1.0, "-"), (1e308, ".4g", 100.0, "1.000e+310"),
    (1e308, ".2f", 100.0, "1.000e+310"), (0.0123, ".2f", 100.0, "1.23"),
])
def test_fixed_or_exponent_shows_what_is_not_finite_as_a_table_cell_does(
        value: float, fmt: str, scale: float, shown: str) -> None:
    """``fixed_or_exponent(inf, ".2f")`` was ``"Infinity"`` (a table's cell shows ``"-"``)
    and a finite 1e308 m in a ``".4g"`` column of cm was ``"inf"``."""
    assert tables.fixed_or_exponent(value, fmt, scale) == shown
    cell = tables.format_table([tables.Column("v", "v", scale, fmt)], [{"v": value}], "text")
    assert cell.splitlines()[-1].strip() == shown


def test_a_stream_glob_without_double_star_through_a_link_loop_is_refused(
        tmp_path: Path) -> None:
    """``loop/*/*/.../*.jsonl`` (40 levels) through a folder holding two links to itself
    searched 2^40 paths (17 levels took 3.4 s, each level doubles it): only ``**`` globs
    were bounded."""
    (tmp_path / "loop").mkdir()
    for name in ("a", "b"):
        (tmp_path / "loop" / name).symlink_to(".")
    pattern = "loop/" + "*/" * 40 + "*.jsonl"
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'streams = ["{pattern}"]\n[[methods]]\nname = "triangulate"\n')
    proc = bomgraph("compare", "--config", sweep, "--out", tmp_path / "out", "--dry-run",
                    timeout=120)
    one_error(proc, "sweep.toml: streams[0]:", "would search more than 10,000 folders",
              "or list the files")
    assert not (tmp_path / "out").exists()


def test_a_glob_without_double_star_is_glob_below_its_bound(tmp_path: Path) -> None:
    import glob

    from bomgraph.stream_globs import GlobTooWideError, bounded_glob

    for rel in ("a/x.jsonl", "a/b/y.jsonl", "c/.h/z.jsonl", "c/d/e/w.jsonl", "c/d/v.jsonl"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text("")
    pattern = f"{tmp_path}/*/*/*.jsonl"   # searches the top, a and c, then a/b and c/d: 5
    assert bounded_glob(pattern, limit=5) == sorted(glob.glob(pattern)) == [
        str(tmp_path / "a/b/y.jsonl"), str(tmp_path / "c/d/v.jsonl")]
    with pytest.raises(GlobTooWideError, match="more than 4 folders"):
        bounded_glob(pattern, limit=4)
    assert bounded_glob(f"{tmp_path}/c/d/*.jsonl", limit=1) == [str(tmp_path / "c/d/v.jsonl")]
