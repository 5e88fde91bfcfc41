"""STMDS on hostile but format-valid streams (issue 13 items 11 and 12): a finite estimate or a
BomgraphError that names the cause, never another exception."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bomgraph.errors import BomgraphError
from bomgraph.mapper import create_mapper, run
from bomgraph.sim import SimConfig, simulate

METHODS = ("stmds-cs", "stmds-smacof", "stmds-cs-loc", "stmds-smacof-loc")
PRESETS = (None, "improved", "window")


@pytest.fixture(scope="module")
def stream():
    return simulate(SimConfig(n_steps=60), np.random.default_rng(0))


def _run(method: str, preset: str | None, header, steps):
    mapper = create_mapper(method, header, **({} if preset is None else {"preset": preset}))
    return run(mapper, steps, checkpoint_every=10)


def _finite_or_bomgraph_error(method, preset, header, steps) -> BomgraphError | None:
    try:
        res = _run(method, preset, header, steps)
    except BomgraphError as exc:
        return exc
    for cp in res.checkpoints:
        assert np.all(np.isfinite(cp.estimate.landmarks_xy))
        if cp.estimate.poses is not None:
            assert np.all(np.isfinite(cp.estimate.poses))
    return None


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("preset", (None, "improved"))
def test_stuck_sensor_is_named_not_an_internal_function(stream, method, preset) -> None:
    """Every landmark at one constant bearing: all rays of a step cross in one point."""
    steps = [dataclasses.replace(s, bearings_rad=np.full(len(s.bearings_rad), 0.3))
             for s in stream.steps]
    with pytest.raises(BomgraphError) as err:
        _run(method, preset, stream.header, steps)
    msg = str(err.value)
    assert "stuck" in msg and "one point" in msg
    assert "shortest_path" not in msg and "classical_scaling" not in msg


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("field,value", [("bearing_sigma_rad", 1e300),
                                         ("odometry_sigma", (1e300, 0.0, 1e300))])
def test_absurd_header_sigmas_are_refused_by_name(stream, method, field, value) -> None:
    header = dataclasses.replace(stream.header, **{field: value})
    with pytest.raises(BomgraphError, match=field):
        _run(method, None, header, stream.steps)


def test_absurd_step_sigma_is_refused_by_step(stream) -> None:
    steps = list(stream.steps)
    steps[7] = dataclasses.replace(steps[7], odom_sigma=np.array([1e300, 0.0, 0.1]))
    with pytest.raises(BomgraphError, match="step 7"):
        _run("stmds-smacof", None, stream.header, steps)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("case", ["range-1e300", "range-1e-300", "step-1e12", "sigma-1e6"])
def test_extreme_valid_values_give_a_finite_map_or_a_bomgraph_error(stream, method, preset,
                                                                    case) -> None:
    header, steps = stream.header, list(stream.steps)
    if case == "range-1e300":
        header = dataclasses.replace(header, sensor_range_m=1e300)
    elif case == "range-1e-300":
        header = dataclasses.replace(header, sensor_range_m=1e-300)
    elif case == "sigma-1e6":
        header = dataclasses.replace(header, bearing_sigma_rad=1e6,
                                     odometry_sigma=(1e6, 1e6, 1e6))
    else:
        s = steps[20]
        steps[20] = dataclasses.replace(s, odom=np.array([1e12, 0.0, s.odom[2]]))
    with np.errstate(all="ignore"):
        _finite_or_bomgraph_error(method, preset, header, steps)
