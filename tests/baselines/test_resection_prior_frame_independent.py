"""The odometry prior of :func:`baselines.resection.resect_trajectory` is in the right frame,
checked against a brute-force MAP pose written here without the resection code.

The stream's odometry sigmas ``[sigma_dx, sigma_dy]`` are on the increment's components in
the frame of pose ``t-1`` (STREAM_FORMAT.md): the predicted pose ``t`` has the position
covariance ``R(psi_{t-1}) diag(sigma_dx^2, sigma_dy^2) R(psi_{t-1})^T``. Before the
twenty-first session ``resect_trajectory`` put ``sigma_dx`` on world x and ``sigma_dy`` on
world y, so a robot heading along world y was held tight along its travel and loose across it
(the simulator's ``sigma_dy = 0`` is the extreme case).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize

from baselines.resection import resect_trajectory


def _map_pose(prior: np.ndarray, prior_cov: np.ndarray, landmarks_xy: np.ndarray,
              bearings_rad: np.ndarray, sigma_rad: float, start: np.ndarray) -> np.ndarray:
    """argmin of ``sum (wrapped bearing residual / sigma)^2 + e^T C^-1 e`` by BFGS."""
    info = np.linalg.inv(prior_cov)

    def cost(p: np.ndarray) -> float:
        pred = np.arctan2(landmarks_xy[:, 1] - p[1], landmarks_xy[:, 0] - p[0]) - p[2]
        r = np.angle(np.exp(1j * (bearings_rad - pred))) / sigma_rad
        e = p - prior
        e[2] = np.angle(np.exp(1j * e[2]))
        return float(r @ r + e @ info @ e)

    out = minimize(cost, start, method="BFGS", options={"gtol": 1e-12})
    return out.x


def test_the_odometry_prior_is_turned_into_the_world_by_the_previous_heading() -> None:
    map_ids = np.arange(6)
    map_xy = np.array([[2.0, 3.0], [-2.0, 2.5], [1.5, -2.0], [-1.0, -2.5], [3.0, 0.5],
                       [-3.0, 0.0]])
    pose0 = np.array([0.1, 0.2, math.pi / 2])        # heading along world +y
    u = np.array([0.5, 0.0, 0.1])                    # forward 0.5 m: along world y
    c, s = math.cos(pose0[2]), math.sin(pose0[2])
    pose1_true = np.array([pose0[0] + c * u[0], pose0[1] + s * u[0], pose0[2] + u[2]])
    sigma_b = 0.05
    # pose 0 sees all six landmarks exactly; pose 1 three, with fixed errors
    b0 = np.arctan2(map_xy[:, 1] - pose0[1], map_xy[:, 0] - pose0[0]) - pose0[2]
    seen1 = np.array([0, 2, 4])
    b1 = (np.arctan2(map_xy[seen1, 1] - pose1_true[1], map_xy[seen1, 0] - pose1_true[0])
          - pose1_true[2] + np.array([0.06, -0.04, 0.05]))
    owner = np.r_[np.zeros(6, np.int64), np.ones(3, np.int64)]
    ids = np.r_[map_ids, seen1]
    brg = np.r_[b0, b1]
    odoms = np.vstack([np.zeros(3), u])
    odo_sigma = np.array([[0.0, 0.0, 0.0], [0.2, 0.002, 0.01]])   # forward loose, lateral tight
    prior_sigma = np.array([1e-3, 1e-3, 1e-3])
    poses = resect_trajectory(owner, ids, brg, sigma_b, map_ids, map_xy, odoms, odo_sigma,
                              huber_k=1e6, map_sigma_m=0.0, prior_sigma=prior_sigma)
    np.testing.assert_allclose(poses[0], pose0, atol=1e-9)
    # the independent MAP: the prior N(pose0 (+) u, G diag(sigma_u^2) G^T + diag(prior_sigma^2))
    g = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    cov = g @ np.diag(odo_sigma[1] ** 2) @ g.T + np.diag(prior_sigma ** 2)
    want = _map_pose(pose1_true, cov, map_xy[seen1], b1, sigma_b, pose1_true)
    np.testing.assert_allclose(poses[1], want, atol=1e-7)
    # the tight lateral sigma (world x here) holds x; forward (world y) is free to move
    assert abs(poses[1][0] - pose1_true[0]) < 0.01
