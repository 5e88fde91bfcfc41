"""The bomgraph measurement stream as data: Stream, StreamHeader, Step, Truth, Prior.

The data classes validate what they hold (``shared/STREAM_FORMAT.md``, format version 1), so
nothing can build a stream the reader would refuse; reading and writing the JSON Lines file is
:mod:`bomgraph.stream_file`. A refusal raises :class:`~bomgraph.errors.StreamFormatError`
naming the key.

Ground truth travels in :class:`Truth`, apart from :class:`StreamHeader`, so a mapper that is
handed the header and the steps cannot read it by accident.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping

import numpy as np

from .angles import wrap_angle
from .checks import finite_or_none, id_array, is_integer, real, row_array
from .errors import StreamFormatError
from .jsonio import jsonable



def _frozen(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class Prior:
    """A known distance between landmarks ``i`` and ``j`` (metres, with its std. dev.)."""

    i: int
    j: int
    distance_m: float
    sigma_m: float


@dataclass(frozen=True)
class StreamHeader:
    """Everything a mapper may know about a run before the first step (no ground truth).

    Attributes
    ----------
    bearing_sigma_rad : float
        Standard deviation of one bearing measurement, > 0.
    odometry_sigma : tuple of 3 floats
        ``(sigma_dx_m, sigma_dy_m, sigma_dpsi_rad)`` of an odometry increment, each >= 0.
    sensor_range_m : float or None
        Maximum range at which landmarks are observed, if known.
    priors : tuple of Prior
        Known inter-landmark distances.
    meta : mapping
        Free-form information (generator, seed, source, licence, ...).
    """

    bearing_sigma_rad: float
    odometry_sigma: tuple[float, float, float]
    sensor_range_m: float | None = None
    priors: tuple[Prior, ...] = ()
    meta: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        sigma = real(self.bearing_sigma_rad, "bearing_sigma_rad", StreamFormatError)
        if not (math.isfinite(sigma) and sigma > 0):
            raise StreamFormatError("must be a finite number > 0", key="bearing_sigma_rad")
        try:
            sig = tuple(real(s, "odometry_sigma", StreamFormatError)
                        for s in self.odometry_sigma)
        except (TypeError, StreamFormatError):
            sig = ()
        if len(sig) != 3 or not all(math.isfinite(s) and s >= 0 for s in sig):
            raise StreamFormatError(f"must be 3 finite numbers >= 0 (sigma_dx_m, sigma_dy_m, "
                                    f"sigma_dpsi_rad), got {self.odometry_sigma!r:.60}",
                                    key="odometry_sigma")
        object.__setattr__(self, "odometry_sigma", sig)
        if self.sensor_range_m is not None and not (math.isfinite(
                real(self.sensor_range_m, "sensor_range_m", StreamFormatError))
                                                    and self.sensor_range_m > 0):
            raise StreamFormatError("must be a finite number > 0 or None", key="sensor_range_m")
        try:
            priors = tuple(self.priors)
        except TypeError:
            priors = (self.priors,)
        for k, p in enumerate(priors):
            if not isinstance(p, Prior):
                raise StreamFormatError(f"must be a Prior(i, j, distance_m, sigma_m), got "
                                        f"{type(p).__name__} {p!r:.40}", key=f"priors[{k}]")
            if not (is_integer(p.i) and is_integer(p.j)):
                raise StreamFormatError(f"landmark ids must be integers, got {p.i!r} and "
                                        f"{p.j!r}", key=f"priors[{k}]")
            for name in ("distance_m", "sigma_m"):
                real(getattr(p, name), f"priors[{k}].{name}", StreamFormatError)
            if p.i == p.j or min(p.i, p.j) < 0:
                raise StreamFormatError(f"prior joins landmarks {p.i} and {p.j}; need two "
                                        f"different non-negative ids", key=f"priors[{k}]")
            if not (math.isfinite(p.distance_m) and p.distance_m > 0
                    and math.isfinite(p.sigma_m) and p.sigma_m > 0):
                raise StreamFormatError("distance_m and sigma_m must be finite and > 0",
                                        key=f"priors[{k}]")
        object.__setattr__(self, "priors", priors)
        try:  # meta must survive the file: normalise it to what JSON gives back
            meta = json.loads(json.dumps(jsonable(dict(self.meta), strict=True),
                                         allow_nan=False))
        except (TypeError, ValueError) as exc:
            raise StreamFormatError(f"must be JSON-serialisable with finite numbers ({exc})",
                                    key="meta") from None
        except RecursionError:  # Python 3.13's json parses what this cannot walk
            raise StreamFormatError("is nested too deeply (keep meta a few levels deep)",
                                    key="meta") from None
        object.__setattr__(self, "meta", meta)


@dataclass(frozen=True, eq=False)
class Step:
    """One time step: the odometry since the previous pose and the bearings taken here.

    Attributes
    ----------
    t : int
        Step index, 0 for the first step.
    odom : ndarray of shape (3,) or None
        ``[dx_m, dy_m, dpsi_rad]``, the motion from pose ``t-1`` to pose ``t`` in the frame of
        pose ``t-1``; None at ``t = 0``.
    landmark_ids : ndarray of shape (k,), int64
        Ids of the landmarks observed, unique within the step.
    bearings_rad : ndarray of shape (k,)
        Bearings relative to the robot heading, wrapped to (-pi, pi].
    odom_sigma : ndarray of shape (3,) or None
        Per-step override of the header's ``odometry_sigma``.
    time_s : float or None
        Time stamp.
    """

    t: int
    odom: np.ndarray | None
    landmark_ids: np.ndarray
    bearings_rad: np.ndarray
    odom_sigma: np.ndarray | None = None
    time_s: float | None = None

    def __post_init__(self) -> None:
        if not (is_integer(self.t) and self.t >= 0):
            raise StreamFormatError(f"must be the step index, an integer >= 0, got "
                                    f"{self.t!r:.40}", key="t")
        ids = _frozen(id_array(self.landmark_ids, f"step {self.t}: landmark_ids",
                               lambda m: StreamFormatError(m, key="bearings")))
        try:
            raw = np.asarray(self.bearings_rad, dtype=float)
        except (TypeError, ValueError):
            raise StreamFormatError(f"step {self.t}: bearings_rad must be numbers, got "
                                    f"{self.bearings_rad!r:.40}", key="bearings") from None
        brg = _frozen(np.array(wrap_angle(raw), dtype=float).reshape(-1))
        if ids.shape != brg.shape:
            raise StreamFormatError(f"step {self.t}: {ids.size} landmark ids but "
                                    f"{brg.size} bearings", key="bearings")
        if not np.all(np.isfinite(brg)):
            raise StreamFormatError(f"step {self.t}: bearings must be finite", key="bearings")
        if np.any(ids < 0) or len(np.unique(ids)) != len(ids):
            raise StreamFormatError(f"step {self.t}: landmark ids must be non-negative and "
                                    f"unique within a step", key="bearings")
        object.__setattr__(self, "landmark_ids", ids)
        object.__setattr__(self, "bearings_rad", brg)
        for key in ("odom", "odom_sigma"):
            v = getattr(self, key)
            if v is None:
                continue
            try:
                arr = np.array(v, dtype=float).reshape(-1)
            except (TypeError, ValueError):
                arr = np.zeros(0)
            if arr.shape != (3,) or not np.all(np.isfinite(arr)):
                raise StreamFormatError(f"step {self.t}: must be 3 finite numbers", key=key)
            if key == "odom_sigma" and np.any(arr < 0):
                raise StreamFormatError(f"step {self.t}: sigmas must be >= 0", key=key)
            object.__setattr__(self, key, _frozen(arr))
        finite_or_none(self.time_s, f"step {self.t}: time_s",
                       lambda m: StreamFormatError(m, key="time_s"))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Step):
            return NotImplemented
        return (self.t == other.t and self.time_s == other.time_s
                and _opt_equal(self.odom, other.odom)
                and _opt_equal(self.odom_sigma, other.odom_sigma)
                and np.array_equal(self.landmark_ids, other.landmark_ids)
                and np.array_equal(self.bearings_rad, other.bearings_rad))

    __hash__ = None  # type: ignore[assignment]

    def odometry_sigma(self, header: StreamHeader) -> np.ndarray:
        """The std. dev. of this step's odometry components: the override, else the header's."""
        if self.odom_sigma is not None:
            return self.odom_sigma
        return np.asarray(header.odometry_sigma, dtype=float)


@dataclass(frozen=True, eq=False)
class Truth:
    """Ground truth of a run, for evaluation only.

    Attributes
    ----------
    landmark_ids : ndarray of shape (n,)
    landmarks_xy : ndarray of shape (n, 2)
    poses : ndarray of shape (T, 3) or None
        ``[x_m, y_m, psi_rad]`` per step, index = ``t``; None when only the map is known.
    """

    landmark_ids: np.ndarray
    landmarks_xy: np.ndarray
    poses: np.ndarray | None = None

    def __post_init__(self) -> None:
        def bad(message: str) -> StreamFormatError:
            return StreamFormatError(message, key="truth.landmarks")

        ids = _frozen(id_array(self.landmark_ids, "landmark_ids", bad))
        xy = _frozen(row_array(self.landmarks_xy, 2, "landmarks_xy", bad))
        if ids.shape[0] != xy.shape[0]:
            raise StreamFormatError("landmark ids and positions differ in number",
                                    key="truth")
        if len(np.unique(ids)) != len(ids) or np.any(ids < 0):
            raise StreamFormatError("landmark ids must be unique and non-negative",
                                    key="truth.landmarks")
        if not np.all(np.isfinite(xy)):
            raise StreamFormatError("landmark positions must be finite", key="truth.landmarks")
        object.__setattr__(self, "landmark_ids", ids)
        object.__setattr__(self, "landmarks_xy", xy)
        if self.poses is not None:
            poses = row_array(self.poses, 3, "poses",
                              lambda m: StreamFormatError(m, key="truth.poses"))
            if not np.all(np.isfinite(poses)):
                raise StreamFormatError("poses must be finite", key="truth.poses")
            object.__setattr__(self, "poses", _frozen(poses))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Truth):
            return NotImplemented
        return (np.array_equal(self.landmark_ids, other.landmark_ids)
                and np.array_equal(self.landmarks_xy, other.landmarks_xy)
                and _opt_equal(self.poses, other.poses))

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True, eq=False)
class Stream:
    """One robot run: the header, the steps and (apart) the ground truth if known."""

    header: StreamHeader
    steps: tuple[Step, ...]
    truth: Truth | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.header, StreamHeader):
            raise StreamFormatError(f"must be a StreamHeader, got {type(self.header).__name__}",
                                    key="header")
        if self.truth is not None and not isinstance(self.truth, Truth):
            raise StreamFormatError(f"must be a Truth or None, got {type(self.truth).__name__}",
                                    key="truth")
        if isinstance(self.steps, Step) or not isinstance(self.steps, Iterable):
            raise StreamFormatError(f"must be a sequence of Step, got "
                                    f"{type(self.steps).__name__}", key="steps")
        object.__setattr__(self, "steps", tuple(self.steps))
        if not self.steps:
            raise StreamFormatError("a stream needs at least the step t = 0", key="t")
        for k, s in enumerate(self.steps):
            if not isinstance(s, Step):
                raise StreamFormatError(f"steps[{k}] is a {type(s).__name__}, not a Step",
                                        key="steps")
            if s.t != k:
                raise StreamFormatError(f"step {k} has t = {s.t}; steps must be 0, 1, 2, ...",
                                        key="t")
            if (s.odom is None) != (k == 0):
                raise StreamFormatError(f"step {k}: odom must be None at t = 0 and given after",
                                        key="odom")
        if self.truth is not None and self.truth.poses is not None \
                and len(self.truth.poses) != len(self.steps):
            raise StreamFormatError(f"{len(self.truth.poses)} truth poses for "
                                    f"{len(self.steps)} steps", key="truth")

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Stream):
            return NotImplemented
        return (self.header == other.header and self.steps == other.steps
                and self.truth == other.truth)

    __hash__ = None  # type: ignore[assignment]

    def __len__(self) -> int:
        return len(self.steps)

    def landmark_ids(self) -> np.ndarray:
        """All landmark ids observed in the run, sorted."""
        if not self.steps:
            return np.zeros(0, dtype=np.int64)
        return np.unique(np.concatenate([s.landmark_ids for s in self.steps]))


def _opt_equal(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return np.array_equal(a, b)


__all__ = ["Prior", "StreamHeader", "Step", "Truth", "Stream"]
