"""Audit h19 of the public Python API: the writers (export, the estimate file, the stream
file), the experiments' constructors and what ``bomgraph`` exports, misused from Python as a
library user would. Each misuse is refused where it enters with a BomgraphError naming the
argument and the fix, never a raw TypeError/AttributeError/ValueError from deep inside, a
silently written file that our own readers then refuse, or a file left half written."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bomgraph.errors import BomgraphError, ConfigError
from bomgraph.map_estimate import MapEstimate
from bomgraph.stream import Stream


# ---- MapEstimate: ids are non-negative, as in the stream ------------------------------------

@pytest.mark.parametrize("ids", [[-1, 2], np.array([3, -7])])
def test_map_estimate_refuses_negative_landmark_ids(ids: object) -> None:
    """A negative id was kept; the estimate file's writer then wrote a file its reader
    refuses, and export wrote it into g2o and csv."""
    with pytest.raises(ConfigError, match="landmark_ids must be non-negative"):
        MapEstimate(ids, [[0.0, 0.0], [1.0, 1.0]])


# ---- output paths: a file name, and the inputs as a list ------------------------------------

@pytest.fixture(scope="module")
def stream() -> Stream:
    from bomgraph.sim import SimConfig, paper_design, simulate_run

    return simulate_run(paper_design(0)[0], SimConfig(n_steps=25))


@pytest.fixture(scope="module")
def result(stream: Stream) -> object:
    from bomgraph.mapper import create_mapper, run

    return run(create_mapper("ekf", stream.header), stream.steps)


def _writers(stream: Stream, result: object) -> dict:
    from bomgraph.estimate_file import write_estimate
    from bomgraph.export import export_text, write_text_atomic
    from bomgraph.stream_file import write_stream

    text = export_text(result.final, "tum", stream)
    return {"write_stream": lambda p, **kw: write_stream(stream, p, **kw),
            "write_estimate": lambda p: write_estimate(result, p),
            "write_text_atomic": lambda p, **kw: write_text_atomic(text, p, **kw)}


@pytest.mark.parametrize("bad", [None, 5, b"out.jsonl"])
@pytest.mark.parametrize("writer", ["write_stream", "write_estimate", "write_text_atomic"])
def test_an_output_that_is_no_file_name_is_refused(stream: Stream, result: object, writer: str,
                                                   bad: object) -> None:
    """None and a number ended in os.fspath's TypeError; bytes in pathlib's."""
    with pytest.raises(BomgraphError, match="must be a file name"):
        _writers(stream, result)[writer](bad)


@pytest.mark.parametrize("writer", ["write_stream", "write_text_atomic"])
@pytest.mark.parametrize("as_path", [False, True])
def test_inputs_given_as_one_path_are_refused_and_the_input_kept(
        tmp_path: Path, stream: Stream, result: object, writer: str, as_path: bool) -> None:
    """``inputs="s.jsonl"`` was read as its characters, so the input itself was overwritten
    (a Path ended in 'PosixPath is not iterable')."""
    from bomgraph.stream_file import write_stream

    src = tmp_path / "s.jsonl"
    write_stream(stream, src)
    before = src.read_bytes()
    with pytest.raises(BomgraphError, match=r"inputs \(the files read\) must be a list"):
        _writers(stream, result)[writer](src, inputs=src if as_path else str(src))
    assert src.read_bytes() == before


def test_readers_name_a_path_that_is_no_file_name(stream: Stream) -> None:
    """read_stream(None) said 'None: cannot open: No such file or directory'; a Stream was
    printed whole as if it were a file name."""
    from bomgraph.estimate_file import read_estimate
    from bomgraph.stream_file import read_stream

    for bad in (None, stream):
        with pytest.raises(BomgraphError, match="stream path must be a file name"):
            read_stream(bad)
        with pytest.raises(BomgraphError, match="estimate path must be a file name"):
            read_estimate(bad)


# ---- export: the estimate, the stream and the text are what they say -----------------------

@pytest.mark.parametrize("fmt", ["tum", "kitti", "csv", "g2o"])
def test_export_refuses_an_estimate_or_stream_of_the_wrong_type(stream: Stream, result: object,
                                                                fmt: str) -> None:
    """A RunResult, None or a dict as the estimate, and a file name, the steps or the header
    as the stream, ended in AttributeError ('RunResult' object has no attribute 'poses')."""
    from bomgraph.errors import ExportError
    from bomgraph.export import export_text, to_csv, to_g2o, to_kitti, to_tum

    for bad, hint in [(result, r"result.final"), (None, "NoneType"), ({}, "dict")]:
        with pytest.raises(ExportError, match=f"the estimate must be a MapEstimate.*{hint}"):
            export_text(bad, fmt, stream)
    for bad, hint in [("s.jsonl", "read_stream"), (stream.steps, "not its steps"),
                      (stream.header, "not its steps or its header")]:
        with pytest.raises(ExportError, match=f"stream must be a bomgraph Stream.*{hint}"):
            export_text(result.final, fmt, bad)
    one = {"tum": lambda e, s: to_tum(e, s), "kitti": lambda e, s: to_kitti(e),
           "csv": lambda e, s: to_csv(e, s), "g2o": lambda e, s: to_g2o(e, s)}[fmt]
    with pytest.raises(ExportError, match=f"to_{fmt}\\(\\): the estimate must be a MapEstimate"):
        one(result, stream)


def test_truth_estimate_and_odometry_information_refuse_wrong_arguments() -> None:
    """truth_estimate("s.jsonl") ended in AttributeError; odometry_information gave inf/NaN
    information for a zero sigma and numpy's TypeError/ValueError for a str or 2 sigmas."""
    from bomgraph.errors import ExportError
    from bomgraph.export import odometry_information, truth_estimate

    with pytest.raises(ExportError, match=r"truth_estimate\(\): stream must be a bomgraph "
                                          r"Stream, got str \(read the file"):
        truth_estimate("s.jsonl")
    for dth, sigma in [(0.1, [0.0, 1.0, 1.0]), (0.1, [1.0, 1.0]), ("a", [1.0, 1.0, 1.0]),
                       (float("nan"), [1.0, 1.0, 1.0]), (0.1, "abc")]:
        with pytest.raises(ExportError, match=r"odometry_information\(\)"):
            odometry_information(dth, sigma)


# ---- the estimate file's writer: what it writes, its reader reads ---------------------------

def _one(est: MapEstimate, t: int = 3) -> object:
    from bomgraph.mapper import Checkpoint, RunResult

    return RunResult("m", (Checkpoint(t, est, 0.0),), np.zeros(t + 1), 0.0)


def test_write_estimate_refuses_what_is_no_run_result(tmp_path: Path, result: object) -> None:
    """A MapEstimate, a list of checkpoints or None ended in AttributeError ('no attribute
    method')."""
    from bomgraph.estimate_file import estimate_to_json, write_estimate

    for bad, hint in [(result.final, "a MapEstimate is one checkpoint's map"),
                      (list(result.checkpoints), "got list"), (None, "got NoneType")]:
        with pytest.raises(ConfigError, match=f"result must be a RunResult.*{hint}"):
            write_estimate(bad, tmp_path / "e.est")
        with pytest.raises(ConfigError, match="estimate_to_json.*result must be a RunResult"):
            estimate_to_json(bad)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("kwargs,match", [
    ({"checkpoint_every": 0}, "checkpoint_every must be an integer >= 1"),     # file refused
    ({"checkpoint_every": 2.5}, "checkpoint_every must be an integer >= 1"),   # written as 2
    ({"checkpoint_every": "10"}, "checkpoint_every must be an integer >= 1"),
    ({"stream": "s.jsonl"}, r"stream must be a StreamIdentity.*stream_file_identity\(path\)"),
    ({"stream": "STREAM"}, r"stream must be a StreamIdentity.*stream_identity\(stream.steps\)"),
    ({"options": "preset=real"}, "options must be a mapping"),
    ({"method": None}, "method must be the method's name"),                   # written "None"
])
def test_estimate_writer_refuses_a_header_it_cannot_hold(tmp_path: Path, stream: Stream,
                                                         result: object, kwargs: dict,
                                                         match: str) -> None:
    from bomgraph.estimate_file import EstimateWriter

    kwargs = {k: stream if v == "STREAM" else v for k, v in kwargs.items()}
    method = kwargs.pop("method", "ekf")
    with pytest.raises(ConfigError, match=match):
        with EstimateWriter(tmp_path / "e.est", method, **kwargs) as w:
            w.add(result.checkpoints[-1])
            w.finish(result)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("what,kwargs,match", [
    ("negative step", {"pose_t": [-2], "poses": [[0.0, 0.0, 0.0]]},
     r"'poses': a pose at step -2"),
    ("asymmetric covariance", {"landmark_cov": [[[1.0, 0.5], [0.0, 1.0]]]},
     r"'landmark_cov\[0\]'.*not symmetric"),
    ("negative covariance", {"landmark_cov": [[[-1.0, 0.0], [0.0, -1.0]]]},
     r"'landmark_cov\[0\]'.*not positive semi-definite"),
    ("bad pose covariance", {"pose_t": [0], "poses": [[0.0, 0.0, 0.0]],
                             "pose_cov": [-np.eye(3)]}, r"'pose_cov\[0\]'.*not positive"),
])
def test_the_estimate_writer_refuses_what_its_reader_refuses(tmp_path: Path, what: str,
                                                             kwargs: dict, match: str) -> None:
    """These were written, and read_estimate then refused the file."""
    from bomgraph.estimate_file import write_estimate

    est = MapEstimate([1], [[0.0, 0.0]], **kwargs)
    with pytest.raises(ConfigError, match=f"{match}.*read_estimate would refuse the file"):
        write_estimate(_one(est), tmp_path / "e.est")
    assert list(tmp_path.iterdir()) == []


def test_estimate_writer_refuses_checkpoints_and_timings_it_cannot_write(
        tmp_path: Path, result: object) -> None:
    """A checkpoint at t = 3.5 was written as t = 3; out of order or negative ones raised a
    plain ValueError, a MapEstimate or None estimate an AttributeError, a NaN time json's
    ValueError; add() outside the block a plain RuntimeError."""
    from bomgraph.estimate_file import EstimateWriter
    from bomgraph.mapper import Checkpoint, RunResult

    est = result.final
    cases = [([Checkpoint(3.5, est, 0.0)], r"checkpoint's t must be an integer >= 0, got 3.5"),
             ([Checkpoint(-3, est, 0.0)], r"checkpoint's t must be an integer >= 0"),
             ([Checkpoint(5, est, 0.0), Checkpoint(5, est, 0.0)], "increasing t: 5 after 5"),
             ([est], "needs a Checkpoint.*got MapEstimate"),
             ([Checkpoint(3, None, 0.0)], "got a Checkpoint whose estimate is NoneType"),
             ([Checkpoint(3, est, float("nan"))], "estimate_s must be finite"),
             ([Checkpoint(3, est, "fast")], "estimate_s must be a number")]
    for added, match in cases:
        with pytest.raises(ConfigError, match=match):
            with EstimateWriter(tmp_path / "e.est", "m") as w:
                for c in added:
                    w.add(c)
                w.finish()
    bad_total = RunResult("m", result.checkpoints, result.step_s, float("nan"))
    with pytest.raises(ConfigError, match="timings must be finite"):
        with EstimateWriter(tmp_path / "e.est", "m") as w:
            w.add(result.checkpoints[-1])
            w.finish(bad_total)
    with pytest.raises(ConfigError, match="result must be the RunResult or None"):
        with EstimateWriter(tmp_path / "e.est", "m") as w:
            w.add(result.checkpoints[-1])
            w.finish(est)
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ConfigError, match=r"add\(\) outside its with-block"):
        EstimateWriter(tmp_path / "e.est", "m").add(result.checkpoints[-1])


def test_stream_identity_refuses_a_stream_a_path_and_a_bad_identity(stream: Stream) -> None:
    """stream_identity(stream) raised 'Stream object is not iterable', a path an
    AttributeError; StreamIdentity("abc", -1) was written into a header its reader refuses."""
    from bomgraph.estimate_file import StreamIdentity, stream_identity

    for bad, hint in [(stream, r"pass stream.steps"), ("s.jsonl", "stream_file_identity"),
                      (None, "NoneType"), ([stream.steps[0], "x"], "step 1 is a str")]:
        with pytest.raises(ConfigError, match=f"stream_identity.*{hint}"):
            stream_identity(bad)
    good = stream_identity(stream.steps)
    for args, match in [(("abc", 3), "steps_sha256 must be the 64 hex digits"),
                        ((good.steps_sha256, -1), "n_steps must be an integer >= 0"),
                        ((good.steps_sha256, 2.0), "n_steps must be an integer >= 0")]:
        with pytest.raises(ConfigError, match=match):
            StreamIdentity(*args)


# ---- the stream writer: what it writes, read_stream reads -----------------------------------

def test_stream_writers_refuse_what_is_no_stream(tmp_path: Path, stream: Stream) -> None:
    """A header, the steps, a dict or None ended in AttributeError (or 'Stream object is not
    iterable') in write_stream, write_stream_parts, header_to_json and step_to_json."""
    from bomgraph.errors import StreamFormatError
    from bomgraph.stream_file import (header_to_json, step_to_json, write_stream,
                                      write_stream_parts)

    out = tmp_path / "s.jsonl"
    for bad in (stream.header, stream.steps, None):
        with pytest.raises(StreamFormatError, match="'stream': must be a Stream"):
            write_stream(bad, out)
    cases = [(({"bearing_sigma_rad": 0.1}, stream.steps), {}, "'header': must be a StreamHeader"),
             ((stream.header, stream.steps), {"truth": {}}, "'truth': must be a Truth"),
             ((stream.header, stream), {}, r"must be an iterable of Step.*pass stream.steps"),
             ((stream.header, [stream.steps[0], "x"]), {}, "steps\\[1\\] is a str, not a Step")]
    for args, kw, match in cases:
        with pytest.raises(StreamFormatError, match=match):
            write_stream_parts(*args, out, **kw)
    with pytest.raises(StreamFormatError, match="'header': must be a StreamHeader"):
        header_to_json(None)
    with pytest.raises(StreamFormatError, match="'step': must be a Step"):
        step_to_json({"t": 0})
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("how", ["reversed", "late start", "no step", "truth of another run"])
def test_write_stream_parts_refuses_a_stream_read_stream_refuses(tmp_path: Path,
                                                                 stream: Stream,
                                                                 how: str) -> None:
    """Each was written, and read_stream then refused the file."""
    from bomgraph.errors import StreamFormatError
    from bomgraph.stream_file import write_stream_parts

    steps = {"reversed": stream.steps[::-1], "late start": stream.steps[1:], "no step": (),
             "truth of another run": stream.steps[:5]}[how]
    match = {"reversed": "step 0 has t = 25", "late start": "step 0 has t = 1",
             "no step": "no steps", "truth of another run": "26 truth poses for 5 steps"}[how]
    with pytest.raises(StreamFormatError, match=match):
        write_stream_parts(stream.header, iter(steps), tmp_path / "s.jsonl", truth=stream.truth)
    assert list(tmp_path.iterdir()) == []


# ---- experiments: the constructors and the functions that build them -----------------------

@pytest.mark.parametrize("kwargs,match", [
    ({"label": None}, "label must be a str"),
    ({"method": None}, "method .* must be a str"),
    ({"prior_fraction": "0.5"}, "prior_fraction must be a number"),
    ({"prior_fraction": 2.0}, r"prior_fraction must be in \[0, 1\]"),
    ({"prior_fraction": float("nan")}, r"prior_fraction must be in \[0, 1\]"),
    ({"checkpoint_every": 0}, "checkpoint_every must be an integer >= 1"),
    ({"checkpoint_every": "5"}, "checkpoint_every must be an integer >= 1"),
])
def test_arm_refuses_fields_of_the_wrong_kind(kwargs: dict, match: str) -> None:
    """Each was accepted and failed (or ran something else) only when the sweep ran."""
    from bomgraph.experiments import Arm

    with pytest.raises(ConfigError, match=match):
        Arm(**{"label": "a", "method": "triangulate", **kwargs})


def test_experiment_refuses_arms_sources_and_settings_of_the_wrong_kind(tmp_path: Path
                                                                        ) -> None:
    """sources="s.jsonl" made one task per character of the name; arms=Arm(...) and
    worlds=World(...) ended in 'not iterable', sim={...} in 'unhashable', n_layouts=2.5 and
    seed=-1 in numpy's errors; checkpoint_every=0 and seed="1" were accepted."""
    from bomgraph.experiments import Arm, Experiment, World
    from bomgraph.sim import SimConfig

    arm = Arm("a", "triangulate")
    cases = [({"arms": arm}, r"arms must be a list or tuple of Arm.*a list of one"),
             ({"arms": ["triangulate"]}, r"arms\[0\] is str 'triangulate'"),
             ({"sources": str(tmp_path / "s.jsonl")}, "sources must be a list or tuple"),
             ({"sources": [str(tmp_path / "s.jsonl")]}, r"sources\[0\] is str"),
             ({"worlds": World("w", SimConfig(), (1,))}, "worlds must be a list or tuple"),
             ({"sim": {"n_steps": 5}}, "sim must be a SimConfig"),
             ({"reference": "ekf"}, "reference must be a Arm or NoneType"),
             ({"n_layouts": 2.5}, "n_layouts must be an integer >= 1"),
             ({"seed": -1}, "seed must be an integer >= 0"),
             ({"seed": "1"}, "seed must be an integer >= 0"),
             ({"checkpoint_every": 0}, "checkpoint_every must be an integer >= 1")]
    for kwargs, match in cases:
        with pytest.raises(ConfigError, match=f"experiment 'e': {match}"):
            Experiment(**{"name": "e", "title": "t", "arms": (arm,), **kwargs}).tasks()


def test_sources_and_tasks_refuse_fields_of_the_wrong_kind(tmp_path: Path) -> None:
    """SimSource(None) and Task(source=None) ended in AttributeError, WorldSource(seed="1")
    in numpy's SeedSequence TypeError, World(seeds=3) in 'not iterable', FileSource(None) in
    os.stat's TypeError and a missing stream file in a raw FileNotFoundError."""
    from bomgraph.errors import StreamFormatError
    from bomgraph.experiments import Arm, FileSource, SimSource, Task, World, WorldSource
    from bomgraph.sim import SimConfig

    sim = SimConfig(n_steps=10)
    cases = [(lambda: SimSource(None), "SimSource: spec .* must be a RunSpec"),
             (lambda: WorldSource(sim, "1"), "seed must be an integer >= 0, got '1'"),
             (lambda: WorldSource(sim, 1.5), "seed must be an integer >= 0, got 1.5"),
             (lambda: World("w", sim, 3), "seeds must be a list or tuple of integer seeds"),
             (lambda: World("w", sim, (1, -2)), r"seeds\[1\] must be an integer >= 0"),
             (lambda: FileSource(None), "FileSource: path must be a file name"),
             (lambda: Task("e", Arm("a", "triangulate"), None), "Task: source must be a")]
    for make, match in cases:
        with pytest.raises(ConfigError, match=match):
            make()
    missing = FileSource(str(tmp_path / "gone.jsonl"))
    for call in (missing.stream, missing.key):
        with pytest.raises(StreamFormatError, match="gone.jsonl: cannot open"):
            call()


def test_experiment_functions_refuse_arguments_of_the_wrong_kind() -> None:
    """select(exps, "ab") picked experiments 'a' and 'b' (the characters of the name);
    real_experiments(dir, methods="ekf") made arms 'e', 'k', 'f'; compare_experiments read a
    str of streams as its characters, took checkpoint_every=0 as 10 and ended in
    AttributeError for a list of methods; designed_variant({...}) and load_experiments(None)
    in AttributeError/TypeError."""
    from bomgraph.experiments import (compare_experiments, designed_variant, load_experiments,
                                      real_experiments, select)

    exps = {"a": 1, "b": 2, "ab": 3}
    cases = [(lambda: select(exps, "ab"), "select\\(\\): names must be a list or tuple"),
             (lambda: select(list(exps), ["a"]), "select\\(\\): experiments .* Mapping"),
             (lambda: designed_variant(exps), "designed_variant\\(\\): experiments must be"),
             (lambda: load_experiments(None), "sweep file .* must be a file name"),
             (lambda: real_experiments(None), "data_dir must be a file name"),
             (lambda: real_experiments(".", methods="ekf"), "methods must be a list or tuple"),
             (lambda: compare_experiments(streams="s.jsonl", methods="ekf"),
              "streams must be a list or tuple of stream file names"),
             (lambda: compare_experiments(streams=["s.jsonl"], methods=["ekf"]),
              "methods .* must be a str"),
             (lambda: compare_experiments(streams=["s.jsonl"], methods="ekf",
                                          options="ekf:preset=real"),
              "options must be a list or tuple"),
             (lambda: compare_experiments(streams=["s.jsonl"], methods="ekf",
                                          checkpoint_every=0),
              "checkpoint_every must be an integer >= 1")]
    for call, match in cases:
        with pytest.raises(ConfigError, match=match):
            call()


# ---- run() and RunResult --------------------------------------------------------------------

def test_run_refuses_a_method_name_that_is_no_str_and_an_empty_result_has_no_final(
        stream: Stream) -> None:
    """run(method=3) made a RunResult whose method 3 the estimate file then held as "3";
    RunResult(...).final of a result without checkpoints raised IndexError."""
    from bomgraph.mapper import RunResult, create_mapper, run

    with pytest.raises(ConfigError, match=r"run\(\): method must be the method's name"):
        run(create_mapper("triangulate", stream.header), stream.steps, method=3)
    with pytest.raises(ConfigError, match="has no checkpoint, so no final map"):
        RunResult("m", (), np.zeros(0), 0.0).final
