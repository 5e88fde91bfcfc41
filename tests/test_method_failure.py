"""A method that raises: the exception keeps its type and gains a note saying where (``run``),
``bomgraph run`` says so in one line with exit status 1 (the traceback with ``-v``), and
``bomgraph compare`` records the place and the traceback and exits 1 when any run failed."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import numpy as np
import pytest

from bomgraph import mapper
from bomgraph.cli import main
from bomgraph.mapper import create_mapper, method_failure_note, run
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream

CRASHER = textwrap.dedent('''
    import gtsam

    from bomgraph.mapper import MapEstimate


    class Crasher:
        """raises in step() at t = at_step, or in estimate() with at_step = -1"""

        def __init__(self, header, *, at_step: int = 5) -> None:
            self.at_step = at_step

        def step(self, step) -> None:
            if step.t == self.at_step:
                raise ValueError(f"boom at {step.t}")

        def estimate(self):
            if self.at_step < 0:
                raise ZeroDivisionError("no map")
            return MapEstimate.empty()


    class Singular(Crasher):
        """Gauss-Newton on a landmark seen once: GTSAM's indeterminate system at t = at_step"""

        def step(self, step) -> None:
            if step.t == self.at_step:
                graph = gtsam.NonlinearFactorGraph()
                noise = gtsam.noiseModel.Isotropic.Sigma(3, 0.01)
                graph.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(), noise))
                graph.add(gtsam.BearingFactor2D(0, 1, gtsam.Rot2(0.3),
                                                gtsam.noiseModel.Isotropic.Sigma(1, 0.01)))
                values = gtsam.Values()
                values.insert(0, gtsam.Pose2())
                values.insert(1, gtsam.Point2(2.0, 0.5))
                gtsam.GaussNewtonOptimizer(graph, values).optimize()


    class Odd(Crasher):
        """at t = 5: kind 0 a colouring escape and a tab, 1 no message, 2 a refusal over
        two lines"""

        def __init__(self, header, *, kind: int = 0) -> None:
            self.at_step, self.kind = 5, kind

        def step(self, step) -> None:
            from bomgraph.errors import ConfigError

            if step.t == 5:
                raise [RuntimeError("red \\x1b[31mtext\\tthen\\n  more"), ZeroDivisionError(),
                       ConfigError("first line\\n  second line")][self.kind]
''')


@pytest.fixture()
def crasher(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    (tmp_path / "crasher_plugin.py").write_text(CRASHER)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    mapper.register_method("crasher", "crasher_plugin:Crasher", "raises")
    mapper.register_method("singular", "crasher_plugin:Singular", "raises GTSAM's error")
    mapper.register_method("odd", "crasher_plugin:Odd", "raises odd messages")
    stream = simulate(SimConfig(n_steps=30, n_landmarks=8), np.random.default_rng(0))
    write_stream(stream, tmp_path / "s.jsonl")
    return tmp_path / "s.jsonl"


def test_run_notes_where_the_method_raised_and_keeps_its_exception(crasher: Path) -> None:
    from bomgraph.stream_file import read_stream

    s = read_stream(crasher)
    with pytest.raises(ValueError, match="boom at 5") as info:
        run(create_mapper("crasher", s.header), s.steps)
    assert method_failure_note(info.value) == "raised in Crasher.step() at t = 5"
    with pytest.raises(ZeroDivisionError) as info:
        run(create_mapper("crasher", s.header, at_step=-1), s.steps, checkpoint_every=10)
    assert method_failure_note(info.value) == "raised in Crasher.estimate() at t = 10"
    assert method_failure_note(ValueError("not from a method")) is None


def test_cli_run_says_where_in_one_line_and_exits_1(crasher: Path, tmp_path: Path,
                                                     capsys) -> None:
    out = tmp_path / "e.est"
    assert main(["run", str(crasher), "--method", "crasher", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.strip().splitlines() == [
        "bomgraph: error: method crasher failed: ValueError: boom at 5 (raised in "
        "Crasher.step() at t = 5); -v shows the traceback"]
    assert not out.exists()
    assert main(["-v", "run", str(crasher), "--method", "crasher", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "Traceback (most recent call last)" in err and "crasher_plugin.py" in err


def test_compare_records_where_and_exits_1_when_a_run_failed(crasher: Path, tmp_path: Path,
                                                            capsys) -> None:
    out = tmp_path / "c"
    status = main(["compare", "--streams", str(crasher), "--methods", "crasher,triangulate",
                   "--out", str(out), "--no-figures", "--jobs", "1"])
    captured = capsys.readouterr()
    assert status == 1
    assert "1 of 2 runs failed (first: crasher on" in captured.err
    assert "ValueError: boom at 5 (raised in Crasher.step() at t = 5)" in captured.err
    results = json.loads((out / "results.json").read_text())["results"]
    bad = [r for r in results if not r["ok"]]
    assert len(bad) == 1 and "crasher_plugin.py" in bad[0]["traceback"]
    assert [r["ok"] for r in results if r["method"] == "triangulate"] == [True]
    assert "FAILED" in captured.out


def test_compare_exits_0_when_every_run_succeeded(crasher: Path, tmp_path: Path) -> None:
    assert main(["compare", "--streams", str(crasher), "--methods", "triangulate",
                 "--out", str(tmp_path / "ok"), "--no-figures", "--jobs", "1"]) == 0


def test_run_and_compare_show_a_multiline_method_error_as_one_readable_line(
        crasher: Path, tmp_path: Path, capsys) -> None:
    """h163: GTSAM's "Indeterminate linear system" message, over several lines (the first
    failure a hybrid of one's own meets), was shown with literal ``\\n``s by the CLI's
    one-line net; its line breaks are now spaces, in ``run``, ``compare`` and results.json."""
    assert main(["run", str(crasher), "--method", "singular", "--out",
                 str(tmp_path / "e.est")]) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert "\\n" not in err, err
    assert ("failed: RuntimeError: Indeterminate linear system detected while working near "
            "variable 1") in err, err
    assert "(raised in Singular.step() at t = 5); -v shows the traceback" in err, err
    out = tmp_path / "c"
    assert main(["compare", "--streams", str(crasher), "--methods", "singular", "--out",
                 str(out), "--no-figures", "--jobs", "1"]) == 1
    err = capsys.readouterr().err
    assert "\\n" not in err and "RuntimeError: Indeterminate linear system detected" in err, err
    run = json.loads((out / "results.json").read_text())["results"][0]
    assert run["error"].startswith("RuntimeError: Indeterminate linear system detected while "
                                   "working near variable 1"), run["error"]
    assert "\n" not in run["error"] and "Traceback" in run["traceback"]


@pytest.mark.parametrize("kind, shown, status", [
    (0, "RuntimeError: red \\x1b[31mtext\\tthen more", 1), (1, "ZeroDivisionError", 1),
    (2, "ConfigError: first line second line", 2)])
def test_a_method_error_s_control_characters_and_empty_message_are_shown_as_one_line(
        crasher: Path, tmp_path: Path, capsys, kind: int, shown: str, status: int) -> None:
    """h166: a method's message with an escape sequence reached the compare table on stdout
    raw (recolouring the terminal), an empty one was shown as a dangling "ZeroDivisionError: ",
    and a refusal a method raised over two lines kept a literal \\n in ``run`` (though its
    lines were joined in compare): each is one line of printable text wherever it is shown."""
    status_run = main(["run", str(crasher), "--method", "odd", "--option", f"kind={kind}",
                       "--out", str(tmp_path / "e.est")])
    err = capsys.readouterr().err
    assert status_run == status and len(err.strip().splitlines()) == 1, err
    said = shown.partition(": ")[2] if status == 2 else shown   # a refusal: its message
    assert f"bomgraph: error: {'' if status == 2 else 'method odd failed: '}{said} (raised in " \
           "Odd.step() at t = 5)" in err, err
    out = tmp_path / "c"
    assert main(["compare", "--streams", str(crasher), "--methods", "odd",
                 "--option", f"odd:kind={kind}", "--out", str(out), "--no-figures",
                 "--jobs", "1"]) in (1, 2)
    captured = capsys.readouterr()
    assert f"FAILED 1: {shown} (raised in Odd.step() at t = 5)" in captured.out, captured.out
    assert all(c.isprintable() for line in captured.out.splitlines() for c in line)
    run = json.loads((out / "results.json").read_text())["results"][0]
    assert run["error"] == f"{shown} (raised in Odd.step() at t = 5)"
