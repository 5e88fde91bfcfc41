"""The EKF baselines as mappers: ``ekf`` and ``ekf-invdepth`` (paper section IV, Exp. 2).

The paper compares BOM-STMDS with "BOSLAM-EKF", whose new landmarks are initialised by Bailey's
*constrained initialisation* (T. Bailey, ICRA 2003): :class:`EkfMapper`, ``ekf``.
:class:`InverseDepthEkfMapper`, ``ekf-invdepth``, is an undelayed alternative (Civera, Davison
and Montiel, IEEE T-RO 2008, reduced to the plane). Both run on :class:`~baselines.ekf.filter.
BearingEkf` (filterpy); the models are in :mod:`baselines.ekf.models`, the options in
:mod:`baselines.ekf.config`, measured numbers in docs/measurements.md.

Each step: predict with the odometry; gate each bearing to a mapped landmark on its own
(individual compatibility, ``y_i^2 / (H_i P H_i^T + var_i)`` against the chi-square 1-dof
quantile ``gate_probability``; a gated bearing leaves the state exactly as if it had not been
measured); then **one batched update** with the rest. Three measures against linearisation
error (landmarks are 0-1 m away and the odometry noise is 15-30 % of a step in the paper's
setup):

* the second-order variance of each bearing, and bearings whose nonlinearity index exceeds
  ``max_bearing_nonlinearity`` are not used (:func:`~baselines.ekf.models.
  second_order_variance`), taken in the robot's frame: a rotation of the map and the robot
  together changes no bearing, so an uncertain global heading does not count;
* observability constraints (OC-EKF): every measurement row is linearised at the closest
  point with ``h N = 0`` (:meth:`~baselines.ekf.slam.EkfSlam._constrain`; the option
  ``jacobians`` also offers first-estimate Jacobians and the plain EKF);
* Bailey's intermediate bearings (below).

Constrained (delayed) initialisation, ``ekf``
    A landmark seen for the first time is a *candidate*: its bearing ``z1`` is kept and the
    current pose is cloned into the state (stochastic cloning; all candidates seen at one step
    share one clone). At each later sighting ``z2`` the landmark is triangulated from the
    anchor clone and the current pose (:func:`~baselines.ekf.models.triangulate_two_bearings`)
    and Bailey's Gaussianity test is applied (:func:`~baselines.ekf.models.triangulation_kl`);
    below ``init_kl_max`` (and in front of both rays) the landmark enters the state with
    ``P_lx = J_x P[x_c, r, :]``, ``P_ll = J_x P_cr J_x^T + J_z diag(sigma^2) J_z^T``. The
    bearings taken between the two (each with a clone of its pose) are then applied in one
    batched, gated update, and clones no candidate needs are removed. A candidate whose rays
    cross behind the robot at clear parallax, or that waited ``max_pending_steps``, is
    re-anchored at the current sighting; why candidates seen again are not initialised is
    counted in ``info`` (``init_rejected_behind``, ``init_rejected_kl``).

Inverse-depth candidates, ``ekf`` with ``candidates="inverse-depth"`` (preset ``"real"``)
    On recordings (landmarks metres away in a narrow view, the heading unconstrained while
    every landmark waits) clone candidates rarely become well conditioned. With this option a
    first sighting enters the state at once as an inverse-depth feature (as in
    ``ekf-invdepth``), so its bearings keep the heading in check from the start; it joins the
    map as ``[x, y]`` when Bailey's test passes on that conversion
    (:func:`~baselines.ekf.models.invdepth_conversion_kl` below ``init_kl_max``). Features not
    yet converted are not on the map (``info["pending"]``). A feature whose bearings fail the
    gate ``restart_after_gated`` times in a row started from an outlier and is started again
    (``info["restarted"]``). With ``anchor_test`` (off in every preset) the first bearing is
    also tested once the later sightings constrain it (:mod:`baselines.ekf.anchor`).

Inverse depth, ``ekf-invdepth``
    A first sighting enters the state at once as ``[x0, y0, theta, rho]`` (anchor = robot
    position, ``theta = psi + z``, ``rho ~ N(rho_init, rho_sigma^2)``); it is converted to a
    Euclidean ``[x, y]`` block once Civera's linearity index ``4 sigma_d / d |cos alpha|``
    falls below ``linearity_max`` and, with ``conversion_kl_max`` set (preset ``real``),
    Bailey's test on the conversion passes, as for ``ekf``'s candidates. Features still in
    inverse depth are reported through the same conversion by ``estimate()``; left out are those with ``rho <= 0`` and those whose
    depth the bearings have not determined (the std. dev. of ``rho`` still above half its
    prior's: no parallax yet, e.g. from a robot that has not moved; with
    ``relative_depth_check``, preset ``"real"``, also its ratio to ``rho``: the std. dev. is
    set by the parallax, hardly by ``rho``, so a small ``rho``, a far landmark or one an update
    pulled towards 0, passed with the depth as unknown as before). The prior on
    ``rho`` makes it inexact on noise-free data and it is less consistent than ``ekf``.

Iterated update (``iterations > 1``)
    Gauss-Newton on the prior and the step's bearings
    (:meth:`~baselines.ekf.filter.BearingEkf.update`); the iterates use the model's own
    Jacobians, the last step the observability-constrained ones. It helps after a long blind
    turn, when one update has to move the heading by tens of degrees.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bomgraph.angles import angle_residual
from bomgraph.config import resolve
from bomgraph.stream import Step, StreamHeader

from .anchor import AnchorTestMixin
from .config import EkfConfig, InverseDepthConfig
from .models import invdepth_conversion_kl, invdepth_to_xy, triangulation_kl
from .range_prior import RhoPriorMixin
from .slam import BLOCK_CLONE, BLOCK_IDP, BLOCK_LM, EkfSlam

_R3 = np.arange(3)


class EkfMapper(AnchorTestMixin, RhoPriorMixin, EkfSlam):
    """Bearing-only EKF-SLAM with Bailey's constrained (delayed) initialisation (``ekf``).

    Parameters
    ----------
    header : StreamHeader
        Supplies the bearing and odometry sigmas.
    start_pose : (x_m, y_m, psi_rad)
        The first pose; the map is in this frame.
    config : EkfConfig, optional
        Or ``preset`` (``EkfConfig.PRESETS``: ``"paper"``, the default, or ``"real"``) and
        its fields as keyword options (they replace the preset's); never both
        (:func:`bomgraph.config.resolve`).
    """

    def __init__(self, header: StreamHeader, *, start_pose: tuple[float, float, float] =
                 (0.0, 0.0, 0.0), config: EkfConfig | None = None,
                 preset: str | None = None, **options: Any) -> None:
        self.config = resolve(EkfConfig, config, preset, options)
        super().__init__(header, start_pose, self.config)
        # id -> sightings [(step, bearing), ...]; the first is the anchor
        self._candidates: dict[int, list[tuple[int, float]]] = {}
        self.n_reanchored = 0
        # why candidates seen again were not initialised: their rays do not cross in front of
        # both poses, or the KL divergence is above init_kl_max
        self.n_rejected = {"behind": 0, "kl": 0}

    def _triangulation_test(self, clone_off: np.ndarray, z1: np.ndarray, z2: np.ndarray
                            ) -> dict[str, np.ndarray]:
        """Triangulate candidates from their clones and the current pose; Bailey's test."""
        x, P = self.filter.x, self.filter.P
        m = len(z1)
        sigma2 = self.filter.bearing_sigma_rad ** 2
        ui = np.empty((m, 6), np.int64)                       # the clone's states, the robot's
        ci = ui[:, :3]
        np.add(clone_off[:, None], _R3, out=ci)
        ui[:, 3:] = _R3
        cov_u = np.zeros((m, 8, 8))
        cov_u[:, :6, :6] = P[ui[:, :, None], ui[:, None, :]]
        cov_u[:, 6, 6] = cov_u[:, 7, 7] = sigma2
        inputs = np.empty((m, 8))
        inputs[:, :6] = x[ui]
        inputs[:, 6], inputs[:, 7] = z1, z2
        pts, jac, kl = triangulation_kl(inputs, cov_u)
        # depth along both rays (in front of the robot at both sightings)
        a1 = inputs[:, 2] + z1
        a2 = x[2] + z2
        d1 = pts - inputs[:, :2]
        d2 = pts - x[:2]
        front = ((d1[:, 0] * np.cos(a1) + d1[:, 1] * np.sin(a1) > 0)
                 & (d2[:, 0] * np.cos(a2) + d2[:, 1] * np.sin(a2) > 0))
        parallax = np.abs(angle_residual(a2, a1))
        jz = jac[:, :, 6:8]                                   # d point / d (z1, z2)
        return {"points": pts, "jac": jac, "kl": kl, "front": front & np.isfinite(pts).all(1),
                "parallax": parallax, "noise_cov": sigma2 * (jz @ jz.transpose(0, 2, 1)),
                "clone_index": ci}

    def _initialise(self, ids: np.ndarray, test: dict[str, np.ndarray], sel: np.ndarray) -> None:
        """Add the selected candidates' landmarks with their cross-covariances, then apply
        their stored intermediate bearings (taken from the clones) in one batched update."""
        m = int(np.count_nonzero(sel))
        ci = test["clone_index"][sel]                         # (m, 3)
        idx, inv = np.unique(np.concatenate([np.arange(3), ci.ravel()]), return_inverse=True)
        pose_cols = inv[:3]
        clone_cols = inv[3:].reshape(m, 3)
        jac = test["jac"][sel]
        g = np.zeros((2 * m, len(idx)))
        rows = 2 * np.arange(m)[:, None] + np.arange(2)       # (m, 2)
        g[rows[:, :, None], clone_cols[:, None, :]] += jac[:, :, 0:3]
        g[rows[:, :, None], np.broadcast_to(pose_cols, (m, 3))[:, None, :]] += jac[:, :, 3:6]
        noise = np.zeros((2 * m, 2 * m))
        noise[rows[:, :, None], rows[:, None, :]] = test["noise_cov"][sel]
        new_ids = ids[sel].tolist()
        self._add_blocks([(BLOCK_LM, i) for i in new_ids], test["points"][sel].ravel(), idx, g,
                         noise)
        later = [(i, ts, zs) for i in new_ids for ts, zs in self._candidates.pop(i)[1:]]
        if later:
            self._gated_update(np.array([self._offset[(BLOCK_CLONE, ts)] for _, ts, _ in later],
                                        np.int64),
                               np.full(len(later), 2, np.int64),
                               np.array([self._offset[(BLOCK_LM, i)] for i, _, _ in later],
                                        np.int64),
                               np.array([zs for _, _, zs in later]))

    def _gaussian_enough(self, features: np.ndarray, covs: np.ndarray) -> np.ndarray:
        """Bailey's test on the Euclidean form of inverse-depth candidates."""
        return invdepth_conversion_kl(features, covs) <= self.config.init_kl_max

    def _new_sightings(self, t: int, ids: np.ndarray, z: np.ndarray) -> None:
        if self.config.candidates == "inverse-depth":
            self._add_inverse_depth(ids, z)
            self._convert(self._gaussian_enough)
            return
        cands = self._candidates
        ids_l, z_l = ids.tolist(), z.tolist()
        seen = [n for n, i in enumerate(ids_l) if i in cands]       # positions of candidates
        restart = [n for n, i in enumerate(ids_l) if i not in cands]
        extend = []
        if seen:
            first = [cands[ids_l[n]][0] for n in seen]
            anchor_t = np.array([f[0] for f in first], np.int64)
            clone_off = np.array([self._offset[(BLOCK_CLONE, f[0])] for f in first], np.int64)
            test = self._triangulation_test(clone_off, np.array([f[1] for f in first]),
                                            z[seen])
            front = test["front"]
            ready = front & (test["kl"] <= self.config.init_kl_max)
            bad = (~front & (test["parallax"] > self.config.inconsistent_parallax_rad)) \
                | ((t - anchor_t) >= self.config.max_pending_steps)
            bad &= ~ready
            n_front, n_ready = int(np.count_nonzero(front)), int(np.count_nonzero(ready))
            self.n_rejected["behind"] += len(seen) - n_front
            self.n_rejected["kl"] += n_front - n_ready         # ready implies front
            self.n_reanchored += int(np.count_nonzero(bad))
            if n_ready:
                self._initialise(ids[seen], test, ready)
            for n, b, r in zip(seen, bad.tolist(), ready.tolist()):
                if b:
                    restart.append(n)
                elif not r:
                    extend.append(n)
            restart.sort()
        for n in restart:
            cands[ids_l[n]] = [(t, z_l[n])]
        for n in extend:
            cands[ids_l[n]].append((t, z_l[n]))
        if (restart or extend) and (BLOCK_CLONE, t) not in self._sizes:
            self.filter.check_room(3, "a pose clone")
            self.filter.clone(_R3)
            self._sizes[(BLOCK_CLONE, t)] = 3
            self._rebuild()
        used = {ts for sightings in self._candidates.values() for ts, _ in sightings}
        self._remove_blocks([k for k in self._sizes if k[0] == BLOCK_CLONE and k[1] not in used])

    def _landmarks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        ids, xy, cov, _ = super()._landmarks()
        pending = sorted(self._candidates) + sorted(k[1] for k in self._sizes if k[0] == BLOCK_IDP)
        return ids, xy, cov, {"pending": pending, "reanchored": self.n_reanchored,
                              "converted": self.n_converted, **self._rho_prior_info(),
                              **self._anchor_info(),
                              **{f"init_rejected_{k}": v for k, v in self.n_rejected.items()}}


class InverseDepthEkfMapper(RhoPriorMixin, EkfSlam):
    """Bearing-only EKF-SLAM with undelayed inverse-depth features (``ekf-invdepth``).

    Parameters
    ----------
    header : StreamHeader
    start_pose : (x_m, y_m, psi_rad)
    config : InverseDepthConfig, optional
        Or ``preset`` (``InverseDepthConfig.PRESETS``) and its fields as keyword options;
        never both.
    """

    def __init__(self, header: StreamHeader, *, start_pose: tuple[float, float, float] =
                 (0.0, 0.0, 0.0), config: InverseDepthConfig | None = None,
                 preset: str | None = None, **options: Any) -> None:
        self.config = resolve(InverseDepthConfig, config, preset, options)
        super().__init__(header, start_pose, self.config)
        self._anchor: dict[int, tuple[float, float, float]] = {}  # id -> x, y, ray angle
        self._baseline: dict[int, float] = {}  # feature id -> metres across its ray

    def _new_sightings(self, t: int, ids: np.ndarray, z: np.ndarray) -> None:
        for i, zi in zip(ids.tolist(), z.tolist()):  # a new anchor (first sighting, restart)
            dr = self._reach.pose
            self._anchor[i] = (dr[0], dr[1], dr[2] + zi)
            self._baseline[i] = 0.0
        self._add_inverse_depth(ids, z)
        self._convert(self._linear_enough)

    def step(self, step: Step) -> None:
        """As :meth:`EkfSlam.step`; and, for each feature sighted, the largest baseline so far
        across its anchor ray (metres, ``_baseline``), measured on the odometry alone (the
        dead-reckoned pose ``_reach.pose``): the parallax that can give the feature a depth.
        It does not come from the filter's estimate, which its own updates move."""
        super().step(step)
        dr = self._reach.pose
        for i in step.landmark_ids.tolist():
            a = self._anchor.get(i)
            if a is not None:
                perp = abs(math.cos(a[2]) * (dr[1] - a[1])
                           - math.sin(a[2]) * (dr[0] - a[0]))
                self._baseline[i] = max(self._baseline[i], perp)

    def _linear_enough(self, features: np.ndarray, covs: np.ndarray) -> np.ndarray:
        """Civera's linearity index ``4 sigma_d / d |cos alpha|`` below ``linearity_max``."""
        px, py = self.filter.x[:2].tolist()
        th, rho = features[:, 2], features[:, 3]
        ct, st = np.cos(th), np.sin(th)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):   # rho <= 0: out
            dx = features[:, 0] + ct / rho - px        # the point a + m / rho, from the robot
            dy = features[:, 1] + st / rho - py
            d = np.sqrt(dx * dx + dy * dy)
            lin = 4.0 * (np.sqrt(covs[:, 3, 3]) / (rho * rho)) / d * np.abs((ct * dx + st * dy)
                                                                            / d)
        ready = (rho > 0) & (lin < self.config.linearity_max)
        kl_max = self.config.conversion_kl_max
        if kl_max is not None and np.any(ready):       # and Gaussian after the conversion
            ready[ready] = invdepth_conversion_kl(features[ready], covs[ready]) <= kl_max
        return ready

    def _landmarks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        ids, xy, cov, _ = super()._landmarks()
        keys, bi = self._idp_blocks()
        left_out: list[int] = []
        n_no_depth = 0
        if keys:
            x, P = self.filter.x, self.filter.P
            f = x[bi]
            # a feature's depth must come from the bearings (parallax), not from its prior:
            # the bearings must have at least halved the prior std. dev. of rho (from a
            # robot that never moves, or only turns, they carry no depth at all); with
            # relative_depth_check also sigma_rho / rho, the depth's relative std. dev.
            rho_sd = np.sqrt(np.clip(P[bi[:, 3], bi[:, 3]], 0, None))
            rho0, rho0_sd = self._rho_prior(keys)
            no_depth = rho_sd > 0.5 * rho0_sd
            if self.config.relative_depth_check:
                with np.errstate(divide="ignore", invalid="ignore"):
                    no_depth |= ~(rho_sd / np.abs(f[:, 3]) <= 0.5 * rho0_sd / rho0)
            # ... and the odometry must have moved the robot across the feature's ray by more
            # than the bearing noise subtends at the feature's depth (turning on the spot
            # gives the iterated update a spurious depth, never a baseline)
            base = np.array([self._baseline.get(k[1], 0.0) for k in keys])
            no_depth |= base * np.abs(f[:, 3]) < self.filter.bearing_sigma_rad
            ok = (f[:, 3] > 0) & ~no_depth
            left_out = sorted(k[1] for k, o in zip(keys, ok) if not o)
            n_no_depth = int(np.count_nonzero(no_depth))
            if np.any(ok):
                pts, jac = invdepth_to_xy(f[ok])
                b = bi[ok]
                c = jac @ P[b[:, :, None], b[:, None, :]] @ jac.transpose(0, 2, 1)
                ids = np.concatenate([ids, [k[1] for k, o in zip(keys, ok) if o]]).astype(
                    np.int64)
                xy = np.concatenate([xy, pts])
                cov = np.concatenate([cov, c])
        return ids, xy, cov, {"inverse_depth": int(len(keys)), "left_out": left_out,
                              "left_out_no_depth": n_no_depth, "converted": self.n_converted,
                              **self._rho_prior_info()}


__all__ = ["EkfMapper", "InverseDepthEkfMapper"]
