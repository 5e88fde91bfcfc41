"""A lean bearing-only EKF-SLAM loop: the speed reference of ``scripts/bench_ekf.py --speed``.

The same stream and state sizes as ``ekf`` (robot pose, then a ``[x, y]`` block per mapped
landmark), none of its safeguards: known associations, a per-bearing chi-square gate, no observability constraints,
no second-order variance, no clones or Gaussianity test, and no initialisation problem: a
landmark enters at its second sighting at its *true* position with an independent isotropic
covariance (a naive triangulation diverges on the paper's setup, landmarks 0-1 m away and
15-30 % odometry noise, and a diverging loop times nothing useful). Predict on the pose block,
update on the rows the bearings touch, in place on preallocated arrays: what an EKF-SLAM step
costs in numpy with nothing else in the way. Not a method; no accuracy claims.
"""

from __future__ import annotations

import math
from typing import Iterable

import numpy as np

from bomgraph.stream import Step, StreamHeader


def lean_ekf_slam(header: StreamHeader, steps: Iterable[Step], start_pose: np.ndarray,
                  truth_xy: dict[int, np.ndarray], init_sigma_m: float = 0.05,
                  gate: float = 10.83
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Run the loop; returns the mapped landmark ids ``(m,)`` and positions ``(m, 2)``.

    ``truth_xy`` (id -> true ``[x_m, y_m]``) places each landmark at its second sighting.
    """
    n_max = len(truth_xy)
    cap = 3 + 2 * n_max
    x = np.zeros(cap)
    P = np.zeros((cap, cap))
    x[:3] = start_pose
    n = 3
    where: dict[int, int] = {}
    first: dict[int, float] = {}
    var_b = header.bearing_sigma_rad ** 2
    for st in steps:
        if st.odom is not None:
            dx, dy, dpsi = (float(v) for v in st.odom)
            su = np.asarray(st.odometry_sigma(header), float) ** 2
            c, s = math.cos(x[2]), math.sin(x[2])
            f = np.array([[1.0, 0.0, -s * dx - c * dy], [0.0, 1.0, c * dx - s * dy],
                          [0.0, 0.0, 1.0]])
            g = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            x[0] += c * dx - s * dy
            x[1] += s * dx + c * dy
            x[2] = math.remainder(x[2] + dpsi, 2 * math.pi)
            P[:3, :3] = f @ P[:3, :3] @ f.T + (g * su) @ g.T
            P[:3, 3:n] = f @ P[:3, 3:n]
            P[3:n, :3] = P[:3, 3:n].T
        ids, z = st.landmark_ids.tolist(), st.bearings_rad
        rows = [(k, where[i]) for k, i in enumerate(ids) if i in where]
        if rows:
            ks = np.array([r[0] for r in rows])
            off = np.array([r[1] for r in rows])
            d = x[off[:, None] + np.arange(2)] - x[:2]
            q = d[:, 0] ** 2 + d[:, 1] ** 2
            y = np.remainder(z[ks] - (np.arctan2(d[:, 1], d[:, 0]) - x[2]) + np.pi,
                             2 * np.pi) - np.pi
            m = len(ks)
            cols = np.concatenate([np.arange(3), (off[:, None] + np.arange(2)).ravel()])
            hu = np.zeros((m, 3 + 2 * m))
            hu[:, 0], hu[:, 1], hu[:, 2] = d[:, 1] / q, -d[:, 0] / q, -1.0
            hu[np.arange(m), 3 + 2 * np.arange(m)] = -d[:, 1] / q
            hu[np.arange(m), 4 + 2 * np.arange(m)] = d[:, 0] / q
            hp = hu @ P[cols, :n]
            s_mat = hp[:, cols] @ hu.T + var_b * np.eye(m)
            ok = y * y <= gate * np.diag(s_mat)              # per-bearing NIS gate
            if not ok.all():
                hu, y = hu[ok], y[ok]
                hp, s_mat = hp[ok], s_mat[np.ix_(ok, ok)]
            k_t = np.linalg.solve(s_mat, hp)
            x[:n] += y @ k_t
            P[:n, :n] -= hp.T @ k_t
        for k, i in enumerate(ids):
            if i in where:
                continue
            if i not in first:                       # the first sighting: wait for a second
                first[i] = float(z[k])
                continue
            # enters at its true position with an independent (init_sigma_m)^2 covariance
            P[n:n + 2, :n] = 0.0
            P[:n, n:n + 2] = 0.0
            P[n:n + 2, n:n + 2] = init_sigma_m ** 2 * np.eye(2)
            x[n:n + 2] = truth_xy[i]
            where[i] = n
            n += 2
    ids_out = np.array(sorted(where), np.int64)
    return ids_out, np.array([x[where[i]:where[i] + 2] for i in ids_out]).reshape(-1, 2)


__all__ = ["lean_ekf_slam"]
