"""Plausibility limits of a stream: values the format allows but no real run has (issue 13,
items 11 and 20).

``shared/STREAM_FORMAT.md`` asks only for finite numbers and positive sigmas, so a header with
``bearing_sigma_rad = 1e300`` or a step of 1e12 m is a valid file. Such values come from a
mistake upstream (a noise scale typed with an extra exponent, swapped columns, a corrupt
velocity), and no method can use them. The rule:

* the stream **reader** warns (``logging``), naming the file, the line and the key, and goes
  on: the file is valid;
* **importers** and ``simulate`` make streams, and refuse to make an implausible one
  (:func:`refuse_implausible`), naming the cause.

The limits are deliberately wide (orders of magnitude beyond any recording bomgraph knows):
they catch absurd values, not unusual ones.
"""

from __future__ import annotations

import math
from typing import Iterable

import numpy as np

from .errors import BomgraphError
from .stream import Step, StreamHeader

#: a bearing sigma above pi: the bearings are uniform on the circle, they carry no information.
MAX_BEARING_SIGMA_RAD = math.pi
#: a bearing sigma below a nanoradian (the finest star trackers reach about 1e-7 rad): a
#: sigma typed with a wrong exponent. At 1e-300 its square underflows to 0 and every method's
#: weights 1 / sigma^2 overflow.
MIN_BEARING_SIGMA_RAD = 1e-9
#: an odometry sigma above this (metres for dx, dy; radians for dpsi): no information.
MAX_ODOMETRY_SIGMA = (1e5, 1e5, 2 * math.pi)
#: a sensor reaching less than a micrometre or further than 1000 km.
SENSOR_RANGE_LIMITS_M = (1e-6, 1e6)
#: one step (the motion between two consecutive poses) longer than 100 km.
MAX_STEP_M = 1e5
#: a truth coordinate further than this from the origin.
MAX_COORDINATE_M = 1e9
#: a bearing as written in a stream, or a step's turn, beyond a full turn: the format's angles
#: are radians (and bearings are wrapped on reading), so such a value is most likely degrees.
MAX_ABS_ANGLE_RAD = 2 * math.pi


def header_problems(header: StreamHeader) -> list[tuple[str, str]]:
    """``(key, message)`` for each implausible value of ``header`` (empty when plausible)."""
    out: list[tuple[str, str]] = []
    if header.bearing_sigma_rad > MAX_BEARING_SIGMA_RAD:
        out.append(("bearing_sigma_rad",
                    f"{header.bearing_sigma_rad:g} rad is above pi: bearings that uncertain "
                    f"carry no information (a noise scale or sigma off by orders of "
                    f"magnitude?)"))
    elif header.bearing_sigma_rad < MIN_BEARING_SIGMA_RAD:
        out.append(("bearing_sigma_rad",
                    f"{header.bearing_sigma_rad:g} rad is below {MIN_BEARING_SIGMA_RAD:g}: no "
                    f"sensor measures bearings that precisely, and the methods' weights "
                    f"1/sigma^2 overflow (a sigma off by orders of magnitude?)"))
    for name, value, limit in zip(("sigma_dx_m", "sigma_dy_m", "sigma_dpsi_rad"),
                                  header.odometry_sigma, MAX_ODOMETRY_SIGMA):
        if value > limit:
            out.append(("odometry_sigma", f"{name} = {value:g} is above {limit:g}: odometry "
                                          f"that uncertain carries no information"))
    lo, hi = SENSOR_RANGE_LIMITS_M
    r = header.sensor_range_m
    if r is not None and not lo <= r <= hi:
        out.append(("sensor_range_m", f"{r:g} m is outside [{lo:g}, {hi:g}] m: no sensor "
                                      f"reaches that (give null if the range is unknown)"))
    return out


def bearings_problem(t: int, bearings_rad: np.ndarray) -> tuple[str, str] | None:
    """``(key, message)`` if a bearing of step ``t`` *as written* (before wrapping) is beyond a
    full turn (:data:`MAX_ABS_ANGLE_RAD`), else None: bearings in degrees. The reader checks
    the values it parsed; a :class:`~bomgraph.stream.Step` holds them wrapped."""
    if bearings_rad.size:
        worst = float(np.max(np.abs(bearings_rad)))
        if not worst <= MAX_ABS_ANGLE_RAD:
            return ("bearings", f"step {t}: a bearing of {worst:g} is more than a full turn; "
                                f"bearings are radians (degrees?)")
    return None


def step_problem(step: Step, sigma_dpsi_rad: float = 0.0, *,
                 turn: bool = True) -> tuple[str, str] | None:
    """``(key, message)`` if ``step``'s odometry is implausible, else None. A turn is taken
    for degrees beyond a full turn and beyond 5 of its stated sigmas (the step's, else
    ``sigma_dpsi_rad``, the header's): a simulated stream of a large noise scale draws such
    turns from its own noise. ``turn`` False: the turn is not judged at all."""
    if step.odom is not None:
        length = math.hypot(float(step.odom[0]), float(step.odom[1]))
        if length > MAX_STEP_M:
            return ("odom", f"step {step.t} moves {length:g} m, more than {MAX_STEP_M:g} m "
                            f"in one step (a corrupt velocity, time stamp or unit?)")
        sigma = float(step.odom_sigma[2]) if step.odom_sigma is not None else sigma_dpsi_rad
        if turn and abs(float(step.odom[2])) > max(MAX_ABS_ANGLE_RAD, 5 * sigma):
            return ("odom", f"step {step.t} turns {float(step.odom[2]):g} rad, more than a full "
                            f"turn in one step; dpsi_rad is radians (degrees?)")
    if step.odom_sigma is not None:
        for name, value, limit in zip(("sigma_dx_m", "sigma_dy_m", "sigma_dpsi_rad"),
                                      step.odom_sigma, MAX_ODOMETRY_SIGMA):
            if value > limit:
                return ("odom_sigma", f"step {step.t}: {name} = {value:g} is above {limit:g}")
    return None


def truth_problem(landmarks_xy: np.ndarray, poses: np.ndarray | None) -> str | None:
    """A message if a truth coordinate is beyond :data:`MAX_COORDINATE_M`, else None."""
    for what, xy in (("landmark", landmarks_xy), ("pose", poses)):
        if xy is not None and len(xy) and np.max(np.abs(xy[:, :2])) > MAX_COORDINATE_M:
            return (f"a truth {what} coordinate is {np.max(np.abs(xy[:, :2])):g} m from the "
                    f"origin, beyond {MAX_COORDINATE_M:g} m")
    return None


def refuse_implausible(header: StreamHeader, steps: Iterable[Step],
                       error: type[BomgraphError], source: str, *,
                       landmarks_xy: np.ndarray | None = None,
                       poses: np.ndarray | None = None) -> None:
    """Raise ``error`` naming the first implausible value of a stream being made by
    ``source`` (an importer, the simulator): the header's sigmas and range, each step's
    odometry, the truth's coordinates."""
    problems = header_problems(header)
    if problems:
        key, msg = problems[0]
        raise error(f"{source}: '{key}': {msg}; refusing to write an implausible stream")
    for st in steps:
        # a turn is not judged here: importers compute turns from their data or read them
        # from a format that wraps angles (g2o), so one beyond 2 pi is valid there (whatever
        # sigma the step states: an infinite header sigma did not stop a step's own)
        p = step_problem(st, turn=False)
        if p is not None:
            raise error(f"{source}: '{p[0]}': {p[1]}; refusing to write an implausible stream")
    msg = truth_problem(np.zeros((0, 2)) if landmarks_xy is None else landmarks_xy, poses)
    if msg is not None:
        raise error(f"{source}: {msg}; refusing to write an implausible stream")


__all__ = ["MAX_BEARING_SIGMA_RAD", "MAX_ODOMETRY_SIGMA", "SENSOR_RANGE_LIMITS_M", "MAX_STEP_M",
           "MAX_COORDINATE_M", "MAX_ABS_ANGLE_RAD", "header_problems", "bearings_problem",
           "step_problem", "truth_problem",
           "refuse_implausible"]
