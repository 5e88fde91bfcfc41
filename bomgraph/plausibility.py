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
they catch absurd values, not unusual ones. Two are set by what the numbers can mean rather
than by magnitude: an angle's sigma above the spread of an angle uniform on the circle
(:data:`MAX_ANGLE_SIGMA_RAD`), and odometry that moves or turns far less than its stated noise
alone would move it (:class:`OdometryScale`, judged by the reader only, after the last step:
a warning, as the stream is valid).
"""

from __future__ import annotations

import math
from typing import Iterable, Sequence

import numpy as np

from .errors import BomgraphError
from .stream import Prior, Step, StreamHeader

#: pi/sqrt(3) (1.81 rad), the standard deviation of an angle uniform on the circle. An angle
#: error wrapped to (-pi, pi] (every method wraps bearing and heading residuals) that is
#: symmetric and unimodal spreads at most this much, and that much only when it carries no
#: information; so a stated bearing or turn sigma above it is the spread of no such error: a
#: sigma in degrees, or a noise scale off by orders of magnitude (the paper's is 0.0524 rad).
MAX_ANGLE_SIGMA_RAD = math.pi / math.sqrt(3)
#: a bearing sigma above :data:`MAX_ANGLE_SIGMA_RAD`
MAX_BEARING_SIGMA_RAD = MAX_ANGLE_SIGMA_RAD
#: a bearing sigma below a nanoradian (the finest star trackers reach about 1e-7 rad): a
#: sigma typed with a wrong exponent. At 1e-300 its square underflows to 0 and every method's
#: weights 1 / sigma^2 overflow.
MIN_BEARING_SIGMA_RAD = 1e-9
#: the header's odometry sigmas above this (metres for dx, dy; radians for dpsi, as for a
#: bearing): a header's turn sigma above pi/sqrt(3) is most likely degrees
MAX_ODOMETRY_SIGMA = (1e5, 1e5, MAX_ANGLE_SIGMA_RAD)
#: a step's own odometry sigmas above this: one step's turn sigma up to a full turn is a
#: valid "turn unknown" (a g2o edge whose rotation information is below 0.3 states one; the
#: g2o importer keeps such sigmas on the steps, not in the header)
MAX_STEP_ODOMETRY_SIGMA = (1e5, 1e5, 2 * math.pi)
#: a turn beyond this many of its stated sigmas (and a full turn) is taken for degrees: once
#: in 4e11 steps a draw of the noise (5 sigmas, once in 1.7 million, were drawn by a 2000-step
#: simulation at noise scale 34, whose turn sigma is 1.78 rad)
TURN_SIGMAS = 7.0
#: odometry that moves (or turns), on average over a stream, less than this fraction of what
#: its stated noise alone would move it (:class:`OdometryScale`): sigmas in cm or degrees
MIN_MOTION_PER_NOISE = 0.1
#: the fewest odometry steps :class:`OdometryScale` judges (with 10 steps of pure noise,
#: the chance of averaging below a tenth of the bound is about 3e-9)
MIN_SCALE_STEPS = 10
#: a sensor reaching less than a micrometre or further than 1000 km.
SENSOR_RANGE_LIMITS_M = (1e-6, 1e6)
#: a prior's sigma outside these metres: below, its weight 1/sigma^2 overflows (a prior of
#: sigma 1e-300 m made every BOM-STMDS weight inf); above, it carries no information
PRIOR_SIGMA_LIMITS_M = (1e-9, 1e5)
#: one step (the motion between two consecutive poses) longer than 100 km.
MAX_STEP_M = 1e5
#: a truth coordinate further than this from the origin.
MAX_COORDINATE_M = 1e9
#: a bearing as written in a stream, or a step's turn, beyond a full turn: the format's angles
#: are radians (and bearings are wrapped on reading), so such a value is most likely degrees.
MAX_ABS_ANGLE_RAD = 2 * math.pi


_DEGREES = (" (pi/sqrt(3), the spread of a heading uniform on the circle; a sigma in "
            "degrees?)")


def header_problems(header: StreamHeader) -> list[tuple[str, str]]:
    """``(key, message)`` for each implausible value of ``header`` (empty when plausible;
    of its priors, the first implausible one)."""
    out: list[tuple[str, str]] = []
    if header.bearing_sigma_rad > MAX_BEARING_SIGMA_RAD:
        out.append(("bearing_sigma_rad",
                    f"{header.bearing_sigma_rad:g} rad is above pi/sqrt(3) = "
                    f"{MAX_BEARING_SIGMA_RAD:.3g} rad, the spread of a bearing uniform on the "
                    f"circle: no bearing error spreads more (a sigma in degrees, or off by "
                    f"orders of magnitude?)"))
    elif header.bearing_sigma_rad < MIN_BEARING_SIGMA_RAD:
        out.append(("bearing_sigma_rad",
                    f"{header.bearing_sigma_rad:g} rad is below {MIN_BEARING_SIGMA_RAD:g}: no "
                    f"sensor measures bearings that precisely, and the methods' weights "
                    f"1/sigma^2 overflow (a sigma off by orders of magnitude?)"))
    for name, value, limit in zip(("sigma_dx_m", "sigma_dy_m", "sigma_dpsi_rad"),
                                  header.odometry_sigma, MAX_ODOMETRY_SIGMA):
        if value > limit:
            out.append(("odometry_sigma", f"{name} = {value:g} is above {limit:.3g}: odometry "
                                          f"that uncertain carries no information"
                                          + _DEGREES * (name == "sigma_dpsi_rad")))
    lo, hi = SENSOR_RANGE_LIMITS_M
    r = header.sensor_range_m
    if r is not None and not lo <= r <= hi:
        out.append(("sensor_range_m", f"{r:g} m is outside [{lo:g}, {hi:g}] m: no sensor "
                                      f"reaches that (give null if the range is unknown)"))
    for k, p in enumerate(header.priors):   # the first implausible prior
        if not PRIOR_SIGMA_LIMITS_M[0] <= p.sigma_m <= PRIOR_SIGMA_LIMITS_M[1]:
            out.append((f"priors[{k}].sigma_m", f"{p.sigma_m:g} m is outside "
                                                f"[{PRIOR_SIGMA_LIMITS_M[0]:g}, "
                                                f"{PRIOR_SIGMA_LIMITS_M[1]:g}] m: no "
                                                f"measurement of a distance is that precise "
                                                f"(or that vague)"))
            break
        if p.distance_m > MAX_COORDINATE_M:
            out.append((f"priors[{k}].distance_m", f"{p.distance_m:g} m is beyond "
                                                   f"{MAX_COORDINATE_M:g} m (squared, it leaves "
                                                   f"double precision)"))
            break
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
    for degrees beyond a full turn and beyond :data:`TURN_SIGMAS` of its stated sigmas (the
    step's, else ``sigma_dpsi_rad``, the header's): a simulated stream of a large noise scale
    draws such turns from its own noise. ``turn`` False: the turn is not judged at all."""
    if step.odom is not None:
        length = math.hypot(float(step.odom[0]), float(step.odom[1]))
        if length > MAX_STEP_M:
            return ("odom", f"step {step.t} moves {length:g} m, more than {MAX_STEP_M:g} m "
                            f"in one step (a corrupt velocity, time stamp or unit?)")
        sigma = float(step.odom_sigma[2]) if step.odom_sigma is not None else sigma_dpsi_rad
        if turn and abs(float(step.odom[2])) > max(MAX_ABS_ANGLE_RAD, TURN_SIGMAS * sigma):
            return ("odom", f"step {step.t} turns {float(step.odom[2]):g} rad, more than a full "
                            f"turn in one step; dpsi_rad is radians (degrees?)")
    if step.odom_sigma is not None:
        for name, value, limit in zip(("sigma_dx_m", "sigma_dy_m", "sigma_dpsi_rad"),
                                      step.odom_sigma, MAX_STEP_ODOMETRY_SIGMA):
            if value > limit:
                return ("odom_sigma", f"step {step.t}: {name} = {value:g} is above {limit:.3g}"
                                      + " (a full turn; degrees?)" * (name == "sigma_dpsi_rad"))
    return None


#: sqrt(2/pi): E|n| / sigma of Gaussian noise n, the bound :class:`OdometryScale` judges by
_K = math.sqrt(2 / math.pi)


class OdometryScale:
    """Whether a stream's stated odometry sigmas fit its odometry: :meth:`add` each step,
    then :meth:`problems`.

    Whatever the true motion, odometry with zero-mean symmetric noise moves on average at
    least as far as the noise alone (``E|d + n| >= E|n|``: ``|.|`` is convex and even), and
    ``E|n| >= sqrt(2/pi) sigma`` for the larger translation sigma (and for the turn's). So
    each step's motion over that bound is 1 or more on average, whatever sigma each step
    states; the mean of these per-step ratios is judged (not the ratio of the sums, which
    one step stating a huge sigma, its odometry lost, made that step's alone), each ratio
    counted at most 1: uncapped, one step stating a tiny sigma (a 'hard' g2o edge of huge
    information) raised the mean past the limit and hid sigmas in centimetres on every
    other step. Capped, a step of Gaussian noise alone averages 0.70 (``min(|d + n|, c)``
    is at least ``min(|n|, c)`` in distribution for symmetric unimodal noise, so motion
    only raises it), a whole stream at most 1; the numbers that follow are the uncapped
    means h55 measured (capped, each is its minimum with 1 or less). Simulated
    streams average 0.99 to 1010 times the bound (translation and turn, noise scales 0.01 to
    34.6), the shipped recordings imported as the README does 3.1 to 73 times it, and with
    other keyframes (0.001 m / 0.001 rad, turns only; MRCLAM6 robot 3 uncalibrated) down to
    1.04. Odometry moving on average less than :data:`MIN_MOTION_PER_NOISE` of the
    bound, over at least :data:`MIN_SCALE_STEPS` steps, contradicts its stated sigmas:
    centimetres for metres or degrees for radians, most likely. A step whose translation (or
    turn) reads exactly 0 is not judged for it (a robot standing still: noise never reads
    exactly 0, and nothing says what it would be), nor one stating a sigma of 0; so a stream
    that never moves (or never turns) is not judged.

    Turns are also judged by their stated sigmas alone, as the header's are
    (:func:`header_problems`): a step's own turn sigma may be above pi/sqrt(3) (a 'turn
    unknown', :data:`MAX_STEP_ODOMETRY_SIGMA`), but when more than half the odometry steps
    state one, it is the stream's turn sigma, and a sigma in degrees, most likely (as the
    header's). Their turns cannot tell: on a turning robot, turn sigmas in degrees are 57
    times the noise but only some 6 to 10 times the turns (the simulator's robot turns about
    10 of its sigmas a step: 3 or 5 written for degrees averaged 0.11 to 0.19 of the bound,
    above the tenth), as a g2o file stating every edge's rotation 'unknown' (0.185), which
    this now warns of too. A step's above a full turn is :func:`step_problem`'s, not counted."""

    def __init__(self, odometry_sigma: tuple[float, float, float]) -> None:
        self._header = odometry_sigma
        self.n = 0
        self.own_sigma = False   # some step states its own odom_sigma
        self._moved = self._turned = 0.0            # the sums, for the message
        self._n_move = self._n_turn = 0             # the steps judged
        self._move_ratio = self._turn_ratio = 0.0   # sums of min(motion / bound, 1)
        self._move_noise = self._turn_noise = 0.0   # sums of sigma
        self._n_unknown = 0                         # steps' own turn sigmas above pi/sqrt(3),
        self._unknown_span = (math.inf, -math.inf)  # and their least and greatest
        self._own_line: int | None = None           # the lines of the first step stating its
        self._unknown_line: int | None = None       # own sigma, and one above pi/sqrt(3)

    def add(self, step: Step, line: int | None = None) -> None:
        """Count ``step`` (read from ``line`` of the file, if given: :meth:`problems` names
        it); a step without odometry (t = 0) is not judged, nor is its ``odom_sigma``."""
        if step.odom is None:
            return
        sigma = self._header if step.odom_sigma is None else step.odom_sigma
        if step.odom_sigma is not None and not self.own_sigma:
            self.own_sigma, self._own_line = True, line
        self.n += 1
        if step.odom_sigma is not None and \
                MAX_ODOMETRY_SIGMA[2] < float(sigma[2]) <= MAX_STEP_ODOMETRY_SIGMA[2]:
            lo, hi = self._unknown_span
            if not self._n_unknown:
                self._unknown_line = line
            self._n_unknown += 1
            self._unknown_span = (min(lo, float(sigma[2])), max(hi, float(sigma[2])))
        moved = math.hypot(float(step.odom[0]), float(step.odom[1]))
        noise = max(float(sigma[0]), float(sigma[1]))
        if moved and noise:
            self._n_move += 1
            self._moved += moved
            self._move_noise += noise
            self._move_ratio += min(moved / (_K * noise), 1.0)
        turned, turn_noise = abs(float(step.odom[2])), float(sigma[2])
        if turned and turn_noise:
            self._n_turn += 1
            self._turned += turned
            self._turn_noise += turn_noise
            self._turn_ratio += min(turned / (_K * turn_noise), 1.0)

    def problem(self) -> tuple[str, str] | None:
        """The first of :meth:`problems` as ``(key, message)``, else None."""
        out = self.problems()
        return out[0][:2] if out else None

    def problems(self) -> list[tuple[str, str, int | None]]:
        """``(key, message, line)`` for each way the odometry contradicts its stated sigmas
        (the translations', the turns'), and if most steps state a turn sigma above
        pi/sqrt(3) (then the turns are not judged again: one warning of degrees); empty if
        none. The key is ``odom_sigma`` if a step states its own, else ``odometry_sigma``;
        ``line`` is the one given to :meth:`add` with the first step stating a turn sigma
        above pi/sqrt(3) (for that count), else with the first stating its own sigma (None:
        not given, or the header's sigmas)."""
        k = _K
        key = "odom_sigma" if self.own_sigma else "odometry_sigma"
        out: list[tuple[str, str, int | None]] = []
        # no division; False without odometry, and as the scale checks below, not judged on
        # fewer than MIN_SCALE_STEPS steps (one step may state its turn unknown)
        unknown = 2 * self._n_unknown > self.n >= MIN_SCALE_STEPS
        if unknown:
            lo, hi = self._unknown_span
            span = f"{lo:g}" + (f" to {hi:g}" if hi > lo else "")
            out.append((key, f"{self._n_unknown} of the {self.n} steps state a turn sigma above "
                             f"pi/sqrt(3) = {MAX_ODOMETRY_SIGMA[2]:.3g} rad ({span}), the "
                             f"spread of a heading uniform on the circle: a step may state its "
                             f"turn unknown, but most steps doing so leave the odometry no "
                             f"turn; sigmas in degrees? (or, if the turns are truly unknown, "
                             f"as a g2o file's weak rotation information, nothing to fix)",
                        self._unknown_line))
        for what, n, done, noise, ratio, unit, other in (
                ("move", self._n_move, self._moved, self._move_noise, self._move_ratio, "m",
                 "centimetres"),
                ("turn", self._n_turn, self._turned, self._turn_noise, self._turn_ratio,
                 "rad", "degrees")):
            if n < MIN_SCALE_STEPS or (what == "turn" and unknown):
                continue
            if ratio / n < MIN_MOTION_PER_NOISE:
                out.append((key, f"the {n} steps {what} {done / n:.3g} {unit} on average, "
                                 f"{ratio / n:.2g} of what noise of their stated sigmas alone "
                                 f"would {what} them (sqrt(2/pi) sigma, {k * noise / n:.3g} "
                                 f"{unit} on average, or more): sigmas in {other}? (or "
                                 f"noise-free odometry with nominal sigmas)", self._own_line))
        return out


class PriorLandmarks:
    """The landmarks a stream's priors name that no step observes. Valid (the simulator
    draws Exp. 3's priors over every landmark, seen in a short run or not), but only a method
    mapping landmarks from priors alone uses such a prior; priors numbered apart from the
    bearings (an offset, a dataset's other ids) were all of them, and every method ran as
    without priors, silently. Judged by the reader after the last step, as
    :class:`OdometryScale`: a warning."""

    def __init__(self, priors: Sequence[Prior]) -> None:
        self._priors = tuple(priors)
        self._unseen = {p.i for p in priors} | {p.j for p in priors}

    def add(self, step: Step) -> None:
        if self._unseen and step.landmark_ids.size:
            self._unseen.difference_update(step.landmark_ids.tolist())

    def problem(self) -> tuple[str, str] | None:
        """``("priors", message)`` naming the unobserved landmarks (the first 5) and how many
        priors name one, else None."""
        if not self._unseen:
            return None
        ids = sorted(self._unseen)
        n = sum(p.i in self._unseen or p.j in self._unseen for p in self._priors)
        more = f", ... ({len(ids)} landmarks)" if len(ids) > 5 else ""
        return ("priors", f"{n} of the {len(self._priors)} priors name a landmark no step "
                          f"observes (id{'s' * (len(ids) > 1)} {', '.join(map(str, ids[:5]))}{more}): only a "
                          f"method mapping landmarks from priors alone (stmds-*, option "
                          f"map_unobserved) uses those, the others ignore them (landmark "
                          f"ids numbered other than the bearings'?)")


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
                       poses: np.ndarray | None = None, odom_lines: Sequence[int] = (),
                       priors_line: int | None = None) -> None:
    """Raise ``error`` naming the first implausible value of a stream being made by
    ``source`` (an importer, the simulator): the header's sigmas and range, each step's
    odometry, the truth's coordinates. Where the importer says where a value was read
    (``odom_lines[t - 1]``: the line of step ``t``'s odometry record; ``priors_line``: of the
    priors), the message names that line of ``source``."""
    problems = header_problems(header)
    if problems:
        key, msg = problems[0]
        at = f", line {priors_line}" if priors_line and key.startswith("priors") else ""
        raise error(f"{source}{at}: '{key}': {msg}; refusing to write an implausible stream")
    for st in steps:
        # a turn is not judged here: importers compute turns from their data or read them
        # from a format that wraps angles (g2o), so one beyond 2 pi is valid there (whatever
        # sigma the step states: an infinite header sigma did not stop a step's own)
        p = step_problem(st, turn=False)
        if p is not None:
            at = f", line {odom_lines[st.t - 1]}" if 0 < st.t <= len(odom_lines) else ""
            raise error(f"{source}{at}: '{p[0]}': {p[1]}; refusing to write an implausible "
                        f"stream")
    msg = truth_problem(np.zeros((0, 2)) if landmarks_xy is None else landmarks_xy, poses)
    if msg is not None:
        raise error(f"{source}: {msg}; refusing to write an implausible stream")


__all__ = ["MAX_ANGLE_SIGMA_RAD", "MAX_BEARING_SIGMA_RAD", "MAX_ODOMETRY_SIGMA",
           "MAX_STEP_ODOMETRY_SIGMA",
           "MIN_MOTION_PER_NOISE", "MIN_SCALE_STEPS", "TURN_SIGMAS", "SENSOR_RANGE_LIMITS_M",
           "PRIOR_SIGMA_LIMITS_M",
           "MAX_STEP_M", "MAX_COORDINATE_M", "MAX_ABS_ANGLE_RAD", "OdometryScale",
           "PriorLandmarks", "header_problems",
           "bearings_problem", "step_problem", "truth_problem", "refuse_implausible"]
