"""Review of h151's method limits (helper h158): the shared dead reckoning (``Reach``) against
an independent computation, a method refusing a sigma it never uses, and a plugin's own
``start_pose`` option refused as a pose."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest

from bomgraph.geometry import compose
from bomgraph.mapper import create_mapper, run
from bomgraph.method_limits import Reach
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream import Step


def test_reach_dead_reckons_as_compose_bit_for_bit_and_as_complex_numbers() -> None:
    """``Reach.advance`` (scalar arithmetic since h158, on every step of every method) gives
    the bits of :func:`bomgraph.geometry.compose`, which ``ekf-invdepth``'s own dead
    reckoning and ``triangulate`` used before h151, and agrees with an independent
    computation (positions as complex numbers, headings unwrapped), turns of many revolutions
    included."""
    rng = np.random.default_rng(158)
    n = 5000
    odom = np.column_stack([rng.normal(0.5, 3.0, n), rng.normal(0.0, 1.0, n),
                            rng.normal(0.0, 2.0, n) * rng.choice([1.0, 1.0, 100.0, 1e6], n)])
    start = (3.0, -4.0, 2.5)
    reach, pose = Reach(start, "test"), np.array(start)
    z, heading = complex(3.0, -4.0), 2.5
    none = np.zeros(0, np.int64)
    for t, u in enumerate(odom, start=1):
        got = reach.advance(Step(t=t, landmark_ids=none, bearings_rad=np.zeros(0), odom=u))
        pose = compose(pose, u)
        assert got.tobytes() == pose.tobytes(), t
        z += np.exp(1j * heading) * complex(u[0], u[1])
        heading += u[2]
    assert abs(complex(pose[0], pose[1]) - z) < 1e-6 * max(abs(z), 1.0)
    assert abs(np.remainder(pose[2] - heading + np.pi, 2 * np.pi) - np.pi) < 1e-6


def test_triangulate_takes_any_sigma_as_it_uses_none() -> None:
    """``triangulate`` uses no sigma: it took a header's odometry sigma of 2e6 m but refused
    the same sigma given by one step (``Reach``'s sigma check, meant for the methods that
    weigh by it), so the same value was refused or not by where the stream put it. Both are
    taken now, and the map is the one of the stream without them."""
    s = simulate(SimConfig(n_steps=40, n_landmarks=12), np.random.default_rng(3))
    steps = list(s.steps)
    steps[5] = dataclasses.replace(steps[5], odom_sigma=np.array([2e6, 2e6, 0.05]))
    plain = run(create_mapper("triangulate", s.header), s.steps).final
    for header, feed in ((s.header, steps),
                         (dataclasses.replace(s.header, odometry_sigma=(2e6, 0.0, 0.05)),
                          s.steps)):
        final = run(create_mapper("triangulate", header), feed).final
        assert np.array_equal(final.landmarks_xy, plain.landmarks_xy)


PLUGIN = '''
from bomgraph.mapper import MapEstimate


class IndexStart:
    """anchored at the pose of step ``start_pose`` (an index, not a pose)"""

    def __init__(self, header, *, start_pose: int = 0):
        self.start_pose = start_pose

    def step(self, step):
        pass

    def estimate(self):
        return MapEstimate.empty(reason="none")


class PoseStart:
    """a start pose as the built-in methods take it"""

    def __init__(self, header, *, start_pose=(0.0, 0.0, 0.0)):
        self.start_pose = start_pose

    def step(self, step):
        pass

    def estimate(self):
        return MapEstimate.empty(reason="none")
'''


def test_a_plugin_s_own_start_pose_is_not_checked_as_a_pose(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """h151's check before any run took every factory's ``start_pose`` for a pose: a plugin
    whose ``start_pose: int`` is an index was refused "must be [x_m, y_m, psi_rad]" (in
    compare, sweeps, ``execute()``). Only a pose-like parameter is checked now (annotated as
    a sequence or an array, or unannotated with a pose or no default)."""
    from bomgraph import mapper
    from bomgraph.errors import ConfigError

    (tmp_path / "h158plug.py").write_text(PLUGIN)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "h158plug", raising=False)
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    mapper.register_method("h158-index", "h158plug:IndexStart", "an index")
    mapper.register_method("h158-pose", "h158plug:PoseStart", "a pose")
    mapper.check_method_options("h158-index", {"start_pose": 5})
    with pytest.raises(ConfigError, match="option start_pose: must be .x_m, y_m, psi_rad"):
        mapper.check_method_options("h158-pose", {"start_pose": 5})
    mapper.check_method_options("h158-pose", {"start_pose": [1.0, 2.0, 0.5]})
