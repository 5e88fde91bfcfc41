"""MapEstimate: what a mapper knows at one moment, in its own frame (the value every method's
``estimate()`` returns, :mod:`bomgraph.mapper`).

Its constructor validates what a method hands it: ids are integers (never rounded), points are
``(n, 2)`` rows and poses ``(m, 3)`` rows (a ``(2, n)`` array is refused, not reshaped), all
finite, one covariance per row (a covariance block may be all NaN: not defined for that
variable). Landmark ids are non-negative, as in the stream
(``shared/STREAM_FORMAT.md``) and the estimate file.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from .checks import id_array, row_array
from .errors import ConfigError


def _ro(a: np.ndarray | None, dtype: Any, shape_tail: tuple[int, ...],
        name: str) -> np.ndarray | None:
    if a is None:
        return None

    def bad(message: str) -> ConfigError:
        return ConfigError(f"MapEstimate: {message}")

    out = (id_array(a, name, bad) if dtype is np.int64 else
           row_array(a, shape_tail[0], name, bad, tail=shape_tail))
    if name.endswith("_cov"):
        undefined = np.isnan(out).all(axis=(1, 2))
        if not np.all(np.isfinite(out[~undefined])):
            raise ConfigError(f"MapEstimate: {name} must be finite, or a block all NaN for a "
                              f"variable whose covariance is not defined")
    elif dtype is float and not np.all(np.isfinite(out)):
        raise ConfigError(f"MapEstimate: {name} must be finite (a method must leave out what "
                          f"it cannot estimate, not return NaN)")
    out.setflags(write=False)
    return out


def _has_repeats(values: np.ndarray) -> bool:
    """Whether a 1-D array holds a value twice (a sort and one comparison: ``np.unique``
    costs several times more on the small arrays of every estimate)."""
    ordered = np.sort(values)
    return bool((ordered[1:] == ordered[:-1]).any())


def _given(a: Any, name: str) -> Any:
    if a is None:
        raise ConfigError(f"MapEstimate: {name} is required (use MapEstimate.empty() for no "
                          f"landmarks)")
    return a


@dataclass(frozen=True, eq=False)
class MapEstimate:
    """What a mapper knows at one moment, in its own frame.

    Attributes
    ----------
    landmark_ids : ndarray of shape (n,), int64
    landmarks_xy : ndarray of shape (n, 2), metres
    pose_t : ndarray of shape (m,), int64, or None
        Step indices of the estimated robot poses.
    poses : ndarray of shape (m, 3) or None
        ``[x_m, y_m, psi_rad]`` per entry of ``pose_t``.
    landmark_cov : ndarray of shape (n, 2, 2) or None
        Covariance of each landmark (m^2), in the estimate's frame. A block that is all NaN
        marks a landmark whose covariance the method does not report (its marginal is not
        defined; ``info["covariances_undefined"]`` says why); every other block is finite.
    pose_cov : ndarray of shape (m, 3, 3) or None
        Covariance of each pose over ``[x_m, y_m, psi_rad]``, in the estimate's frame (not
        the robot's: a GTSAM tangent-space covariance is turned by its heading first,
        :func:`baselines.lm_report.marginal_covariances`). All-NaN blocks as in
        ``landmark_cov``.
    info : mapping
        Method diagnostics (convergence, stress, landmarks left out and why, ...).
    """

    landmark_ids: np.ndarray
    landmarks_xy: np.ndarray
    pose_t: np.ndarray | None = None
    poses: np.ndarray | None = None
    landmark_cov: np.ndarray | None = None
    pose_cov: np.ndarray | None = None
    info: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        ids = _ro(_given(self.landmark_ids, "landmark_ids"), np.int64, (), "landmark_ids")
        xy = _ro(_given(self.landmarks_xy, "landmarks_xy"), float, (2,), "landmarks_xy")
        if ids.size and ids.min() < 0:
            raise ConfigError(f"MapEstimate: landmark_ids must be non-negative (landmark ids "
                              f"are integers >= 0, as in the stream), got {int(ids.min())}")
        if ids.shape[0] != xy.shape[0]:
            raise ConfigError(f"MapEstimate: {ids.shape[0]} ids but {xy.shape[0]} positions")
        if _has_repeats(ids):
            raise ConfigError("MapEstimate: a landmark id appears twice")
        if not isinstance(self.info, Mapping):
            raise ConfigError(f"MapEstimate: info must be a mapping (a dict of diagnostics), "
                              f"got {type(self.info).__name__}")
        object.__setattr__(self, "landmark_ids", ids)
        object.__setattr__(self, "landmarks_xy", xy)
        object.__setattr__(self, "pose_t", _ro(self.pose_t, np.int64, (), "pose_t"))
        object.__setattr__(self, "poses", _ro(self.poses, float, (3,), "poses"))
        object.__setattr__(self, "landmark_cov",
                           _ro(self.landmark_cov, float, (2, 2), "landmark_cov"))
        object.__setattr__(self, "pose_cov", _ro(self.pose_cov, float, (3, 3), "pose_cov"))
        if self.pose_t is not None and _has_repeats(self.pose_t):
            raise ConfigError("MapEstimate: a pose step t appears twice")
        if (self.pose_t is None) != (self.poses is None):
            raise ConfigError("MapEstimate: pose_t and poses go together")
        if self.poses is not None and len(self.poses) != len(self.pose_t):
            raise ConfigError("MapEstimate: pose_t and poses differ in length")
        if self.landmark_cov is not None and len(self.landmark_cov) != len(ids):
            raise ConfigError("MapEstimate: one 2x2 covariance per landmark")
        if self.pose_cov is not None and (self.poses is None or len(self.pose_cov) != len(self.poses)):
            raise ConfigError("MapEstimate: one 3x3 covariance per pose")

    @classmethod
    def empty(cls, **info: Any) -> "MapEstimate":
        """No landmarks yet (``info`` says why)."""
        return cls(np.zeros(0, np.int64), np.zeros((0, 2)), info=info)

    def __len__(self) -> int:
        return len(self.landmark_ids)


__all__ = ["MapEstimate"]
