"""Faults helper h143 found reviewing h136's merge (STMDS refusals located, one quoting of
file names, evaluate near 1e300, bounded ``**`` globs); each test failed on that merge."""

from __future__ import annotations

import glob
import json
import warnings
from pathlib import Path

import pytest
from hostile_helpers import HEADER, bomgraph, one_error, write_jsonl

DIVERGED = '''
from baselines.triangulate import TriangulateMapper


class Diverged(TriangulateMapper):
    """triangulate's maps moved 1e307 times as far (a diverged method)."""

    def estimate(self):
        est = super().estimate()
        poses = None if est.poses is None else est.poses * [1e307, 1e307, 1]
        return type(est)(est.landmark_ids, est.landmarks_xy * 1e307, est.pose_t, poses,
                         None, None, est.info)
'''


def test_a_diverged_run_beyond_the_scored_range_is_unscored_not_a_stopped_sweep(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A method whose map went beyond 1e306 m (evaluate.MAX_SCORED_M) scored '-' at each
    checkpoint, and then the final map's alignment for the figures raised OutOfRangeError
    out of run_task: a compare stopped there, every other run's result with it."""
    from bomgraph import mapper
    from bomgraph.bench import run_task
    from bomgraph.experiments import Arm, Experiment
    from bomgraph.sim import SimConfig

    (tmp_path / "diverged_mapper.py").write_text(DIVERGED)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    mapper.register_method("diverged", "diverged_mapper:Diverged", "triangulate, diverged")
    task = Experiment("t", "test", (Arm("d", "diverged"),), SimConfig(n_steps=40,
                      n_landmarks=20), seed=3, n_layouts=1, n_starts=1).tasks()[0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")   # no overflow warning either
        res = run_task(task)
    assert res["ok"], res.get("error")
    assert [c["t"] for c in res["checkpoints"]] == [10, 20, 30, 40]
    assert all(c["mpe_m"] != c["mpe_m"] for c in res["checkpoints"])   # NaN: '-'
    assert res["final_map"] is None


def test_a_debug_traceback_of_a_failed_run_keeps_its_lines(tmp_path: Path) -> None:
    """``compare -vv``: a failed run's traceback was logged inside the message, which the
    one-line net (errors.one_line) flattened to one line of literal '\\n's."""
    steps = [{"t": 0, "bearings": [[0, 0.5], [1, -0.5], [2, 2.0]]}] + [
        {"t": t, "odom": [0.1, 0.0, 0.05],
         "bearings": [[0, 0.5 + 0.05 * t], [1, -0.5 - 0.04 * t], [2, 2.0 + 0.03 * t]]}
        for t in range(1, 8)]
    steps[4]["odom_sigma"] = [1e8, 0.0, 0.1]
    stream = write_jsonl(tmp_path / "odd.jsonl", HEADER, steps)
    proc = bomgraph("compare", "-vv", "--streams", stream, "--methods", "stmds-smacof",
                    "--out", tmp_path / "cmp", "--jobs", "1", "--no-progress", "--no-figures")
    assert proc.returncode == 1, proc.stderr
    lines = proc.stderr.decode().splitlines()
    assert "bomgraph: DEBUG: stmds-smacof on odd failed" in lines, [
        ln[:120] for ln in lines if "failed" in ln]
    at = lines.index("bomgraph: DEBUG: stmds-smacof on odd failed")
    assert lines[at + 1] == "Traceback (most recent call last):", lines[at:at + 3]
    assert any("StreamValueError" in ln and "line 6: 'odom_sigma'" in ln
               for ln in lines[at + 2:]), lines[at:]
    assert "line 6: 'odom_sigma'" in json.dumps(
        json.loads((tmp_path / "cmp" / "results.json").read_text()))


def test_a_glob_below_a_wildcard_counts_only_the_folders_it_searches(tmp_path: Path) -> None:
    """``runs*/**/*.jsonl`` counted every folder below the sweep file's folder (the part
    before the first wildcard), so a big folder beside ``runs1`` (a dataset, an
    environment) refused a glob that searches two folders."""
    from bomgraph.stream_globs import GlobTooWideError, bounded_glob

    for rel in ("runs1/a.jsonl", "runs1/deep/b.jsonl", "runs2/c.jsonl", ".runs3/d.jsonl"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text("")
    for i in range(20):
        (tmp_path / "big" / str(i)).mkdir(parents=True)
    pattern = f"{tmp_path}/runs*/**/*.jsonl"
    expected = sorted(glob.glob(pattern, recursive=True))
    assert len(expected) == 3
    assert bounded_glob(pattern, limit=3) == expected   # runs1, runs1/deep, runs2
    with pytest.raises(GlobTooWideError, match=r"more than 2 folders below .*/runs\*;"):
        bounded_glob(pattern, limit=2)
    for hidden in (f"{tmp_path}/.runs*/**/*.jsonl", f"{tmp_path}/*/**/*.jsonl"):
        expected = sorted(glob.glob(hidden, recursive=True))
        assert bounded_glob(hidden, limit=24) == expected   # glob's '*' skips .runs3 too
    with pytest.raises(GlobTooWideError):
        bounded_glob(f"{tmp_path}/**/*.jsonl", limit=24)    # the top too: 25


NL = "a\nb"


@pytest.mark.parametrize("case", ["run-out-is-input", "compare-link", "compare-not-listed"])
def test_a_file_name_the_output_checks_name_is_shown_as_every_message_shows_it(
        work: Path, case: str) -> None:
    """``--out 'a\\nb.jsonl': is the input a\\nb.jsonl``: the output checks named the input
    and compare's files without errors.shown_path (escaped by the CLI's net, unquoted),
    where every other message quotes such a name."""
    (work / f"{NL}.jsonl").write_bytes((work / "s.jsonl").read_bytes())
    out = work / NL
    out.mkdir()
    if case == "compare-link":
        (out / "results.json").symlink_to(work / "nowhere")
    else:
        (out / "summary.csv").write_text("x\n")
    args, shown = {
        "run-out-is-input": (["run", f"{NL}.jsonl", "--method", "triangulate", "--out",
                              f"{NL}.jsonl"], f"is the input {NL + '.jsonl'!r};"),
        "compare-link": (["compare", "--streams", "s.jsonl", "--methods", "triangulate",
                          "--out", NL, "--jobs", "1", "--no-progress", "--no-figures"],
                         f"would replace {NL + '/results.json'!r}, which is a link"),
        "compare-not-listed": (["compare", "--streams", "s.jsonl", "--methods", "triangulate",
                                "--out", NL, "--jobs", "1", "--no-progress", "--no-figures"],
                               f"would replace {NL + '/summary.csv'!r}, which is not listed"),
    }[case]
    one_error(bomgraph(*args, cwd=work), shown)


def test_a_fifo_with_a_newline_in_its_name_is_named_as_every_file(tmp_path: Path) -> None:
    """A stream read from a named pipe is spooled to a temporary file; messages named the
    pipe in its place as written, so ``a\\nb`` came out escaped by the CLI's net but
    unquoted (``a\\nb, line 6``), where a regular file of that name is ``'a\\nb', line 6``."""
    import os
    import threading

    steps = [{"t": 0, "bearings": [[0, 0.5], [1, -0.5], [2, 2.0]]}] + [
        {"t": t, "odom": [0.1, 0.0, 0.05],
         "bearings": [[0, 0.5 + 0.05 * t], [1, -0.5 - 0.04 * t], [2, 2.0 + 0.03 * t]]}
        for t in range(1, 8)]
    steps[4]["odom_sigma"] = [1e8, 0.0, 0.1]
    data = write_jsonl(tmp_path / "odd.jsonl", HEADER, steps).read_bytes()
    fifo = tmp_path / NL
    os.mkfifo(fifo)
    writer = threading.Thread(target=fifo.write_bytes, args=(data,), daemon=True)
    writer.start()
    proc = bomgraph("run", NL, "--method", "stmds-smacof", "--out", "o.json", cwd=tmp_path,
                    timeout=120)
    writer.join(10)
    one_error(proc, f"{NL!r}, line 6: 'odom_sigma': step 4")
    assert f"bomgraph: WARNING: {NL!r}, line 6" in proc.stderr.decode(), proc.stderr
