"""The values of a valid stream no method can compute with, refused alike by every method that
meets them (STMDS, the EKFs, the GTSAM graphs, ``triangulate``; the exceptions are listed) as
:class:`StreamValueError`: the refusal names the step ``t`` and the field, and ``bomgraph run``
and ``compare`` name the file and the line (:func:`bomgraph.stream_file.located`), as for the
reader's refusals.

The reader only warns about such values (:mod:`bomgraph.plausibility`: the file is valid);
a method that cannot use one refuses it at its line, rather than failing later at another
step or returning a map from numbers it could not represent.

* **Distance from the map origin** beyond :data:`~bomgraph.plausibility.MAX_COORDINATE_M`
  (1e9 m): :class:`Reach` dead-reckons the stream's odometry from ``start_pose`` and refuses
  the step whose move carries the robot beyond it (and a ``start_pose`` beyond it, as an
  option, :func:`checked_start_pose`). Measured (h151, ``docs/measurements.md``): with the
  whole run moved to ``start_pose = (X, X, 0)`` every GTSAM method reproduces the map, cost
  and convergence of the run at the origin up to X = 1e10 m; at 2e10 m ``gtsam-isam2`` and
  ``hybrid-isam2`` no longer converge (cost +0.8 of 531.5), at 1e11 m the oracle's error
  moves by 4 %, at 1e16 m no landmark enters any graph; ``ekf-invdepth`` moves by 1 % at
  1e9 m. 1e9 m keeps every method a decade inside what it computes correctly. STMDS has no
  ``start_pose`` and no :class:`Reach`: it bounds each move instead (its squared distances),
  as its maps do not depend on the distance from the origin (h158: a 300-step run driven
  first 1.2e9 m, or 3e9 m, out gave the MPE of the run driven 2 m, or 5 m, out, to 1e-3 cm);
  ``triangulate``'s maps do not either (the same to 1e-3 cm up to 1e11 m), it holds the
  shared bound for one map frame across methods.
* A method checks only the sigmas it uses: ``triangulate`` none.
* **A factory's own options**, before any run (:func:`check_factory_options`, called by
  :func:`bomgraph.mapper.check_method_options`): ``start_pose``, a mapper object.
* **Known distances** beyond it, or with a sigma above :data:`MAX_SIGMA` (:func:`check_priors`).
* **Sigmas** above :data:`MAX_SIGMA` (:func:`check_sigmas`), a bearing sigma outside
  ``(0, pi]`` (:func:`check_bearing_sigma`; STMDS too, h161: it weights its distances,
  bundle and localisation by it, and had taken one of 4 rad with the reader's warning only).
"""

from __future__ import annotations

import math
import types
import typing
from collections import abc
from numbers import Real
from typing import Any, Callable, Mapping

import numpy as np

from .angles import wrap_angle
from .errors import ConfigError, StreamValueError
from .plausibility import MAX_COORDINATE_M
from .stream import Step, StreamHeader

#: Largest std. dev. (metres or radians) a method accepts in a header or a step: beyond it no
#: measurement carries information and the variances (fourth powers in STMDS) leave double
#: precision; an EKF's covariance overflows some steps later, at another step's line.
MAX_SIGMA = 1e6


def shown_beyond(value: float, bound: float) -> str:
    """``value``, beyond ``bound``, with the digits (6 at least) that set it apart from it:
    "1e+09 m, beyond 1e+09 m" said nothing (h161), nor "3.14159 rad: it must be in (0, pi]"
    of a bearing sigma of 3.1415927 (h167)."""
    return next((f"{value:.{k}g}" for k in range(6, 18) if float(f"{value:.{k}g}") > bound),
                repr(value))


def check_sigmas(values: Any, t: int | None, key: str, method: str,
                 max_sigma: float = MAX_SIGMA) -> None:
    """Refuse sigmas above ``max_sigma`` (or non-finite) of step ``t`` (None: the header)
    under ``key``, with a message naming ``method`` and them."""
    arr = np.asarray(values, float).reshape(-1)
    if not np.all(np.isfinite(arr)) or np.any(np.abs(arr) > max_sigma):
        raise StreamValueError(
            f"{method} cannot use {arr.tolist() if arr.size > 1 else float(arr[0])!r}: "
            f"a std. dev. above {max_sigma:g} (m or rad) carries no information and overflows "
            f"the variance arithmetic; fix the stream's sigmas", t=t, key=key, method=method)


def check_bearing_sigma(header: StreamHeader, method: str) -> StreamHeader:
    """``header``, refused if its ``bearing_sigma_rad`` is outside ``(0, pi]`` (the reader
    accepts one above pi with a warning; a larger sigma carries no information: a filter's
    update and a graph's bearing factors have no weight, and a graph maps nothing)."""
    sigma = header.bearing_sigma_rad
    if not (math.isfinite(sigma) and 0 < sigma <= math.pi):
        raise StreamValueError(
            f"{method} cannot use a bearing std. dev. of {shown_beyond(sigma, math.pi)} rad: it "
            f"must be in (0, pi] (a larger sigma carries no information); fix the stream's "
            f"bearing_sigma_rad",
            t=None, key="bearing_sigma_rad", method=method)
    return header


def check_priors(header: StreamHeader, method: str) -> None:
    """Refuse a known distance (``priors[k]``) beyond
    :data:`~bomgraph.plausibility.MAX_COORDINATE_M` or with a sigma above :data:`MAX_SIGMA`
    (h151: STMDS's squared distances overflowed, and it blamed its own distance matrix)."""
    for k, p in enumerate(header.priors):
        if not p.distance_m <= MAX_COORDINATE_M:
            raise StreamValueError(
                f"{method} cannot use a known distance of {p.distance_m:g} m, beyond "
                f"{MAX_COORDINATE_M:g} m (squared, it leaves double precision); fix the "
                f"stream's priors", t=None, key=f"priors[{k}].distance_m", method=method)
        check_sigmas(p.sigma_m, None, f"priors[{k}].sigma_m", method)


def checked_header(header: StreamHeader, method: str,
                   max_sigma: float = MAX_SIGMA) -> StreamHeader:
    """``header``, refused if ``method`` (a filter, a graph) cannot use its sigmas: its
    odometry sigmas above ``max_sigma`` (:func:`check_sigmas`), its bearing sigma outside
    ``(0, pi]`` (:func:`check_bearing_sigma`), a known distance (:func:`check_priors`)."""
    check_sigmas(header.odometry_sigma, None, "odometry_sigma", method, max_sigma)
    check_priors(header, method)
    return check_bearing_sigma(header, method)


def check_distance(distance_m: float, t: int, method: str, what: str,
                   fix: str = "the stream's odometry") -> None:
    """Refuse (``'odom'`` of step ``t``) a distance of ``distance_m`` metres beyond
    :data:`~bomgraph.plausibility.MAX_COORDINATE_M`: "``method`` cannot use ``what``
    ``distance_m`` m, beyond ...; fix ``fix``" (the distance shown by :func:`shown_beyond`)."""
    if not distance_m <= MAX_COORDINATE_M:
        raise StreamValueError(
            f"{method} cannot use {what} {shown_beyond(distance_m, MAX_COORDINATE_M)} m, "
            f"beyond {MAX_COORDINATE_M:g} m (coordinates that far lose the precision the "
            f"measurements need); fix {fix}",
            t=t, key="odom", method=method)


def checked_start_pose(value: Any, option: str = "start_pose") -> np.ndarray:
    """``value`` as a pose ``(x_m, y_m, psi_rad)``, shape (3,), refused as
    :class:`ConfigError` naming ``option`` unless it is three finite numbers with ``x`` and
    ``y`` within :data:`~bomgraph.plausibility.MAX_COORDINATE_M` of the origin."""
    items = list(value) if isinstance(value, (list, tuple, np.ndarray)) else None
    if items is None or len(items) != 3 or not all(
            isinstance(v, Real) and not isinstance(v, bool) for v in items):
        raise ConfigError(f"option {option}: must be [x_m, y_m, psi_rad] (three numbers), "
                          f"got {value!r:.80}")
    pose = np.array([float(v) for v in items])
    if not (np.all(np.isfinite(pose)) and math.hypot(pose[0], pose[1]) <= MAX_COORDINATE_M):
        raise ConfigError(f"option {option}: {pose.tolist()} must be finite, with x and y "
                          f"within {MAX_COORDINATE_M:g} m of the origin")
    return pose


def check_mapper_option(option: str, value: Any) -> None:
    """Refuse, as :class:`ConfigError` naming ``option``, a ``value`` that is neither None
    nor a mapper (an object with ``step`` and ``estimate`` methods): e.g. a hybrid's
    ``seed_mapper=5`` from ``--option``, which failed every run at its first step."""
    if value is None or (not isinstance(value, type) and callable(getattr(value, "step", None))
                         and callable(getattr(value, "estimate", None))):
        return
    raise ConfigError(f"option {option}: must be a mapper object (with step() and estimate(), "
                      f"built in Python), got {type(value).__name__} {value!r:.40}; the "
                      f"command line and sweep files name a method instead (seed_method)")


def _pose_parameter(hint: Any, param: Any) -> bool:
    """Whether a factory's ``start_pose`` parameter (``param``, annotated ``hint``) is a pose
    as the built-in methods' is: annotated as a sequence or an array (``Optional`` too), or
    unannotated with no default, None or three items. A plugin's ``start_pose: int`` (the
    index of an anchor step, say) is its own (h158: it was refused as "must be [x_m, y_m,
    psi_rad]" before any run)."""
    if hint is None or hint is Any:
        default = getattr(param, "default", None)
        return (default is None or default is getattr(param, "empty", None)
                or (isinstance(default, (list, tuple, np.ndarray)) and len(default) == 3))
    union = typing.get_origin(hint) in (typing.Union, types.UnionType)
    args = typing.get_args(hint) if union else (hint,)
    return any(a is np.ndarray or a in (list, tuple) or typing.get_origin(a) in (
        list, tuple, np.ndarray, abc.Sequence) for a in args)


def check_factory_options(name: str, target: Callable[..., Any], params: Mapping[str, Any],
                          opts: Mapping[str, Any], mapper_type: type) -> None:
    """Refuse, before any run, an option of ``name`` that is a parameter of its factory
    ``target`` (not of its configuration) with a value the factory refuses at every run:
    ``start_pose`` when it is a pose (:func:`checked_start_pose`: was a ValueError or an
    IndexError per run, h151) and a parameter annotated as a ``mapper_type``
    (:class:`bomgraph.mapper.Mapper`, given by the caller: :func:`check_mapper_option`)."""
    try:
        hints = typing.get_type_hints(target)
    except Exception:  # unresolvable annotations in a plugin: start_pose only
        hints = {}
    for key, value in opts.items():
        if key not in params:
            continue
        hint = hints.get(key)
        try:
            if key == "start_pose" and _pose_parameter(hint, params[key]):
                checked_start_pose(value)
            elif hint is mapper_type or mapper_type in typing.get_args(hint):
                check_mapper_option(key, value)
        except ConfigError as exc:
            raise ConfigError(f"method {name!r}: {exc}") from None


class Reach:
    """The stream's odometry dead-reckoned from ``start_pose`` (:func:`checked_start_pose`):
    :meth:`advance` refuses the step whose move carries the robot beyond
    :data:`~bomgraph.plausibility.MAX_COORDINATE_M` from the map origin, or whose own
    ``odom_sigma`` is above ``max_sigma`` (None: a method that uses no sigma, such as
    ``triangulate``, checks none), naming ``method``."""

    def __init__(self, start_pose: Any, method: str,
                 max_sigma: float | None = MAX_SIGMA) -> None:
        self.start_pose = checked_start_pose(start_pose)
        self.pose = self.start_pose.copy()
        self.method = method
        self.max_sigma = max_sigma

    def advance(self, step: Step) -> np.ndarray:
        """The dead-reckoned pose after ``step`` (its odometry composed on), shape (3,);
        the reach is left as it was when the step is refused.

        On every step of every method that holds one, so in scalars (h158: numpy's
        :func:`~bomgraph.geometry.compose` and :func:`check_sigmas` took 33-58 us a step,
        +4.7 % of the instructions of a paper run of ``ekf``, +1.2 % now); the same IEEE
        operations as ``compose``, so the same bits (``tests/hostile/test_h158_review.py``)."""
        sigma, cap = step.odom_sigma, self.max_sigma
        if sigma is not None and cap is not None and not all(
                abs(v) <= cap for v in np.asarray(sigma, float).tolist()):
            check_sigmas(sigma, step.t, "odom_sigma", self.method, cap)  # refused at its line
        if step.odom is None:
            return self.pose
        x, y, psi = self.pose.tolist()
        dx, dy, dpsi = np.asarray(step.odom, float).tolist()
        c, s = float(np.cos(psi)), float(np.sin(psi))   # numpy's, as compose's
        x, y = x + c * dx - s * dy, y + s * dx + c * dy
        distance = math.hypot(x, y)
        if not distance <= MAX_COORDINATE_M:
            check_distance(distance, step.t, self.method, "this step's move: it carries the "
                           "robot from the map origin to a distance of", self._fix(x, y))
        self.pose = np.array([x, y, float(wrap_angle(psi + dpsi))])
        return self.pose

    def _fix(self, x: float, y: float) -> str:
        """What to fix for a move to ``(x, y)`` beyond the bound: the odometry, and the option
        ``start_pose`` where the odometry alone stays within it (a far start is the user's
        option, not the stream's; h167: a start 1 m out was named for a move of 2e9 m)."""
        x0, y0 = self.start_pose[:2].tolist()
        if not math.hypot(x - x0, y - y0) <= MAX_COORDINATE_M:
            return "the stream's odometry"
        return (f"the stream's odometry, or the option start_pose: it starts the robot "
                f"{math.hypot(x0, y0):g} m from the map origin")


__all__ = ["MAX_SIGMA", "Reach", "check_bearing_sigma", "check_distance",
           "check_factory_options", "check_mapper_option", "check_priors", "checked_header",
           "check_sigmas", "checked_start_pose", "shown_beyond"]
