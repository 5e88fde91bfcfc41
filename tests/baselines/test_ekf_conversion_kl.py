"""``ekf-invdepth``: when a feature becomes Euclidean (``conversion_kl_max``,
baselines/ekf/mappers.py).

Civera's linearity index ``4 sigma_d / d |cos alpha|`` asks whether the bearing from the
current pose is linear in ``[x, y]``; it passes whenever the robot sees the anchor ray
side-on or from afar (after a long blind step on a recording), however uncertain the
feature's depth still is, and the linear map of such a feature's Gaussian to ``[x, y]`` is
overconfident (docs/measurements.md, h159). With ``conversion_kl_max`` the conversion also
has to pass Bailey's Gaussianity test, as ``ekf``'s inverse-depth candidates do.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from baselines.ekf import InverseDepthConfig
from baselines.ekf.mappers import InverseDepthEkfMapper
from baselines.ekf.models import invdepth_conversion_kl
from bomgraph.errors import ConfigError
from bomgraph.stream import StreamHeader

_HEADER = StreamHeader(bearing_sigma_rad=0.01, odometry_sigma=(0.01, 0.01, 0.005),
                       sensor_range_m=8.0)


def _features(rel_sd: float) -> tuple[np.ndarray, np.ndarray]:
    """A feature 2 m along its anchor ray, the ray 20 m from the robot (at the origin) and
    seen side-on: ``sigma_rho / rho = rel_sd``."""
    f = np.array([[0.0, -20.0, 0.0, 0.5]])
    c = np.diag([1e-4, 1e-4, 1e-4, (rel_sd * 0.5) ** 2])[None]
    return f, c


@pytest.mark.parametrize("rel_sd, converts", [(0.3, False), (0.02, True)])
def test_the_conversion_waits_for_a_gaussian_depth(rel_sd, converts) -> None:
    f, c = _features(rel_sd)
    civera = InverseDepthEkfMapper(_HEADER, preset="real", conversion_kl_max=None)
    assert civera._linear_enough(f, c).tolist() == [True]        # the index passes either way
    bailey = InverseDepthEkfMapper(_HEADER, preset="real", conversion_kl_max=0.01)
    assert bailey._linear_enough(f, c).tolist() == [converts]
    assert (invdepth_conversion_kl(f, c)[0] <= 0.01) == converts


def test_the_test_only_narrows_civeras() -> None:
    """A feature Civera's index keeps in inverse depth stays there, however Gaussian."""
    f, c = _features(0.001)
    f[0, :2] = [0.0, -2.0]                      # the ray 2 m away, the point seen at 45 deg
    m = InverseDepthEkfMapper(_HEADER, preset="real", conversion_kl_max=1e9)
    lin = InverseDepthEkfMapper(_HEADER, preset="real", linearity_max=1e-6)
    assert m._linear_enough(f, c).tolist() == [True]
    assert lin._linear_enough(f, c).tolist() == [False]
    both = InverseDepthEkfMapper(_HEADER, preset="real", linearity_max=1e-6,
                                 conversion_kl_max=1e9)
    assert both._linear_enough(f, c).tolist() == [False]


def test_on_in_real_off_in_paper_and_checked() -> None:
    assert InverseDepthConfig.preset("paper").conversion_kl_max is None
    assert InverseDepthConfig.preset("real").conversion_kl_max == 0.01
    assert InverseDepthConfig(conversion_kl_max=0.5).conversion_kl_max == 0.5
    for bad in (0, -1.0, math.inf, math.nan, True, "0.01"):
        with pytest.raises(ConfigError, match="conversion_kl_max"):
            InverseDepthConfig(conversion_kl_max=bad)
