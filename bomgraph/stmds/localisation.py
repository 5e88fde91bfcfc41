"""Localisation (paper section III-E): the last p robot poses, their distances, headings.

:class:`RobotPoses` holds the last ``n_robot_poses`` (the paper's p = 6) poses: the odometry
between them, their bearings and, per (pose, landmark), the sums of the fused robot-landmark
distances. Robot-robot distances come from dead reckoning the odometry between the held poses
(:meth:`RobotPoses.robot_pairs`); robot-landmark distances are the triangulation depths ``r1``
(from pose ``t-k``) and ``r2`` (from pose ``t``) fused with the landmark pairs' rule, or one
triangulation of each landmark over all the held poses (:meth:`RobotPoses.all_pose_ranges`).

Method 2 reconstructs the positions jointly with the landmarks (the paper's extended matrix,
eq. 7: :func:`extend_with_robots`); Method 1 maps the landmarks alone and then trilaterates
each position against that map (:func:`trilaterate_robots`), because DMC-SPL over the sparse
robot rows distorts the map. A heading is then found for every pose by resection
(:func:`resect_headings`): the circular mean of ``atan2(landmark - robot) - bearing`` over the
landmarks it saw. MDS cannot tell a map from its mirror image; the bearings can, so the output
is reflected when the mirrored resection fits the bearings better, and every pose is returned
in a frame with the measured (counter-clockwise) bearing convention.
"""

from __future__ import annotations

import math

import numpy as np

from ..angles import angle_residual, wrap_angle
from ..geometry import chain_odometry, dead_reckon
from .distances import estimate_weights, fused_from_sums
from .mds import trilaterate


class RobotPoses:
    """The last ``n_robot_poses`` (the paper's p) poses: odometry between them, their bearings
    and the fused robot-landmark distance sums."""

    def __init__(self, size: int, fusion: str) -> None:
        self.size = size
        self.fusion = fusion
        self.t: list[int] = []
        self.odom: list[np.ndarray] = []        # odom[k] leads from pose k-1 to pose k
        self.sigma: list[np.ndarray] = []       # its std. devs.
        self.bearing_idx: list[np.ndarray] = []  # dense landmark indices seen at the pose
        self.bearings: list[np.ndarray] = []
        self.rl_idx: list[np.ndarray] = []       # robot-landmark estimates: landmark index
        self.rl_w: list[np.ndarray] = []         # sum of 1 / var
        self.rl_wd: list[np.ndarray] = []        # sum of d / var

    def reset(self) -> None:
        self.__init__(self.size, self.fusion)  # type: ignore[misc]

    def push(self, t: int, odom: np.ndarray | None, sigma: np.ndarray | None, idx: np.ndarray,
             bearings: np.ndarray) -> None:
        if odom is None and self.t:
            self.reset()
        self.t.append(t)
        self.odom.append(np.zeros(3) if odom is None else np.asarray(odom, float))
        self.sigma.append(np.zeros(3) if sigma is None else np.asarray(sigma, float))
        self.bearing_idx.append(idx)
        self.bearings.append(bearings)
        self.rl_idx.append(np.zeros(0, np.int64))
        self.rl_w.append(np.zeros(0))
        self.rl_wd.append(np.zeros(0))
        if len(self.t) > self.size:
            for lst in (self.t, self.odom, self.sigma, self.bearing_idx, self.bearings,
                        self.rl_idx, self.rl_w, self.rl_wd):
                del lst[0]

    def add_ranges(self, k: int, idx: np.ndarray, dist: np.ndarray, var: np.ndarray) -> None:
        """Fold robot-landmark distance estimates into pose ``k`` held, weighted by
        the same fusion rule as the landmark pairs (``var(r^2) = 4 r^2 var(r)``)."""
        if k < 0 or k >= len(self.t) or idx.size == 0:
            return
        r2 = dist * dist
        w, x = estimate_weights(self.fusion, r2, 4.0 * r2 * var)
        old_i, old_w, old_wd = self.rl_idx[k], self.rl_w[k], self.rl_wd[k]
        all_i = np.concatenate([old_i, idx])
        uniq, inv = np.unique(all_i, return_inverse=True)
        self.rl_idx[k] = uniq
        self.rl_w[k] = np.bincount(inv, np.concatenate([old_w, w]), len(uniq))
        self.rl_wd[k] = np.bincount(inv, np.concatenate([old_wd, w * x]), len(uniq))

    def ranges(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Fused robot-landmark distances of pose ``k``: (landmark, distance_m, variance_m2)."""
        d, v = fused_from_sums(self.fusion, self.rl_w[k], self.rl_wd[k])
        return self.rl_idx[k], d, v

    def relative_poses(self) -> np.ndarray:
        """The held poses dead-reckoned from the first one, shape ``(m, 3)``."""
        return dead_reckon(np.array(self.odom[1:]).reshape(-1, 3))

    def all_pose_ranges(self, bearing_sigma_rad: float, min_parallax_rad: float
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Robot-landmark distances by triangulating every landmark over all the held poses.

        The held poses are dead-reckoned (short chains, little drift); each landmark seen
        from at least two of them is the least-squares intersection of its rays, weighted by
        ``1 / range^2`` (a bearing error moves the ray by ``range * sigma`` at the point), and
        refused without enough parallax or behind a ray. The distance from every observing
        pose follows, with the first-order variance ``u^T Cov(x) u`` plus the dead-reckoning
        variance of that pose's position among the held poses.

        Returns
        -------
        pose, landmark : int arrays of shape (R,)
            Pose slot and dense landmark index of each distance.
        distance_m, variance_m2 : arrays of shape (R,)
        """
        m = len(self.t)
        empty = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros(0))
        if m < 2:
            return empty
        poses = self.relative_poses()
        pose_of = np.repeat(np.arange(m), [len(b) for b in self.bearings])
        lm = np.concatenate(self.bearing_idx)
        if lm.size == 0:
            return empty
        ang = poses[pose_of, 2] + np.concatenate(self.bearings)
        origin = poses[pose_of, :2]
        uniq, owner = np.unique(lm, return_inverse=True)
        dx, dy = np.cos(ang), np.sin(ang)
        nxx, nxy, nyy = dy * dy, -dx * dy, dx * dx          # I - d d^T
        wgt = np.ones(lm.size)
        x = np.full((len(uniq), 2), np.nan)
        ok = np.zeros(len(uniq), bool)
        for _ in range(2):                                   # unweighted, then 1 / r^2
            axx = np.bincount(owner, wgt * nxx, len(uniq))
            axy = np.bincount(owner, wgt * nxy, len(uniq))
            ayy = np.bincount(owner, wgt * nyy, len(uniq))
            bx = np.bincount(owner, wgt * (nxx * origin[:, 0] + nxy * origin[:, 1]), len(uniq))
            by = np.bincount(owner, wgt * (nxy * origin[:, 0] + nyy * origin[:, 1]), len(uniq))
            det = axx * ayy - axy * axy
            tr = axx + ayy
            lam = tr / 2 - np.sqrt(np.maximum(tr * tr / 4 - det, 0.0))
            # smallest eigenvalue over the mean weight: 1 - cos(parallax) for two rays
            mean_w = np.bincount(owner, wgt, len(uniq)) / np.maximum(
                np.bincount(owner, minlength=len(uniq)), 1)
            ok = lam >= (1.0 - math.cos(min_parallax_rad)) * mean_w
            with np.errstate(divide="ignore", invalid="ignore"):
                x = np.column_stack([(ayy * bx - axy * by) / det, (axx * by - axy * bx) / det])
            off = x[owner] - origin
            with np.errstate(invalid="ignore"):
                depth = off[:, 0] * dx + off[:, 1] * dy
                front = np.bincount(owner, ~(depth > 0), len(uniq)) == 0
                rng2 = np.einsum("ra,ra->r", off, off)
            ok &= front & np.isfinite(x).all(axis=1)
            wgt = 1.0 / np.where(ok[owner], np.maximum(rng2, 1e-6), 1.0)
        use = ok[owner]
        if not use.any():
            return empty
        # Cov(x) = sigma^2 A_w^-1 with the 1 / r^2 weights of the last pass
        with np.errstate(divide="ignore", invalid="ignore"):
            cxx, cxy, cyy = ayy / det, -axy / det, axx / det
        off = off[use]
        r = np.sqrt(np.einsum("ra,ra->r", off, off))
        ux, uy = off[:, 0] / r, off[:, 1] / r
        o = owner[use]
        var = bearing_sigma_rad ** 2 * (ux * ux * cxx[o] + 2 * ux * uy * cxy[o] + uy * uy * cyy[o])
        sig = np.array(self.sigma)
        drift = np.cumsum((sig[:, 0] ** 2 + sig[:, 1] ** 2))        # position variance growth
        pose_var = np.abs(drift - drift[m // 2])
        return pose_of[use], uniq[o], r, var + pose_var[pose_of[use]]

    def robot_pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Dead-reckoned distances between all held poses and their variances.

        Returns ``(a, b, distance_m, variance_m2)`` with pose slots ``a < b``.
        """
        m = len(self.t)
        sig = np.array(self.sigma[1:]).reshape(-1, 3)
        xy, psi = chain_odometry(np.array(self.odom[1:]).reshape(-1, 3))
        c, s = np.cos(psi[:-1]), np.sin(psi[:-1])
        a, b = np.triu_indices(m, 1)
        off = xy[b] - xy[a]
        dist = np.hypot(off[:, 0], off[:, 1])
        unit = off / np.maximum(dist, 1e-300)[:, None]
        # First-order variance: motion k (pose k-1 -> k) moves the offset when a < k <= b.
        k = np.arange(1, m)
        inside = (k[None, :] > a[:, None]) & (k[None, :] <= b[:, None])       # (pairs, m-1)
        # d off / d(dx, dy)_k = R(psi_{k-1}); projected on the unit offset.
        rx = unit[:, None, 0] * c[None, :] + unit[:, None, 1] * s[None, :]
        ry = -unit[:, None, 0] * s[None, :] + unit[:, None, 1] * c[None, :]
        # d off / d dpsi_k turns every later motion: the lever is xy_b - xy_k.
        lever = xy[b][:, None, :] - xy[k][None, :, :]
        perp = unit[:, None, 0] * (-lever[..., 1]) + unit[:, None, 1] * lever[..., 0]
        inside_turn = (k[None, :] > a[:, None]) & (k[None, :] < b[:, None])
        var = (inside * (rx ** 2 * sig[None, :, 0] ** 2 + ry ** 2 * sig[None, :, 1] ** 2)).sum(1) \
            + (inside_turn * perp ** 2 * sig[None, :, 2] ** 2).sum(1)
        return a, b, dist, var



def extend_with_robots(win: RobotPoses, first: np.ndarray, second: np.ndarray,
                       dist: np.ndarray, var: np.ndarray, n_lm: int, robot_ranges: str,
                       bearing_sigma_rad: float, min_parallax_rad: float
                       ) -> tuple[np.ndarray, ...]:
    """Append the held robot positions as nodes ``n_lm + k`` with their distances (eq. 7).

    Returns ``(first, second, distance_m, variance_m2, robot_nodes)``: the landmark pairs
    given, then robot-robot pairs (dead reckoning) and robot-landmark pairs (``robot_ranges``).
    """
    m = len(win.t)
    robot_nodes = n_lm + np.arange(m)
    parts_f, parts_s, parts_d, parts_v = [first], [second], [dist], [var]
    if m >= 2:
        a, b, d, v = win.robot_pairs()
        parts_f.append(robot_nodes[a])
        parts_s.append(robot_nodes[b])
        parts_d.append(d)
        parts_v.append(np.maximum(v, 1e-12))
    if robot_ranges == "all-poses":
        k, lm, d, v = win.all_pose_ranges(bearing_sigma_rad, min_parallax_rad)
        parts_f.append(lm)
        parts_s.append(robot_nodes[k])
        parts_d.append(d)
        parts_v.append(np.maximum(v, 1e-12))
    for k in range(m if robot_ranges == "pairwise" else 0):
        if win.rl_idx[k].size:
            lm, d, v = win.ranges(k)
            parts_f.append(lm)
            parts_s.append(np.full(lm.size, robot_nodes[k]))
            parts_d.append(d)
            parts_v.append(v)
    return (np.concatenate(parts_f), np.concatenate(parts_s), np.concatenate(parts_d),
            np.concatenate(parts_v), robot_nodes)


def trilaterate_robots(win: RobotPoses, n_lm: int, lm_idx: np.ndarray, lm_xy: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Held positions placed against the mapped landmarks (dense indices ``lm_idx``, points
    ``lm_xy`` of shape ``(n, 2)``) from their fused ranges: ``(pose slots, xy (k, 2))``."""
    where = np.full(n_lm, -1, np.int64)
    where[lm_idx] = np.arange(len(lm_idx))
    ks, pts = [], []
    for k in range(len(win.t)):                       # at most n_robot_poses
        lm, d, v = win.ranges(k)
        row = where[lm]
        use = row >= 0
        x = trilaterate(lm_xy[row[use]], d[use], v[use])
        if x is not None:
            ks.append(k)
            pts.append(x)
    return np.array(ks, np.int64), np.array(pts).reshape(-1, 2)


def resect_headings(win: RobotPoses, kept_nodes: np.ndarray, xy: np.ndarray, n_lm: int,
                    lm_idx: np.ndarray, lm_xy: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, bool]:
    """Headings by resection; reflect the frame when the mirror image fits better.

    Every bearing taken from a held pose to a mapped landmark gives a heading candidate
    ``atan2(landmark - robot) - bearing`` (vectorised over all of them); a pose's heading
    is the circular mean of its candidates. The spread of the candidates around their
    means decides between the map and its mirror image.

    Returns ``(lm_xy, pose_t, poses (k, 3), reflected)`` in the frame chosen.
    """
    m = len(win.t)
    node_row = np.full(n_lm + m, -1, np.int64)
    node_row[kept_nodes] = np.arange(len(kept_nodes))
    robot_row = node_row[n_lm + np.arange(m)]
    ks = np.flatnonzero(robot_row >= 0)
    if ks.size == 0:
        return lm_xy, None, None, False
    robot_xy = xy[robot_row[ks]]
    lm_row = np.full(n_lm, -1, np.int64)
    lm_row[lm_idx] = np.arange(len(lm_idx))
    # all bearings of the kept poses to mapped landmarks: (pose slot, landmark row, bearing)
    slot = np.concatenate([np.full(len(win.bearing_idx[k]), j) for j, k in enumerate(ks)])
    lm = lm_row[np.concatenate([win.bearing_idx[k] for k in ks])]
    brg = np.concatenate([win.bearings[k] for k in ks])
    use = lm >= 0
    slot, lm, brg = slot[use], lm[use], brg[use]
    n_obs = np.bincount(slot, minlength=len(ks))
    best = None
    for sign in (1.0, -1.0):
        flip = np.array([1.0, sign])
        off = lm_xy[lm] * flip - robot_xy[slot] * flip
        cand = np.arctan2(off[:, 1], off[:, 0]) - brg
        with np.errstate(invalid="ignore"):
            psi = np.arctan2(np.bincount(slot, np.sin(cand), len(ks)),
                             np.bincount(slot, np.cos(cand), len(ks)))
        psi[n_obs == 0] = np.nan
        resid = float(np.sum(angle_residual(cand, psi[slot]) ** 2))
        if best is None or resid < best[0]:
            best = (resid, sign, psi)
    assert best is not None
    _, sign, psi = best
    flip = np.array([1.0, sign])
    psi = _fill_headings(win, ks, psi)
    poses = np.column_stack([robot_xy * flip, wrap_angle(psi)])
    pose_t = np.array(win.t, np.int64)[ks]
    good = np.isfinite(poses).all(axis=1)
    return lm_xy * flip, pose_t[good], poses[good], bool(sign < 0)


def _fill_headings(win: RobotPoses, ks: np.ndarray, psi: np.ndarray) -> np.ndarray:
    """Poses that saw no mapped landmark take the heading of a neighbour plus odometry."""
    psi = psi.copy()
    for _ in range(len(psi)):
        miss = ~np.isfinite(psi)
        if not miss.any() or miss.all():
            break
        for row in np.flatnonzero(miss):
            k = ks[row]
            if row > 0 and np.isfinite(psi[row - 1]) and ks[row - 1] == k - 1:
                psi[row] = psi[row - 1] + win.odom[k][2]
            elif row + 1 < len(psi) and np.isfinite(psi[row + 1]) and ks[row + 1] == k + 1:
                psi[row] = psi[row + 1] - win.odom[k + 1][2]
    return psi


__all__ = ["RobotPoses", "extend_with_robots", "trilaterate_robots", "resect_headings"]
