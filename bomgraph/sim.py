"""The paper's simulated world, robot and sensor (section IV-A), seeded and configurable.

Defaults reproduce the paper: a 2.5 m square with N = 50 uniformly placed landmarks, a 1 m
sensor range, 300 moves, sigma_l = 3 cm, sigma_phi = sigma_theta = 3 deg, move-then-turn motion.

Motion law (the paper gives none; see shared/paper/NOTES.md): each step the robot moves
``l ~ U(step_min_m, step_max_m)`` along its heading, then turns ``phi ~ U(-turn_max_rad,
turn_max_rad)``. If the point ``lookahead_m`` ahead along the new heading would lie closer than
``wall_margin_m`` to a wall, the turn is redrawn as the turn toward the arena centre plus a
``U(-turn_max_rad, turn_max_rad)`` perturbation (up to 8 draws, then exactly toward the centre).
Because ``lookahead_m >= step_max_m`` the next move always stays inside the arena.

Odometry is ``[l + n_l, 0, phi + n_phi]``; bearings are ``theta + n_theta`` wrapped, for the
landmarks in range ``[min_range_m, sensor_range_m]`` and inside the field of view. The noise
``n_theta`` is drawn for every landmark within ``sensor_range_m``, so ``min_range_m`` and
``fov_rad`` leave bearings out without changing the noise of the others.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from .angles import angle_residual, wrap_angle
from .checks import is_integer, row_array
from .config import requirement
from .errors import ConfigError
from .geometry import bearings_to
from .plausibility import (MAX_BEARING_SIGMA_RAD, MIN_BEARING_SIGMA_RAD, MAX_COORDINATE_M, MAX_ODOMETRY_SIGMA,
                           MAX_STEP_M, PRIOR_SIGMA_LIMITS_M, SENSOR_RANGE_LIMITS_M)
from .stream import Prior, Step, Stream, StreamHeader, Truth

DEG = math.pi / 180.0

#: the most moves one simulated run may have: its truth (one header line) then fills about
#: 60 MiB, near the readers' 64 MiB line limit (``bomgraph.stdio.MAX_LINE_BYTES``).
MAX_SIM_STEPS = 1_000_000
#: the most landmarks one simulated world may have (``bench_speed.py`` scales to 10,000).
MAX_SIM_LANDMARKS = 100_000
#: Exp. 3's priors are drawn from all landmark pairs (``np.triu_indices``): at most this many
#: pairs (n = 4,472 landmarks), and at most this many priors (one header line, about 35 MiB).
MAX_PRIOR_PAIRS = 10_000_000
MAX_PRIORS = 500_000


def _finite(v: float) -> bool:
    try:
        return math.isfinite(v)
    except OverflowError:  # an int beyond float range (`simulate --landmarks 10**400`)
        return False


@dataclass(frozen=True)
class SimConfig:
    """Parameters of the simulated world, robot and sensor; defaults are the paper's.

    ``noise_scale`` multiplies every noise draw and the sigmas written in the header;
    ``noise_scale = 0`` draws no noise and keeps the nominal sigmas in the header (a stream
    needs a positive bearing sigma), which gives the noise-free runs the tests use.
    """

    arena_m: float = 2.5
    n_landmarks: int = 50
    n_steps: int = 300
    sensor_range_m: float = 1.0
    min_range_m: float = 0.0
    fov_rad: float = 2.0 * math.pi
    sigma_l_m: float = 0.03
    sigma_phi_rad: float = 3.0 * DEG
    sigma_theta_rad: float = 3.0 * DEG
    noise_scale: float = 1.0
    step_min_m: float = 0.1
    step_max_m: float = 0.2
    turn_max_rad: float = 30.0 * DEG
    wall_margin_m: float = 0.05
    lookahead_m: float = 0.3
    start_margin_m: float = 0.25
    wrong_association_rate: float = 0.0

    def __post_init__(self) -> None:
        need = requirement("SimConfig")

        for f in self.__dataclass_fields__:
            v = getattr(self, f)
            need(isinstance(v, (int, float)) and _finite(v),
                 f"{f} must be a finite number, got {v!r}")
        for f in ("n_landmarks", "n_steps"):
            need(is_integer(getattr(self, f)), f"{f} must be an integer, got "
                                               f"{getattr(self, f)!r}")
        need(self.arena_m > 0, f"arena_m must be > 0, got {self.arena_m}")
        need(1 <= self.n_landmarks <= MAX_SIM_LANDMARKS,
             f"n_landmarks must be in [1, {MAX_SIM_LANDMARKS:,}], got {self.n_landmarks}")
        need(0 <= self.n_steps <= MAX_SIM_STEPS,
             f"n_steps must be in [0, {MAX_SIM_STEPS:,}], got {self.n_steps}")
        need(self.sensor_range_m > 0, f"sensor_range_m must be > 0, got {self.sensor_range_m}")
        need(0 <= self.min_range_m < self.sensor_range_m,
             "min_range_m must be in [0, sensor_range_m)")
        need(0 < self.fov_rad <= 2 * math.pi, "fov_rad must be in (0, 2 pi]")
        for name in ("sigma_l_m", "sigma_phi_rad", "sigma_theta_rad", "noise_scale"):
            need(getattr(self, name) >= 0, f"{name} must be >= 0")
        need(self.sigma_theta_rad > 0, "sigma_theta_rad must be > 0 (the header needs it)")
        need(0 < self.step_min_m <= self.step_max_m, "need 0 < step_min_m <= step_max_m")
        need(0 <= self.turn_max_rad <= math.pi, "turn_max_rad must be in [0, pi]")
        need(self.lookahead_m >= self.step_max_m,
             "lookahead_m must be >= step_max_m so the robot cannot leave the arena")
        need(2 * self.wall_margin_m < self.arena_m, "wall_margin_m too large for the arena")
        need(0 <= self.start_margin_m < self.arena_m / 2, "start_margin_m out of range")
        need(0 <= self.wrong_association_rate <= 1, "wrong_association_rate must be in [0, 1]")
        # plausibility (bomgraph.plausibility): valid numbers no method can use are refused
        sigma_theta, odo = self.header_sigmas()
        need(sigma_theta >= MIN_BEARING_SIGMA_RAD,
             f"the bearing sigma (sigma_theta_rad x noise_scale) is {sigma_theta:g} rad, "
             f"below {MIN_BEARING_SIGMA_RAD:g}: no sensor is that precise (for noise-free "
             f"data give noise_scale 0)")
        need(sigma_theta <= MAX_BEARING_SIGMA_RAD,
             f"noise_scale {self.noise_scale:g} gives a bearing sigma of {sigma_theta:g} rad, "
             f"above pi/sqrt(3) = {MAX_BEARING_SIGMA_RAD:.3g} rad, the spread of a bearing "
             f"uniform on the circle: no information (the paper's noise is 1)")
        need(all(v <= lim for v, lim in zip(odo, MAX_ODOMETRY_SIGMA)),
             f"noise_scale {self.noise_scale:g} gives odometry sigmas {odo}: no information")
        lo, hi = SENSOR_RANGE_LIMITS_M
        need(lo <= self.sensor_range_m <= hi,
             f"sensor_range_m must be in [{lo:g}, {hi:g}] m, got {self.sensor_range_m:g}")
        need(self.arena_m <= MAX_COORDINATE_M and self.step_max_m <= MAX_STEP_M,
             f"arena_m (<= {MAX_COORDINATE_M:g}) or step_max_m (<= {MAX_STEP_M:g}) too large")

    @property
    def noise_free(self) -> bool:
        return self.noise_scale == 0.0

    def header_sigmas(self) -> tuple[float, tuple[float, float, float]]:
        """The bearing and odometry sigmas written in the stream header."""
        k = self.noise_scale if self.noise_scale > 0 else 1.0
        return (k * self.sigma_theta_rad, (k * self.sigma_l_m, 0.0, k * self.sigma_phi_rad))


def random_landmarks(config: SimConfig, rng: np.random.Generator) -> np.ndarray:
    """``(n_landmarks, 2)`` positions, uniform in the arena."""
    return rng.uniform(0.0, config.arena_m, size=(config.n_landmarks, 2))


def _inside(xy: np.ndarray, config: SimConfig) -> bool:
    m = config.wall_margin_m
    return bool(np.all(xy >= m) and np.all(xy <= config.arena_m - m))


def _choose_turn(pose_xy: np.ndarray, psi: float, config: SimConfig,
                 rng: np.random.Generator) -> float:
    def ahead(turn: float) -> np.ndarray:
        h = psi + turn
        return pose_xy + config.lookahead_m * np.array([math.cos(h), math.sin(h)])

    phi = float(rng.uniform(-config.turn_max_rad, config.turn_max_rad))
    if _inside(ahead(phi), config):
        return phi
    centre = np.full(2, config.arena_m / 2)
    to_centre = float(angle_residual(math.atan2(*(centre - pose_xy)[::-1]), psi))
    for _ in range(8):
        phi = to_centre + float(rng.uniform(-config.turn_max_rad, config.turn_max_rad))
        if _inside(ahead(phi), config):
            return float(wrap_angle(phi))
    return to_centre


def simulate_truth(config: SimConfig, rng: np.random.Generator,
                   start_pose: Sequence[float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The true trajectory and the true (noise-free) motions.

    Returns
    -------
    poses : ndarray of shape (n_steps + 1, 3)
    motions : ndarray of shape (n_steps, 2)
        True ``(l_m, phi_rad)`` of each step (move ``l``, then turn ``phi``).
    """
    if start_pose is None:
        m = config.start_margin_m
        xy0 = rng.uniform(m, config.arena_m - m, size=2)
        psi0 = float(rng.uniform(-math.pi, math.pi))
    else:
        xy0 = np.asarray(start_pose[:2], dtype=float)
        if not (np.all(np.isfinite(start_pose)) and np.all(xy0 >= 0)
                and np.all(xy0 <= config.arena_m)):
            raise ConfigError(f"start_pose {tuple(start_pose)} must be finite and inside the "
                              f"{config.arena_m} m arena")
        psi0 = float(wrap_angle(start_pose[2]))
    poses = np.empty((config.n_steps + 1, 3))
    motions = np.empty((config.n_steps, 2))
    xy, psi = xy0.copy(), psi0
    # The first heading must also let the first move stay inside.
    psi = float(wrap_angle(psi + _choose_turn(xy, psi, config, rng))) if not _inside(
        xy + config.lookahead_m * np.array([math.cos(psi), math.sin(psi)]), config) else psi
    poses[0] = (xy[0], xy[1], psi)
    for t in range(config.n_steps):
        l = float(rng.uniform(config.step_min_m, config.step_max_m))
        xy = xy + l * np.array([math.cos(psi), math.sin(psi)])
        phi = _choose_turn(xy, psi, config, rng)
        psi = float(wrap_angle(psi + phi))
        poses[t + 1] = (xy[0], xy[1], psi)
        motions[t] = (l, phi)
    return poses, motions


def simulate(config: SimConfig, rng: np.random.Generator, *,
             landmarks_xy: np.ndarray | None = None,
             start_pose: Sequence[float] | None = None,
             meta: dict | None = None) -> Stream:
    """Simulate one run and return it as a Stream with truth.

    Parameters
    ----------
    config : SimConfig
    rng : numpy.random.Generator
        The only source of randomness; the same generator state gives the same stream.
    landmarks_xy : array of shape (N, 2), optional
        A fixed layout (the paper's design reuses each layout for 5 starts); drawn if None.
    start_pose : (x_m, y_m, psi_rad), optional
        Drawn uniformly (inside ``start_margin_m``) if None.
    meta : dict, optional
        Extra entries for the header's ``meta``.
    """
    if not isinstance(config, SimConfig):
        raise ConfigError(f"simulate(): config must be a SimConfig, got {type(config).__name__}")
    if not isinstance(rng, np.random.Generator):
        raise ConfigError(f"simulate(): rng must be a numpy.random.Generator "
                          f"(np.random.default_rng(seed)), got {type(rng).__name__}")
    if start_pose is not None and np.shape(start_pose) != (3,):
        raise ConfigError(f"simulate(): start_pose must be (x_m, y_m, psi_rad), got "
                          f"{start_pose!r:.60}")
    if landmarks_xy is None:
        landmarks_xy = random_landmarks(config, rng)
    landmarks_xy = row_array(landmarks_xy, 2, "simulate(): landmarks_xy", ConfigError,
                             copy=False)
    n = len(landmarks_xy)
    ids = np.arange(n, dtype=np.int64)
    poses, motions = simulate_truth(config, rng, start_pose)
    k = config.noise_scale
    steps = []
    for t in range(config.n_steps + 1):
        odom = None
        if t > 0:
            l, phi = motions[t - 1]
            odom = np.array([l + k * config.sigma_l_m * rng.standard_normal(), 0.0,
                             phi + k * config.sigma_phi_rad * rng.standard_normal()])
        pose = poses[t]
        d = np.hypot(*(landmarks_xy - pose[:2]).T)
        brg = bearings_to(pose, landmarks_xy)
        # noise is drawn for every landmark within sensor range, before the minimum range and
        # the field of view leave some out, so that those two settings change no other
        # bearing's noise (a stream with and without them pairs bearing for bearing)
        in_range = d <= config.sensor_range_m
        noise = k * config.sigma_theta_rad * rng.standard_normal(int(in_range.sum()))
        seen = (d[in_range] >= config.min_range_m) & (np.abs(brg[in_range]) <= config.fov_rad / 2)
        seen_ids = ids[in_range][seen]
        meas = wrap_angle(brg[in_range][seen] + noise[seen])
        if config.wrong_association_rate > 0 and seen_ids.size:
            seen_ids = _mislabel(seen_ids, n, config.wrong_association_rate, rng)
        steps.append(Step(t=t, odom=odom, landmark_ids=seen_ids, bearings_rad=meas))
    sigma_theta, odo_sigma = config.header_sigmas()
    info = {"generator": "bomgraph.sim", "motion": "move-then-turn",
            "noise_scale": config.noise_scale}
    info.update(meta or {})
    header = StreamHeader(bearing_sigma_rad=sigma_theta, odometry_sigma=odo_sigma,
                          sensor_range_m=config.sensor_range_m, meta=info)
    return Stream(header, tuple(steps), Truth(ids, landmarks_xy, poses))


def _mislabel(seen_ids: np.ndarray, n: int, rate: float,
              rng: np.random.Generator) -> np.ndarray:
    """Replace a fraction of ids by other landmarks' ids (never duplicating within the step)."""
    out = seen_ids.copy()
    wrong = rng.random(out.size) < rate
    for k in np.flatnonzero(wrong):
        free = np.setdiff1d(np.arange(n), out)
        if free.size:
            out[k] = rng.choice(free)
    return out


# --------------------------------------------------------------------------------------------
# The paper's 25-run design and the Exp. 3 priors
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class RunSpec:
    """One run of an experiment design: layout ``layout`` and start ``start`` from ``seed``."""

    seed: int
    layout: int
    start: int

    def layout_rng(self) -> np.random.Generator:
        return np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(self.layout,)))

    def run_rng(self) -> np.random.Generator:
        return np.random.default_rng(
            np.random.SeedSequence(self.seed, spawn_key=(self.layout, self.start)))

    def prior_rng(self) -> np.random.Generator:
        return np.random.default_rng(
            np.random.SeedSequence(self.seed, spawn_key=(self.layout, self.start, 1)))

    @property
    def name(self) -> str:
        return f"s{self.seed}-l{self.layout}-r{self.start}"


def paper_design(seed: int = 0, n_layouts: int = 5, n_starts: int = 5) -> list[RunSpec]:
    """The paper's 25 runs: ``n_layouts`` landmark layouts times ``n_starts`` start poses."""
    if n_layouts < 1 or n_starts < 1:
        raise ConfigError("n_layouts and n_starts must be >= 1")
    return [RunSpec(seed, a, b) for a in range(n_layouts) for b in range(n_starts)]


def simulate_run(spec: RunSpec, config: SimConfig = SimConfig(), *,
                 prior_fraction: float = 0.0, prior_sigma_xy_m: float = 0.03) -> Stream:
    """Simulate one run of a design; the same spec and config always give the same stream.

    With ``prior_fraction > 0`` the header carries Exp. 3 priors (:func:`make_priors`).
    """
    layout = random_landmarks(config, spec.layout_rng())
    stream = simulate(config, spec.run_rng(), landmarks_xy=layout,
                      meta={"seed": spec.seed, "layout": spec.layout, "start": spec.start})
    if prior_fraction > 0:
        stream = with_priors(stream, make_priors(stream.truth, prior_fraction,
                                                 prior_sigma_xy_m, spec.prior_rng()))
    return stream


def n_prior_pairs(n_landmarks: int, fraction: float) -> int:
    """``fraction`` of all pairs, rounded half up (10% of 1225 pairs is 123, as in the paper)."""
    return int(math.floor(fraction * n_landmarks * (n_landmarks - 1) / 2 + 0.5))


def make_priors(truth: Truth, fraction: float, sigma_xy_m: float,
                rng: np.random.Generator) -> tuple[Prior, ...]:
    """Exp. 3 priors: a random ``fraction`` of all landmark pairs with noisy known distances.

    Each chosen pair's relative offset is known with independent Gaussian noise of std.
    ``sigma_xy_m`` in x and in y (the paper's 3 cm); the prior is the length of the noisy
    offset, with ``sigma_m = sigma_xy_m`` (the first-order std. dev. of that length).
    """
    if not (math.isfinite(fraction) and 0 < fraction <= 1):
        raise ConfigError(f"prior fraction must be in (0, 1], got {fraction}")
    lo, hi = PRIOR_SIGMA_LIMITS_M
    if not (math.isfinite(sigma_xy_m) and lo <= sigma_xy_m <= hi):
        raise ConfigError(f"prior sigma must be in [{lo:g}, {hi:g}] m (the paper's is 0.03; "
                          f"bomgraph.plausibility), got {sigma_xy_m:g}")
    n = len(truth.landmark_ids)
    if n * (n - 1) // 2 > MAX_PRIOR_PAIRS or n_prior_pairs(n, fraction) > MAX_PRIORS:
        raise ConfigError(f"priors for {n:,} landmarks: {n * (n - 1) // 2:,} pairs to draw "
                          f"{n_prior_pairs(n, fraction):,} priors from; at most "
                          f"{MAX_PRIOR_PAIRS:,} pairs and {MAX_PRIORS:,} priors (fewer "
                          f"landmarks or a smaller fraction)")
    iu, ju = np.triu_indices(n, 1)
    pick = np.sort(rng.choice(iu.size, size=n_prior_pairs(n, fraction), replace=False))
    a, b = iu[pick], ju[pick]
    offset = truth.landmarks_xy[b] - truth.landmarks_xy[a]
    offset = offset + sigma_xy_m * rng.standard_normal(offset.shape)
    dist = np.hypot(offset[:, 0], offset[:, 1])
    return tuple(Prior(int(truth.landmark_ids[i]), int(truth.landmark_ids[j]), float(d),
                       float(sigma_xy_m)) for i, j, d in zip(a, b, dist))


def with_priors(stream: Stream, priors: Sequence[Prior]) -> Stream:
    """A copy of ``stream`` whose header carries ``priors``."""
    return Stream(replace(stream.header, priors=tuple(priors)), stream.steps, stream.truth)
