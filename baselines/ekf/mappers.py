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
  point with ``h N = 0`` (:meth:`_EkfSlam._constrain`);
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
    (``info["restarted"]``).

Inverse depth, ``ekf-invdepth``
    A first sighting enters the state at once as ``[x0, y0, theta, rho]`` (anchor = robot
    position, ``theta = psi + z``, ``rho ~ N(rho_init, rho_sigma^2)``); it is converted to a
    Euclidean ``[x, y]`` block once Civera's linearity index ``4 sigma_d / d |cos alpha|``
    falls below ``linearity_max``. Features still in inverse depth are reported through the
    same conversion by ``estimate()``; left out are those with ``rho <= 0`` and those whose
    depth the bearings have not determined (the std. dev. of ``rho`` still above half its
    prior's: no parallax yet, e.g. from a robot that has not moved). The prior on
    ``rho`` makes it inexact on noise-free data and it is less consistent than ``ekf``.

Iterated update (``iterations > 1``)
    Gauss-Newton on the prior and the step's bearings
    (:meth:`~baselines.ekf.filter.BearingEkf.update`); the iterates use the model's own
    Jacobians, the last step the observability-constrained ones. It helps after a long blind
    turn, when one update has to move the heading by tens of degrees.
"""

from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np
from scipy.stats import chi2

from bomgraph.angles import angle_residual, wrap_angle
from bomgraph.config import resolve
from bomgraph.errors import ConfigError
from bomgraph.mapper import MapEstimate
from bomgraph.stream import Step, StreamHeader

from .config import BearingEkfConfig, EkfConfig, InverseDepthConfig
from .filter import BearingEkf, BearingModel, FilterNumericalError, JacobianRows
from .models import (bearing_and_jacobian, invdepth_bearing_and_jacobian,
                     invdepth_conversion_kl, invdepth_to_xy, second_order_variance,
                     triangulation_kl)

_LM, _CLONE, _IDP = "lm", "clone", "idp"
_CHI2_1_MEDIAN = float(chi2.ppf(0.5, 1))
_SIZE = {_LM: 2, _CLONE: 3, _IDP: 4}


def _take_rows(parts: JacobianRows, keep: np.ndarray) -> JacobianRows:
    """The rows ``keep`` (bool, (k,)) of a sparse Jacobian, renumbered ``0..count(keep)-1``."""
    new = np.cumsum(keep) - 1
    out = []
    for rows, cols, j in parts:
        m = keep[rows]
        if m.any():
            out.append((new[rows[m]], cols[m], j[m]))
    return out


class _EkfSlam:
    """Shared machinery: state layout, predict, gated batch update, trajectory, estimate."""

    def __init__(self, header: StreamHeader, start_pose: tuple[float, float, float],
                 config: BearingEkfConfig) -> None:
        self._header = header
        self.filter = BearingEkf(np.asarray(start_pose, dtype=float),
                                 np.diag(np.asarray(config.initial_pose_sigma, float) ** 2),
                                 header.bearing_sigma_rad, observability_constrained=True,
                                 max_state=int(config.max_state),
                                 limit_hint=" (option max_state; raise it with --option "
                                            "max_state=N, the covariance takes 8 N^2 bytes)")
        p = config.gate_probability
        self._gate = float(chi2.ppf(p, 1)) if p < 1 else np.inf
        self._iterations = int(config.iterations)
        rng_m = header.sensor_range_m
        self.rho_init = config.rho_init_per_m or (2.0 / rng_m if rng_m else 0.1)
        self.rho_sigma = config.rho_sigma_per_m or (1.0 / rng_m if rng_m else 0.5)
        try:
            representable = all(math.isfinite(v) and v > 0 for v in (
                self.rho_init, self.rho_sigma ** 2, 1.0 / self.rho_init ** 2))
        except (OverflowError, ZeroDivisionError):
            representable = False
        if not representable and self._uses_inverse_depth(config):
            raise ConfigError(f"the inverse-depth prior rho = {self.rho_init:g} +- "
                              f"{self.rho_sigma:g} per m (from sensor_range_m = {rng_m:g}) "
                              f"cannot be represented; set the options rho_init_per_m and "
                              f"rho_sigma_per_m")
        self.n_converted = 0
        self.n_restarted = 0
        self._restart_after = config.restart_after_gated or math.inf
        self._gated_run: dict[int, int] = {}          # inverse-depth feature -> gated in a row
        self._sizes: dict[tuple[str, int], int] = {}
        self._offset: dict[tuple[str, int], int] = {}
        self._last_t: int | None = None
        self._pose_t: list[int] = []
        self._poses: list[np.ndarray] = []
        self._pose_covs: list[np.ndarray] = []
        self.n_gated = 0
        self.n_updates = 0
        self.n_failures = 0
        self.last_failure = ""
        self._t = -1
        self.n_nonlinear = 0
        self._max_nonlin = float(config.max_bearing_nonlinearity)
        self._decorr = (None if config.decorrelation_rad is None
                        else float(config.decorrelation_rad))
        self._last_used: dict[int, np.ndarray] = {}   # landmark -> pose of its last bearing
        self._adaptive = bool(config.adaptive_sigma)
        self._nis: list[float] = []
        self.noise_scale = 1.0

    @staticmethod
    def _uses_inverse_depth(config: BearingEkfConfig) -> bool:
        return getattr(config, "candidates", "inverse-depth") == "inverse-depth"

    # -- layout -----------------------------------------------------------------------------
    def _rebuild(self) -> None:
        off = 3
        self._offset = {}
        for key, size in self._sizes.items():
            self._offset[key] = off
            off += size
        if off != self.filter.dim:
            raise RuntimeError("internal: state layout and filter size disagree")

    def _add_blocks(self, keys: list[tuple[str, int]], value: np.ndarray, idx: np.ndarray,
                    jac: np.ndarray, noise_cov: np.ndarray) -> None:
        is_angle = np.zeros(len(value), bool)
        pos = 0
        for key in keys:
            size = _SIZE[key[0]]
            if key[0] in (_CLONE, _IDP):
                is_angle[pos + 2] = True
            pos += size
        self.filter.augment(value, idx, jac, noise_cov, is_angle)
        for key in keys:
            self._sizes[key] = _SIZE[key[0]]
        self._rebuild()

    def _remove_blocks(self, keys: list[tuple[str, int]]) -> None:
        if not keys:
            return
        idx = np.concatenate([self._offset[k] + np.arange(self._sizes[k]) for k in keys])
        self.filter.remove(idx)
        for k in keys:
            del self._sizes[k]
        self._rebuild()

    def _block_index(self, offsets: np.ndarray, size: int) -> np.ndarray:
        return np.asarray(offsets, np.int64)[:, None] + np.arange(size)

    # -- measurement model ------------------------------------------------------------------
    def _model(self, pose_off: np.ndarray, kinds: np.ndarray, offsets: np.ndarray,
               constrained: bool = True,
               at: tuple[np.ndarray, np.ndarray, JacobianRows] | None = None) -> BearingModel:
        """The bearing model for :meth:`BearingEkf.update`, memoised on ``x``.

        Bearings are taken from the poses at ``pose_off`` (0: the robot, else a clone) to the
        blocks at ``offsets`` of size ``kinds`` (2: Euclidean landmark, 4: inverse-depth
        feature). The returned function maps ``x`` to ``h (k,)`` and the Jacobian's nonzero
        blocks ``[(rows (m,), columns (m, s), values (m, s))]``, one per kind
        (:data:`~baselines.ekf.filter.JacobianRows`; observability-constrained when
        ``constrained``). ``at = (x, h, rows)`` seeds the memo with the model's values at
        ``x`` (already computed).
        """
        k = len(offsets)
        groups = []
        for size, fn in ((2, bearing_and_jacobian), (4, invdepth_bearing_and_jacobian)):
            sel = kinds == size
            if sel.any():
                cols = np.concatenate([self._block_index(pose_off[sel], 3),
                                       self._block_index(offsets[sel], size)], 1)
                groups.append((np.flatnonzero(sel), cols, fn))
        memo: dict[str, Any] = {}
        if at is not None:
            memo.update(x=at[0].copy(), h=at[1], parts=at[2])

        def both(x: np.ndarray) -> tuple[np.ndarray, JacobianRows]:
            if "x" in memo and np.array_equal(memo["x"], x):
                return memo["h"], memo["parts"]
            h = np.empty(k)
            parts = []
            for rows, cols, fn in groups:
                v = x[cols]
                h[rows], j = fn(v[:, :3], v[:, 3:])
                if constrained:
                    j = self._constrain(j, cols)
                parts.append((rows, cols, j))
            memo.update(x=x.copy(), h=h, parts=parts)
            return h, parts

        return both

    def _constrain(self, jac: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Jacobian rows that satisfy ``h N = 0`` (observability-constrained EKF).

        ``N`` (n, 3) spans global translation and rotation of the linearised system
        (:attr:`BearingEkf.nullspace`); keeping ``H N = 0`` at every step keeps them
        unobservable, so the filter gains no spurious information about them (Huang, Mourikis
        and Roumeliotis, IJRR 2010). A row to a Euclidean landmark keeps its direction and is
        linearised at the closest point that satisfies the constraint: with ``u`` the unit
        vector of the current ray and ``a_l``, ``a_p`` the positions the landmark's and the
        pose's rows of ``N`` are anchored at, ``h_l = J u / L``, ``h_p = -h_l``,
        ``h_psi = -1`` with ``L = u . (a_l - a_p)``. Other rows (inverse-depth features, or
        ``L <= 0``) are projected, ``h <- h - (h N_S)(N_S^T N_S)^-1 N_S^T`` over their own
        columns ``S``.

        Parameters
        ----------
        jac : array of shape (m, s)
            Rows over the columns ``cols`` (pose first, then the landmark block).
        cols : int array of shape (m, s)

        Returns
        -------
        ndarray of shape (m, s)
        """
        N = self.filter.nullspace
        out = jac.copy()
        project = np.ones(len(jac), bool)
        if jac.shape[1] == 5:
            hx, hy = jac[:, 3], jac[:, 4]                          # J u / |r|
            norm = np.sqrt(hy * hy + hx * hx)
            ux, uy = hy / norm, -hx / norm
            length = (ux * (N[cols[:, 4], 2] - N[cols[:, 1], 2])
                      + uy * (N[cols[:, 0], 2] - N[cols[:, 3], 2]))
            ok = length > 1e-6
            if ok.all():
                out[:, 3] = -uy / length
                out[:, 4] = ux / length
                out[:, 0] = -out[:, 3]
                out[:, 1] = -out[:, 4]
                return out
            out[ok, 3] = -uy[ok] / length[ok]
            out[ok, 4] = ux[ok] / length[ok]
            out[ok, 0:2] = -out[ok, 3:5]
            project = ~ok
        if project.any():
            ns = N[cols[project]]                                # (m, s, 3)
            h = jac[project]
            gram = np.einsum("msi,msj->mij", ns, ns)
            rhs = np.einsum("ms,msi->mi", h, ns)[..., None]
            try:
                coef = np.linalg.solve(gram, rhs)[..., 0]
            except np.linalg.LinAlgError:     # a degenerate nullspace (e.g. after a huge step)
                coef = (np.linalg.pinv(gram) @ rhs)[..., 0]
            out[project] = h - np.einsum("msi,mi->ms", ns, coef)
        return out

    def _gated_update(self, pose_off: np.ndarray, kinds: np.ndarray, offsets: np.ndarray,
                      z: np.ndarray, inflation: np.ndarray | None = None) -> np.ndarray:
        """Gate each bearing on its own NIS, then one batched filterpy update with the rest.

        The NIS of bearing ``i`` is ``y_i^2 / (H_i P H_i^T + var_i)`` with the wrapped
        innovation ``y_i`` and the variance ``var_i`` of
        :func:`~baselines.ekf.models.second_order_variance`; it is compared with the
        chi-square 1-dof quantile. Bearings past ``max_bearing_nonlinearity`` are not used.
        With ``iterations > 1`` the iterates of the iterated update use the model's own
        Jacobians and only the last step the observability-constrained ones. ``inflation``
        (k,) multiplies each kept bearing's variance in the update (not in the gate; see
        :meth:`_decorrelation`).

        Returns
        -------
        ndarray of shape (k,), bool
            The bearings that failed the gate.
        """
        model = self._model(pose_off, kinds, offsets)
        x, P = self.filter.x, self.filter.P
        h, parts = model(x)
        var = np.full(len(z), self.filter.bearing_sigma_rad ** 2)
        index = np.zeros(len(z))
        hph = np.zeros(len(z))
        for rows, cols, j in parts:
            block = P[cols[:, :, None], cols[:, None, :]]          # (m, s, s)
            hph[rows] = np.einsum("mi,mij,mj->m", j, block, j)
            var[rows], index[rows] = second_order_variance(x[cols], block,
                                                           self.filter.bearing_sigma_rad)
        usable = index <= self._max_nonlin
        innovation = np.asarray(angle_residual(z, h))
        nis = innovation ** 2 / (hph + var)
        if self._adaptive:
            # the stream's sigma may be a MAD estimate (too small when there are outliers) or
            # a generous one: scale the bearing variance by the median NIS of the bearings
            # seen so far against the chi-square 1-dof median (never below the stream's)
            self._nis.extend(nis[usable].tolist())
            scale = max(1.0, float(np.median(self._nis)) / _CHI2_1_MEDIAN) \
                if len(self._nis) >= 20 else 1.0
            var = var * scale
            nis = nis * (hph + var / scale) / (hph + var)
            self.noise_scale = scale
        gated = (nis > self._gate) & usable
        self.n_nonlinear += int(np.count_nonzero(~usable))
        self.n_gated += int(np.count_nonzero(gated))
        keep = usable & ~gated
        if keep.any():
            if keep.all():
                kept = model
            else:                           # the kept rows, already evaluated at this x
                kept = self._model(pose_off[keep], kinds[keep], offsets[keep],
                                   at=(x, h[keep], _take_rows(parts, keep)))
            plain = (self._model(pose_off[keep], kinds[keep], offsets[keep], constrained=False)
                     if self._iterations > 1 else None)
            var_upd = var[keep] if inflation is None else var[keep] * inflation[keep]
            try:
                self.filter.update(z[keep], kept, var_upd, self._iterations, plain,
                                   innovation=innovation[keep])
            except FilterNumericalError as exc:         # the state is as before the update
                self.n_failures += 1
                self.last_failure = f"step {self._t}: {exc}"
                return np.zeros(len(z), bool)
            self.n_updates += int(np.count_nonzero(keep))
        return gated

    # -- inverse-depth features ---------------------------------------------------------------
    def _add_inverse_depth(self, ids: np.ndarray, z: np.ndarray) -> None:
        """Add first sightings as inverse-depth features anchored at the robot (Civera):
        ``[x, y, psi + z, rho_init]`` with ``rho ~ N(rho_init, rho_sigma^2)``."""
        if ids.size:
            m = ids.size
            self.filter.check_room(4 * m)
            x = self.filter.x
            value = np.column_stack([np.broadcast_to(x[:2], (m, 2)), wrap_angle(x[2] + z),
                                     np.full(m, self.rho_init)]).ravel()
            g = np.tile(np.vstack([np.eye(3), np.zeros((1, 3))]), (m, 1))      # (4m, 3)
            noise = np.tile([0.0, 0.0, self.filter.bearing_sigma_rad ** 2,
                             self.rho_sigma ** 2], m)                           # diagonal
            self._add_blocks([(_IDP, int(i)) for i in ids], value, np.arange(3), g, noise)

    def _idp_blocks(self) -> tuple[list[tuple[str, int]], np.ndarray]:
        keys = [k for k in self._sizes if k[0] == _IDP]
        bi = self._block_index(np.array([self._offset[k] for k in keys], np.int64), 4)
        return keys, bi

    def _convert(self, ready: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> None:
        """Replace the inverse-depth features that ``ready(features (k, 4), covs (k, 4, 4))``
        selects by Euclidean ``[x, y]`` blocks (the exact linear map of their Gaussian)."""
        keys, bi = self._idp_blocks()
        if not keys:
            return
        x, P = self.filter.x, self.filter.P
        f = x[bi]
        sel = np.flatnonzero(ready(f, P[bi[:, :, None], bi[:, None, :]]) & (f[:, 3] > 0))
        if sel.size == 0:
            return
        pts, jac = invdepth_to_xy(f[sel])
        m = sel.size
        idx = bi[sel].ravel()
        g = np.zeros((2 * m, 4 * m))
        rows = 2 * np.arange(m)[:, None] + np.arange(2)
        cols = 4 * np.arange(m)[:, None] + np.arange(4)
        g[rows[:, :, None], cols[:, None, :]] = jac
        old = [keys[s] for s in sel]
        self._add_blocks([(_LM, k[1]) for k in old], pts.ravel(), idx, g,
                         np.zeros((2 * m, 2 * m)))
        self._remove_blocks(old)
        for k in old:
            self._gated_run.pop(k[1], None)
        self.n_converted += m

    def _decorrelation(self, ids: np.ndarray, kinds: np.ndarray,
                       offsets: np.ndarray) -> np.ndarray | None:
        """Variance factors for bearings whose errors are correlated with the last one used.

        Bearing errors of real sensors are serially correlated: sightings of a landmark from
        nearly the same place and heading share much of their error (MRCLAM6 at 0.1 m / 10 deg
        keyframes: correlation 0.66 between sightings less than 0.05 rad of parallax plus
        turn apart, 0.38 at 0.05-0.1, 0.26 at 0.1-0.2, 0.11 beyond 0.4; docs/measurements.md).
        An EKF that takes them as independent gains information in proportion to how often
        the stream was keyframed, not to how much the geometry changed, and becomes
        overconfident on dense streams. Here a bearing to landmark ``i`` is weighted by the
        change of geometry since the last bearing of ``i`` that was used: ``D = (parallax +
        |turn|) / decorrelation_rad``, the parallax being the angle at the landmark's
        estimate between the two robot positions (scale-free); its variance is multiplied by
        ``1 / D`` when ``D < 1``, so that however the path is keyframed, one decorrelation
        angle of change brings about one bearing's information. None (the ``paper``
        default): every bearing counts in full (the simulation's noise is white).
        """
        if self._decorr is None:
            return None
        x = self.filter.x
        pose = x[:3]
        out = np.ones(len(ids))
        for n, (i, kind, off) in enumerate(zip(ids.tolist(), kinds.tolist(), offsets.tolist())):
            last = self._last_used.get(i)
            if last is None:
                continue
            if kind == 2:
                lm = x[off:off + 2]
            elif x[off + 3] > 0:
                lm = invdepth_to_xy(x[None, off:off + 4])[0][0]
            else:
                lm = None
            parallax = 0.0
            if lm is not None:
                a = math.atan2(pose[1] - lm[1], pose[0] - lm[0])
                b = math.atan2(last[1] - lm[1], last[0] - lm[0])
                parallax = abs(float(angle_residual(a, b)))
            change = (parallax + abs(float(angle_residual(pose[2], last[2])))) / self._decorr
            if change < 1.0:
                out[n] = 1.0 / max(change, 1e-9)
        return out

    def _update_mapped(self, ids: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Gate and apply the bearings to landmarks in the state; returns the mask of those."""
        found = [(n, kind, off) for n, i in enumerate(ids.tolist()) for kind in (_LM, _IDP)
                 if (off := self._offset.get((kind, i))) is not None]
        in_state = np.zeros(len(ids), bool)
        if found:
            rows, kind_names, offs = zip(*found)
            in_state[list(rows)] = True
            kinds = np.array([_SIZE[k] for k in kind_names], np.int64)
            offsets = np.array(offs, np.int64)
            seen = ids[in_state]
            inflation = self._decorrelation(seen, kinds, offsets)
            gated = self._gated_update(np.zeros(len(found), np.int64), kinds, offsets,
                                       z[in_state], inflation)
            if inflation is not None:
                pose = self.filter.x[:3].copy()
                for i, g in zip(seen.tolist(), gated.tolist()):
                    if not g:
                        self._last_used[i] = pose
            # an inverse-depth feature gated again and again was started from an outlier:
            # drop it; the current sighting starts it again (as a new sighting)
            restart = []
            for i, kind, g in zip(ids[in_state].tolist(), kind_names, gated.tolist()):
                if kind == _IDP:
                    run_length = self._gated_run.get(i, 0) + 1 if g else 0
                    self._gated_run[i] = run_length
                    if run_length >= self._restart_after:
                        restart.append(i)
            if restart:
                self._remove_blocks([(_IDP, i) for i in restart])
                for i in restart:
                    del self._gated_run[i]
                in_state &= ~np.isin(ids, restart)
                self.n_restarted += len(restart)
        return in_state

    # -- the Mapper protocol ----------------------------------------------------------------
    def step(self, step: Step) -> None:
        """Predict with the step's odometry, update with its bearings, grow the map."""
        if self._last_t is not None and step.t <= self._last_t:
            raise ConfigError(f"steps must come in increasing t: got t = {step.t} after "
                              f"t = {self._last_t}")
        self._t = step.t
        if step.odom is not None:
            try:
                self.filter.predict(step.odom, step.odometry_sigma(self._header))
            except FilterNumericalError as exc:
                raise FilterNumericalError(f"step {step.t}: {exc}") from None
        ids, z = step.landmark_ids, step.bearings_rad
        if ids.size:
            in_state = self._update_mapped(ids, z)
            self._new_sightings(step.t, ids[~in_state], z[~in_state])
        self._last_t = step.t
        self._pose_t.append(step.t)
        self._poses.append(self.filter.x[:3].copy())
        self._pose_covs.append(self.filter.P[:3, :3].copy())

    def _new_sightings(self, t: int, ids: np.ndarray, z: np.ndarray) -> None:
        raise NotImplementedError

    def _landmarks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Ids, positions ``(n, 2)`` and covariances ``(n, 2, 2)`` of the reportable landmarks."""
        keys = [k for k in self._sizes if k[0] == _LM]
        ids = np.array([k[1] for k in keys], np.int64)
        bi = self._block_index(np.array([self._offset[k] for k in keys], np.int64), 2)
        x, P = self.filter.x, self.filter.P
        return ids, x[bi].reshape(-1, 2), P[bi[:, :, None], bi[:, None, :]].reshape(-1, 2, 2), {}

    def estimate(self) -> MapEstimate:
        """The filtered map, the filtered trajectory (every step) and their covariances."""
        ids, xy, cov, info = self._landmarks()
        order = np.argsort(ids)
        info = dict(info)
        info.update(state_dim=self.filter.dim, gated_bearings=self.n_gated,
                    nonlinear_bearings=self.n_nonlinear, used_bearings=self.n_updates,
                    restarted=self.n_restarted)
        if self._adaptive:
            info["bearing_variance_scale"] = self.noise_scale
        if self.n_failures:
            info.update(update_failures=self.n_failures, last_failure=self.last_failure)
        if not self._poses:
            return MapEstimate.empty(reason="no steps yet", **info)
        if ids.size == 0:
            info["reason"] = "no landmark initialised yet"
        return MapEstimate(ids[order], xy[order], pose_t=np.array(self._pose_t),
                           poses=np.array(self._poses), landmark_cov=cov[order],
                           pose_cov=np.array(self._pose_covs), info=info)


class EkfMapper(_EkfSlam):
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
        ci = self._block_index(clone_off, 3)
        ui = np.concatenate([ci, np.broadcast_to(np.arange(3), (m, 3))], 1)   # (m, 6)
        cov_u = np.zeros((m, 8, 8))
        cov_u[:, :6, :6] = P[ui[:, :, None], ui[:, None, :]]
        cov_u[:, 6, 6] = cov_u[:, 7, 7] = self.filter.bearing_sigma_rad ** 2
        pose_c = x[ci]
        pose_r = np.broadcast_to(x[:3], (m, 3))
        pts, jac, kl = triangulation_kl(
            np.concatenate([pose_c, pose_r, z1[:, None], z2[:, None]], 1), cov_u)
        # depth along both rays (in front of the robot at both sightings)
        d1 = pts - pose_c[:, :2]
        d2 = pts - pose_r[:, :2]
        a1 = pose_c[:, 2] + z1
        a2 = pose_r[:, 2] + z2
        front = (np.einsum("mi,mi->m", d1, np.column_stack([np.cos(a1), np.sin(a1)])) > 0) \
            & (np.einsum("mi,mi->m", d2, np.column_stack([np.cos(a2), np.sin(a2)])) > 0)
        parallax = np.abs(angle_residual(a2, a1))
        return {"points": pts, "jac": jac, "kl": kl, "front": front & np.isfinite(pts).all(1),
                "parallax": parallax, "noise_cov": self.filter.bearing_sigma_rad ** 2
                * (jac[:, :, 6:7] @ jac[:, :, 6:7].transpose(0, 2, 1)
                   + jac[:, :, 7:8] @ jac[:, :, 7:8].transpose(0, 2, 1)),
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
        self._add_blocks([(_LM, i) for i in new_ids], test["points"][sel].ravel(), idx, g,
                         noise)
        later = [(i, ts, zs) for i in new_ids for ts, zs in self._candidates.pop(i)[1:]]
        if later:
            self._gated_update(np.array([self._offset[(_CLONE, ts)] for _, ts, _ in later],
                                        np.int64),
                               np.full(len(later), 2, np.int64),
                               np.array([self._offset[(_LM, i)] for i, _, _ in later],
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
        cand = np.array([i in self._candidates for i in ids.tolist()], bool)
        restart = ~cand
        extend = np.zeros(len(ids), bool)
        if np.any(cand):
            cid = ids[cand]
            first = [self._candidates[i][0] for i in cid.tolist()]
            anchor_t = np.array([f[0] for f in first], np.int64)
            z1 = np.array([f[1] for f in first])
            clone_off = np.array([self._offset[(_CLONE, int(a))] for a in anchor_t], np.int64)
            test = self._triangulation_test(clone_off, z1, z[cand])
            ready = test["front"] & (test["kl"] <= self.config.init_kl_max)
            self.n_rejected["behind"] += int(np.count_nonzero(~test["front"]))
            self.n_rejected["kl"] += int(np.count_nonzero(test["front"] & ~ready))
            bad = (~test["front"] & (test["parallax"] > self.config.inconsistent_parallax_rad)) \
                | ((t - anchor_t) >= self.config.max_pending_steps)
            bad &= ~ready
            self.n_reanchored += int(np.count_nonzero(bad))
            if np.any(ready):
                self._initialise(cid, test, ready)
            pos = np.flatnonzero(cand)
            restart[pos[bad]] = True
            extend[pos[~bad & ~ready]] = True
        for i, zi in zip(ids[restart].tolist(), z[restart].tolist()):
            self._candidates[i] = [(t, zi)]
        for i, zi in zip(ids[extend].tolist(), z[extend].tolist()):
            self._candidates[i].append((t, zi))
        if np.any(restart | extend) and (_CLONE, t) not in self._sizes:
            self._add_blocks([(_CLONE, t)], self.filter.x[:3].copy(), np.arange(3), np.eye(3),
                             np.zeros((3, 3)))
        used = {ts for sightings in self._candidates.values() for ts, _ in sightings}
        self._remove_blocks([k for k in self._sizes if k[0] == _CLONE and k[1] not in used])

    def _landmarks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        ids, xy, cov, _ = super()._landmarks()
        pending = sorted(self._candidates) + sorted(k[1] for k in self._sizes if k[0] == _IDP)
        return ids, xy, cov, {"pending": pending, "reanchored": self.n_reanchored,
                              "converted": self.n_converted,
                              **{f"init_rejected_{k}": v for k, v in self.n_rejected.items()}}


class InverseDepthEkfMapper(_EkfSlam):
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

    def _new_sightings(self, t: int, ids: np.ndarray, z: np.ndarray) -> None:
        self._add_inverse_depth(ids, z)
        self._convert(self._linear_enough)

    def _linear_enough(self, features: np.ndarray, covs: np.ndarray) -> np.ndarray:
        """Civera's linearity index ``4 sigma_d / d |cos alpha|`` below ``linearity_max``."""
        x = self.filter.x
        rho = features[:, 3]
        ok = rho > 0
        lin = np.full(len(rho), np.inf)
        if np.any(ok):
            sig_rho = np.sqrt(covs[ok, 3, 3])
            pts, _ = invdepth_to_xy(features[ok])
            d_vec = pts - x[:2]
            d = np.linalg.norm(d_vec, axis=1)
            m = np.column_stack([np.cos(features[ok, 2]), np.sin(features[ok, 2])])
            cos_a = np.einsum("ki,ki->k", m, d_vec) / d
            lin[ok] = 4.0 * (sig_rho / rho[ok] ** 2) / d * np.abs(cos_a)
        return lin < self.config.linearity_max

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
            # robot that never moves, or only turns, they carry no depth at all)
            rho_sd = np.sqrt(np.clip(P[bi[:, 3], bi[:, 3]], 0, None))
            no_depth = rho_sd > 0.5 * self.rho_sigma
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
                              "left_out_no_depth": n_no_depth, "converted": self.n_converted}


__all__ = ["EkfMapper", "InverseDepthEkfMapper"]
