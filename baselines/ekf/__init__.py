"""Bearing-only EKF-SLAM on filterpy: the paper's BOSLAM-EKF baseline (section IV, Exp. 2).

``models`` (motion and bearing models, Jacobians, Bailey's KL test, inverse depth), ``filter``
(the filterpy wrapper), ``config`` (options and presets), ``mappers`` (``ekf``,
``ekf-invdepth``).
"""

from .config import BearingEkfConfig, EkfConfig, InverseDepthConfig
from .filter import BearingEkf
from .mappers import EkfMapper, InverseDepthEkfMapper

__all__ = ["BearingEkf", "BearingEkfConfig", "EkfConfig", "EkfMapper", "InverseDepthConfig",
           "InverseDepthEkfMapper"]
