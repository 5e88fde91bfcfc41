"""Bearing-only EKF-SLAM on filterpy: the paper's BOSLAM-EKF baseline (section IV, Exp. 2).

``models`` (motion and bearing models, Jacobians, Bailey's KL test, inverse depth), ``filter``
(the filter: filterpy's ``ExtendedKalmanFilter`` holds the state, lean block predict and
sparse update), ``config`` (options and presets), ``slam`` (the machinery both mappers share),
``mappers`` (``ekf``, ``ekf-invdepth``), ``anchor`` (``ekf``'s option ``anchor_test``).
"""

from .config import BearingEkfConfig, EkfConfig, InverseDepthConfig
from .filter import BearingEkf
from .mappers import EkfMapper, InverseDepthEkfMapper

__all__ = ["BearingEkf", "BearingEkfConfig", "EkfConfig", "EkfMapper", "InverseDepthConfig",
           "InverseDepthEkfMapper"]
