"""Small faults a new user met (helper h46's walkthrough), each fixed with a test here."""

from __future__ import annotations

from pathlib import Path

import pytest

from bomgraph.cli import main


def test_compare_says_how_many_runs_came_from_the_cache(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture) -> None:
    """The last line said "2 runs in 0.0 s" when both came from the cache; only --dry-run
    said what was cached. It (and compare's result) now counts the runs the cache gave."""
    from bomgraph.bench import Executor
    from bomgraph.experiments import compare_experiments
    from bomgraph.report import compare

    run_file = tmp_path / "s.jsonl"
    assert main(["simulate", "--steps", "20", "--landmarks", "10", "--out", str(run_file)]) == 0
    cmd = ["compare", "--streams", str(run_file), "--methods", "triangulate,stmds-cs",
           "--jobs", "1", "--no-figures", "--no-progress", "--out", str(tmp_path / "c")]
    assert main(cmd) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith("2 runs in ") and "from the cache" not in last
    assert main(cmd) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith("2 runs in ") and " s (2 from the cache); wrote " in last
    chosen, _ = compare_experiments(streams=[str(run_file)], methods="triangulate")
    assert compare(chosen, tmp_path / "c", executor=Executor("serial")).n_cached == 1
    assert compare(chosen, tmp_path / "c", executor=Executor("serial"),
                   use_cache=False).n_cached == 0


def test_compare_counts_one_run_in_the_singular(tmp_path: Path, capsys: pytest.CaptureFixture
                                                ) -> None:
    """Its last line said "1 runs in 0.0 s"."""
    run_file = tmp_path / "s.jsonl"
    assert main(["simulate", "--steps", "20", "--landmarks", "10", "--out", str(run_file)]) == 0
    assert main(["compare", "--streams", str(run_file), "--methods", "triangulate", "--jobs",
                 "1", "--no-figures", "--no-progress", "--out", str(tmp_path / "c")]) == 0
    assert capsys.readouterr().out.strip().splitlines()[-1].startswith("1 run in ")


_HEAD = ('{"format": "bomgraph-stream", "version": %s, "bearing_sigma_rad": 0.05, '
         '"odometry_sigma": [0.03, 0, 0.05]}\n{"t": 0, "bearings": [[1, 0.5]]}\n')


@pytest.mark.parametrize("version, says", [('"1"', 'the integer 1, not the string "1"'),
                                           ("1.0", "the integer 1, not 1.0"),
                                           ("true", "the integer 1, not true"),
                                           ("2", "unknown version 2; this reader knows "
                                                 "version 1")])
def test_a_version_that_is_not_the_integer_1_says_what_to_write(
        tmp_path: Path, capsys: pytest.CaptureFixture, version: str, says: str) -> None:
    """``"version": "1"`` was refused with 'unknown version "1"; this reader knows version
    1', which reads as a contradiction: it now says to write the integer."""
    stream = tmp_path / "s.jsonl"
    stream.write_text(_HEAD % version)
    assert main(["run", str(stream), "--method", "triangulate",
                 "--out", str(tmp_path / "e.est")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(stream) in err[0] and "line 1" in err[0]
    assert "'version'" in err[0] and says in err[0], err[0]


@pytest.mark.parametrize("version, says", [('"2"', 'the integer 1 or 2, not the string "2"'),
                                           ("3", "unknown version 3; this reader knows "
                                                 "versions 1 and 2")])
def test_an_estimate_version_that_is_not_an_integer_says_what_to_write(
        tmp_path: Path, capsys: pytest.CaptureFixture, version: str, says: str) -> None:
    stream, est = tmp_path / "s.jsonl", tmp_path / "e.est"
    assert main(["simulate", "--steps", "20", "--landmarks", "10", "--out", str(stream)]) == 0
    assert main(["run", str(stream), "--method", "triangulate", "--out", str(est)]) == 0
    lines = est.read_text().splitlines(keepends=True)
    assert '"version":2,' in lines[0]
    est.write_text(lines[0].replace('"version":2,', f'"version":{version},', 1)
                   + "".join(lines[1:]))
    capsys.readouterr()
    assert main(["evaluate", str(est), str(stream)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(est) in err[0] and "line 1" in err[0]
    assert "'version'" in err[0] and says in err[0], err[0]


BOUND = '''
from bomgraph.mapper import MapEstimate


class TruthMap:
    """the true landmarks, seen or not (a bound)

    More text that is not the description."""

    needs_truth = True

    def __init__(self, header, *, truth):
        self.truth = truth

    def step(self, step):
        pass

    def estimate(self):
        return MapEstimate(self.truth.landmark_ids, self.truth.landmarks_xy)


class Described(TruthMap):
    description = "its own description attribute"
    needs_truth = "yes"             # not True: not a bound, as for a plugin

    def __init__(self, header):
        self.truth = None
'''


@pytest.fixture()
def h48_methods(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    import sys

    from bomgraph import mapper

    (tmp_path / "h48bound.py").write_text(BOUND)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "h48bound", raising=False)
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    return mapper


def test_register_method_honours_a_factory_s_needs_truth_as_plugins_do(h48_methods) -> None:
    """A class with ``needs_truth = True`` registered without needs_truth=True was not given
    the truth: create_mapper failed with "bad options []: ... missing ... 'truth'"."""
    import numpy as np

    from bomgraph.errors import ConfigError
    from bomgraph.sim import SimConfig, simulate

    mapper = h48_methods
    mapper.register_method("h48-truth", "h48bound:TruthMap", "a bound")
    mapper.register_method("h48-plain", "h48bound:Described", "not a bound")
    assert mapper.method_info("h48-truth").needs_truth is True
    assert mapper.method_info("h48-plain").needs_truth is False
    stream = simulate(SimConfig(n_steps=10, n_landmarks=6), np.random.default_rng(1))
    with pytest.raises(ConfigError, match="reads the ground truth"):
        mapper.create_mapper("h48-truth", stream.header)
    est = mapper.run(mapper.create_mapper("h48-truth", stream.header, truth=stream.truth),
                     stream.steps).final
    assert np.array_equal(est.landmarks_xy, stream.truth.landmarks_xy)


def test_register_method_falls_back_to_the_factory_s_description(h48_methods) -> None:
    """register_method required a description where a plugin falls back to its factory's
    ``description`` attribute, else the first line of its docstring."""
    from bomgraph.method_list import method_listing

    mapper = h48_methods
    mapper.register_method("h48-doc", "h48bound:TruthMap")
    mapper.register_method("h48-attr", "h48bound:Described")
    mapper.register_method("h48-given", "h48bound:Described", "given here")
    assert mapper.method_description("h48-doc") == "the true landmarks, seen or not (a bound)"
    assert mapper.method_description("h48-attr") == "its own description attribute"
    assert mapper.method_description("h48-given") == "given here"
    row = method_listing(mapper.method_info("h48-doc"))
    assert row["description"] == "the true landmarks, seen or not (a bound)"
    assert row["needs_truth"] is True and row["origin"] == "runtime"


def test_the_package_namespace_shows_no_implementation_names() -> None:
    """``dir(bomgraph)`` listed ``Any`` and ``import_module`` (its own imports)."""
    import subprocess
    import sys

    code = ("import bomgraph; d = dir(bomgraph); print(sorted({'Any', 'import_module'} & "
            "set(d))); ns = {}; exec('from bomgraph import *', ns); "
            "print(sorted(set(bomgraph.__all__) - set(ns))); "
            "print(all(n in d for n in bomgraph.__all__)); "
            "print(bomgraph.mapper.register_method.__name__, "
            "bomgraph.stream_file.read_stream.__name__, bomgraph.run.__name__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split("\n")
    assert out[:4] == ["[]", "[]", "True", "register_method read_stream run"]
