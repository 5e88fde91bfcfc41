"""h52's fresh hostile-input audit of every command: what gave a traceback, filled the memory,
named no line or printed a warning over three lines. Each test failed before its fix."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from hostile_helpers import (ENV, MEMORY_LIMIT_BYTES, ROOT, _limit_memory, bomgraph, no_traceback,
                             one_error)

sys.path.insert(0, str(ROOT / "tests" / "datasets"))
from dataset_excerpts import write_g2o  # noqa: E402

#: JSON Python's parser gives up on (RecursionError), and an integer it will not convert
#: (ValueError): both valid JSON. 20,000 deep: Python 3.13's parser reads 3,000 (3.11's gave
#: up there), and gives up by 10,000; 20,000 is still a command line argument (< 128 KiB)
DEEP = "[" * 20_000 + "]" * 20_000
LONG_INT = "9" * 5000


def _estimate(work: Path) -> Path:
    est = work / "e.json"
    proc = bomgraph("run", work / "s.jsonl", "--method", "triangulate", "--out", est)
    assert proc.returncode == 0, no_traceback(proc)
    return est


def test_evaluate_of_a_stream_nested_too_deep_is_one_error(work: Path) -> None:
    """Looking whether the broken stream was an estimate (arguments swapped?) raised the
    RecursionError the stream reader had caught."""
    (work / "deep.jsonl").write_text(DEEP + "\n")
    one_error(bomgraph("evaluate", _estimate(work), work / "deep.jsonl"), "deep.jsonl, line 1",
              "too deeply nested")


@pytest.mark.parametrize("value", [DEEP, LONG_INT])
def test_an_option_json_will_not_parse_is_a_string_refused_by_the_method(work: Path,
                                                                        value) -> None:
    """``--option min_count=<5000 digits>`` or ``=[[[...]]]`` raised out of the option
    parser (ValueError, RecursionError): a traceback."""
    one_error(bomgraph("run", work / "s.jsonl", "--method", "stmds-smacof", "--option",
                       f"min_count={value}", "--out", work / "e.json"), "min_count")
    one_error(bomgraph("compare", "--streams", work / "s.jsonl", "--methods", "stmds-smacof",
                       "--option", f"stmds-smacof:min_count={value}", "--out", work / "c",
                       "--no-figures", "--jobs", "1"), "min_count")


def _compare(work: Path, *extra: str, memory: int | None = None):
    return bomgraph("compare", "--streams", work / "s.jsonl", "--methods", "triangulate",
                    "--out", work / "c", "--no-figures", "--jobs", "1", *extra, memory=memory)


@pytest.mark.parametrize("bad", ["deep", "device"])
def test_compare_refuses_a_damaged_manifest_in_one_line(work: Path, bad: str) -> None:
    """A manifest nested too deep raised RecursionError; one linked to /dev/zero was read
    until the memory ran out (MemoryError). A damaged manifest was then ignored; since h61 it
    proves no file compare's, so compare, which would replace the first one's results, refuses
    in one line instead (naming the manifest), within the memory bound."""
    assert _compare(work).returncode == 0
    manifest = work / "c" / ".bomgraph-compare-files"
    manifest.unlink()
    if bad == "deep":
        manifest.write_text(DEEP)
    else:
        manifest.symlink_to("/dev/zero")
    one_error(_compare(work, memory=MEMORY_LIMIT_BYTES), ".bomgraph-compare-files is not the "
              "list of files bomgraph compare keeps there")


@pytest.mark.parametrize("bad", ["deep", "device"])
def test_a_damaged_cache_file_is_a_miss(tmp_path: Path, bad: str) -> None:
    """Read in a process bounded in memory: /dev/zero was read until the memory ran out."""
    path = tmp_path / "0123456789abcdef0123.json"
    if bad == "deep":
        path.write_text(DEEP)
    else:
        path.symlink_to("/dev/zero")
    code = ("import logging, sys; logging.basicConfig(); "
            "from bomgraph.result_cache import read_cached; "
            "sys.exit(0 if read_cached(__import__('pathlib').Path(sys.argv[1])) is None else 3)")
    proc = subprocess.run([sys.executable, "-c", code, str(path)], env=ENV, timeout=120,
                          capture_output=True, preexec_fn=_limit_memory(MEMORY_LIMIT_BYTES))
    assert proc.returncode == 0, proc.stderr.decode()
    assert "ignoring the unreadable cache file" in proc.stderr.decode()


def test_plot_results_refuses_a_results_file_that_is_a_device(work: Path) -> None:
    """``results.json`` linked to /dev/zero was read whole: MemoryError, a traceback."""
    (work / "c").mkdir()
    (work / "c" / "results.json").symlink_to("/dev/zero")
    one_error(bomgraph("plot", "--results", work / "c", "--out", work / "r.png",
                       memory=MEMORY_LIMIT_BYTES), "results.json", "not a regular file")
    assert not (work / "r.png").exists()


def test_plot_says_an_empty_out_is_empty(work: Path) -> None:
    """It said ``bomgraph: error: : the figure's file name must end in .png, ...``."""
    one_error(bomgraph("plot", "--out", "", _estimate(work), work / "s.jsonl"),
              "--out is empty")


# ---- importers ------------------------------------------------------------------------------

@pytest.mark.parametrize("comment,needle", [
    ("# bomgraph header: " + DEEP, "not JSON"),
    ('# bomgraph header: {"priors": [], "priors": []}', "'priors' appears twice"),
])
def test_a_g2o_bomgraph_header_json_will_not_parse_is_one_error(tmp_path: Path, sim, comment,
                                                                needle) -> None:
    """A repeated key (DuplicateKeyError) or deep nesting (RecursionError) in the g2o file's
    ``# bomgraph header:`` comment escaped as a traceback."""
    g2o = tmp_path / "data.g2o"
    write_g2o(g2o, sim)
    g2o.write_text(comment + "\n" + g2o.read_text())
    one_error(bomgraph("import", "g2o", g2o, "--out", tmp_path / "s.jsonl"),
              f"{g2o}, line 1: field 'bomgraph header'", needle)


def _edit_first(path: Path, tag: str, field: int, value: str) -> int:
    """Replace field ``field`` of the first ``tag`` record of ``path``; its line number."""
    lines = path.read_text().splitlines()
    k = next(n for n, ln in enumerate(lines) if ln.startswith(tag + " "))
    rec = lines[k].split()
    rec[field] = value
    lines[k] = " ".join(rec)
    path.write_text("\n".join(lines) + "\n")
    return k + 1


def test_an_importer_refusing_implausible_odometry_names_its_line(tmp_path: Path, sim) -> None:
    """``'odom': step 1 moves 1e+300 m ...; refusing to write an implausible stream`` named the
    file but not the line of the record."""
    g2o = tmp_path / "data.g2o"
    write_g2o(g2o, sim)
    line = _edit_first(g2o, "EDGE_SE2", 3, "1e300")
    one_error(bomgraph("import", "g2o", g2o, "--out", tmp_path / "s.jsonl"),
              f"{g2o}, line {line}: 'odom': step 1 moves 1e+300 m")
    victoria = tmp_path / "victoria.txt"
    victoria.write_text("ODOMETRY 0 1 0.5 0 0.01 0.0001 0 0 4e-06 0 4e-06\n"
                        "ODOMETRY 1 2 1e300 0 0.01 0.0001 0 0 4e-06 0 4e-06\n"
                        "LANDMARK 0 7 3.0 1.0 0.01 0 0.01\n"
                        "LANDMARK 2 7 2.0 1.0 0.01 0 0.01\n")
    one_error(bomgraph("import", "victoria", victoria, "--out", tmp_path / "v.jsonl"),
              f"{victoria}, line 2: 'odom': step 2 moves 1e+300 m")


# ---- priors no measurement has --------------------------------------------------------------

def test_a_prior_sigma_no_measurement_has_is_warned_of_and_not_made(work: Path, sim) -> None:
    """A prior of sigma 1e-300 m was read silently (BOM-STMDS's weights overflowed: numpy's
    RuntimeWarnings, each over three lines, and no map); simulate made such priors."""
    head, *steps = (work / "s.jsonl").read_text().splitlines()
    obj = json.loads(head)
    obj["priors"] = [{"i": 0, "j": 1, "distance_m": 1.0, "sigma_m": 1e-300}]
    (work / "p.jsonl").write_text("\n".join([json.dumps(obj), *steps]) + "\n")
    proc = bomgraph("run", work / "p.jsonl", "--method", "stmds-smacof", "--out",
                    work / "e.json")
    err = no_traceback(proc)
    assert proc.returncode == 0, err
    assert "p.jsonl, line 1: 'priors[0].sigma_m': 1e-300 m is outside [1e-09, 100000] m" in err
    # every line of stderr is one message (a Python warning too: its source line is cut)
    assert all(ln.startswith("bomgraph: ") or ln.startswith("stmds-smacof: ")
               for ln in err.splitlines() if ln.strip()), err
    one_error(bomgraph("simulate", "--prior-fraction", "0.1", "--prior-sigma", "1e-300",
                       "--out", work / "q.jsonl"), "prior sigma", "1e-09")
    assert not (work / "q.jsonl").exists()
    g2o = work / "data.g2o"
    write_g2o(g2o, sim)
    g2o.write_text('# bomgraph header: {"priors": [{"i": 0, "j": 1, "distance_m": 1.0, '
                   '"sigma_m": 1e-300}]}\n' + g2o.read_text())
    one_error(bomgraph("import", "g2o", g2o, "--out", work / "g.jsonl"),
              f"{g2o}, line 1: 'priors[0].sigma_m'")
    assert not os.path.exists(work / "g.jsonl")


def test_a_stream_integer_python_will_not_convert_is_named_for_the_user(work: Path) -> None:
    """The message told the user to call ``sys.set_int_max_str_digits()``."""
    head = (work / "s.jsonl").read_text().splitlines()[0]
    (work / "i.jsonl").write_text(head + '\n{"t": 0, "bearings": [[1, ' + LONG_INT + ']]}\n')
    line = one_error(bomgraph("run", work / "i.jsonl", "--method", "triangulate", "--out",
                              work / "e.json"),
                     "i.jsonl, line 2: not valid JSON (an integer of 5000 digits")
    assert "set_int_max_str_digits" not in line
