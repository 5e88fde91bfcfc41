"""Misuse of MapEstimate, run(), create_mapper() and register_method() from Python, and
methods that break the Mapper protocol: each is refused where it enters, with a
BomgraphError naming the argument (or the method) and the fix, never a raw
TypeError/AttributeError deep inside or a silently reshaped map."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bomgraph import errors, mapper
from bomgraph.errors import BomgraphError, ConfigError
from bomgraph.evaluate import score_estimate
from bomgraph.mapper import MapEstimate, create_mapper, run
from bomgraph.sim import SimConfig, paper_design, simulate_run
from bomgraph.stream import Step, StreamHeader, Truth

H = StreamHeader(0.05, (0.03, 0.0, 0.05))


@pytest.fixture(scope="module")
def stream() -> Any:
    return simulate_run(paper_design(0)[0], SimConfig(n_steps=25))


def _protocol_error(exc: BaseException) -> bool:
    return type(exc).__name__ == "MethodProtocolError" and isinstance(exc, BomgraphError)


def test_map_estimate_refuses_columns_instead_of_rows() -> None:
    """A (2, n) array was reshaped to (n, 2), pairing x of one landmark with x of the next:
    a map scored as if it were right."""
    ids = np.array([1, 2, 3, 4])
    cols = np.array([[0.0, 1.0, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0]])
    with pytest.raises(ConfigError, match=r"landmarks_xy must have shape \(n, 2\), got \(2, 4\)"
                                          r"; transpose"):
        MapEstimate(ids, cols)
    with pytest.raises(ConfigError, match=r"poses must have shape \(n, 3\), got \(3, 4\)"):
        MapEstimate(ids, cols.T, pose_t=[0, 1, 2, 3], poses=np.zeros((3, 4)))
    with pytest.raises(ConfigError, match=r"landmark_cov must have shape \(n, 2, 2\)"):
        MapEstimate(ids, cols.T, landmark_cov=np.zeros(16))
    assert score_estimate(MapEstimate(ids, cols.T), Truth(ids, cols.T)).mpe_m < 1e-12


@pytest.mark.parametrize("kwargs,match", [
    ({"landmark_ids": None}, "landmark_ids is required"),
    ({"landmarks_xy": None}, "landmarks_xy is required"),
    ({"landmark_ids": [1e30]}, "must be integers"),
    ({"info": None}, "info must be a mapping"),
    ({"info": [1]}, "info must be a mapping"),
])
def test_map_estimate_refuses_missing_parts_huge_ids_and_non_dict_info(kwargs: dict,
                                                                        match: str) -> None:
    args = {"landmark_ids": [1], "landmarks_xy": [[0.0, 0.0]], **kwargs}
    with pytest.raises(ConfigError, match=match):
        MapEstimate(**args)


def _reorder(steps: tuple, how: str) -> list:
    return {"late start": list(steps[5:]), "reversed": list(steps[::-1]),
            "gap": list(steps[:3] + steps[5:]), "twice": list(steps + steps)}[how]


@pytest.mark.parametrize("how", ["late start", "reversed", "gap", "twice"])
def test_run_refuses_steps_out_of_order(stream: Any, how: str) -> None:
    with pytest.raises(ConfigError, match="steps must come in order t = 0, 1, 2"):
        run(create_mapper("triangulate", stream.header), _reorder(stream.steps, how))


def test_run_refuses_odometry_against_the_rule_and_things_that_are_not_steps(stream: Any
                                                                             ) -> None:
    m = create_mapper("triangulate", stream.header)
    with pytest.raises(ConfigError, match="step 0: odom must be None at t = 0"):
        run(m, [Step(0, [0.1, 0.0, 0.0], [1], [0.1])])
    with pytest.raises(ConfigError, match="step 1: odom must be None at t = 0 and given after"):
        run(m, [stream.steps[0], Step(1, None, [1], [0.1])])
    with pytest.raises(ConfigError, match=r"step 0 is a tuple, not a bomgraph.stream.Step"):
        run(m, [(0, None, [1], [0.1])])
    with pytest.raises(ConfigError, match=r"got Stream \(pass stream.steps\)"):
        run(m, stream)
    with pytest.raises(ConfigError, match=r"got Step \(pass \[step\]\)"):
        run(m, stream.steps[0])
    with pytest.raises(ConfigError, match="steps must be an iterable of Step, got NoneType"):
        run(m, None)  # type: ignore[arg-type]


@pytest.mark.parametrize("every", [0, -1, 2.5, "10", None, True])
def test_run_refuses_a_checkpoint_cadence_that_is_not_a_positive_integer(stream: Any,
                                                                         every: Any) -> None:
    with pytest.raises(ConfigError, match="checkpoint_every must be an integer >= 1"):
        run(create_mapper("triangulate", stream.header), stream.steps, checkpoint_every=every)


def test_run_refuses_a_non_mapper_and_a_non_callable_hook_before_the_first_step(stream: Any
                                                                                ) -> None:
    m = create_mapper("triangulate", stream.header)
    for bad, what in [(None, "a NoneType"), ("ekf", "a str"),
                      (type(m), f"the class {type(m).__name__} \\(build it first\\)")]:
        with pytest.raises(BomgraphError, match=f"mapper is {what}, not a Mapper") as exc:
            run(bad, stream.steps)  # type: ignore[arg-type]
        assert _protocol_error(exc.value)
    with pytest.raises(ConfigError, match="on_checkpoint must be callable"):
        run(m, stream.steps, on_checkpoint=5)  # type: ignore[arg-type]


@pytest.mark.parametrize("header", [None, {"bearing_sigma_rad": 0.1}, "stream"])
@pytest.mark.parametrize("name", ["triangulate", "ekf", "stmds-smacof"])
def test_create_mapper_refuses_a_header_of_the_wrong_type(stream: Any, name: str,
                                                          header: Any) -> None:
    header = stream if header == "stream" else header
    with pytest.raises(ConfigError, match=r"header must be a StreamHeader \(stream.header\)"):
        create_mapper(name, header)


def test_create_mapper_refuses_a_truth_of_the_wrong_type(stream: Any) -> None:
    with pytest.raises(ConfigError, match=r"truth must be a Truth \(stream.truth\) or None"):
        create_mapper("oracle", stream.header, truth={"poses": []})  # type: ignore[arg-type]


BROKEN = '''
import numpy as np
from bomgraph.mapper import MapEstimate

class NotAMapper:
    def __init__(self, header): pass

def returns_none(header): return None

class Base:
    def __init__(self, header): pass
    def step(self, step): pass

class ReturnsDict(Base):
    def estimate(self): return {"landmark_ids": [1], "landmarks_xy": [[0.0, 0.0]]}

class ReturnsNone(Base):
    def estimate(self): return None

class Transposed(Base):
    def estimate(self):
        return MapEstimate([1, 2, 3], np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
'''


@pytest.fixture
def broken(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "broken_methods.py").write_text(BROKEN)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "broken_methods", raising=False)
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    for name in ("NotAMapper", "returns_none", "ReturnsDict", "ReturnsNone", "Transposed"):
        mapper.register_method(name, f"broken_methods:{name}", "breaks the protocol")


@pytest.mark.parametrize("name,match", [
    ("NotAMapper", "method 'NotAMapper': its factory broken_methods:NotAMapper returned "
                   "NotAMapper, not a Mapper"),
    ("returns_none", "method 'returns_none': its factory broken_methods:returns_none "
                     "returned NoneType, not a Mapper"),
])
def test_a_factory_that_returns_no_mapper_is_named(stream: Any, broken: None, name: str,
                                                   match: str) -> None:
    with pytest.raises(BomgraphError, match=match) as exc:
        create_mapper(name, stream.header)
    assert _protocol_error(exc.value)


@pytest.mark.parametrize("name,got", [("ReturnsDict", "dict"), ("ReturnsNone", "NoneType")])
def test_an_estimate_that_is_no_map_estimate_names_the_method(stream: Any, broken: None,
                                                              name: str, got: str) -> None:
    with pytest.raises(BomgraphError, match=f"{name}.estimate\\(\\) returned {got} after step "
                                            f"10; a Mapper's estimate\\(\\) must return a "
                                            f"bomgraph.mapper.MapEstimate") as exc:
        run(create_mapper(name, stream.header), stream.steps)
    assert _protocol_error(exc.value)


def test_a_method_returning_columns_is_refused_not_scored(stream: Any, broken: None) -> None:
    with pytest.raises(ConfigError, match=r"landmarks_xy must have shape \(n, 2\), got \(2, 3\)"):
        run(create_mapper("Transposed", stream.header), stream.steps)


@pytest.mark.parametrize("name,target,match", [
    (None, "a:b", "name must be a non-empty string"), ("", "a:b", "name must be a non-empty"),
    ("x", None, "target must be 'module:attribute'"),
])
def test_register_method_refuses_a_name_or_target_that_is_not_a_string(
        monkeypatch: pytest.MonkeyPatch, name: Any, target: Any, match: str) -> None:
    """A None name was registered and then broke every later 'unknown method' message."""
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    with pytest.raises(ConfigError, match=match):
        mapper.register_method(name, target, "d")
    with pytest.raises(errors.UnknownMethodError, match="known methods: triangulate"):
        create_mapper("no-such-method", H)


FACTORIES = '''
def strict(header, *, window=3):
    raise AssertionError("not reached in these tests")

def buggy(header, **options):
    return len(None)          # a fault inside the factory: TypeError
'''


def test_a_typeerror_inside_a_factory_is_the_factory_s_not_the_options(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The options were blamed for any TypeError a factory raised ('bad options []')."""
    (tmp_path / "factories_h18.py").write_text(FACTORIES)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    mapper.register_method("strict", "factories_h18:strict", "d")
    mapper.register_method("buggy", "factories_h18:buggy", "d")
    with pytest.raises(errors.MethodProtocolError,
                       match=r"factory factories_h18:buggy raised TypeError .*look in the "
                             r"factory"):
        create_mapper("buggy", H)
    with pytest.raises(ConfigError, match=r"method 'strict': unknown option 'colour'"):
        create_mapper("strict", H, colour=1)        # a wrong option is still the options'
