"""The machinery both EKF mappers share (paper section IV, Exp. 2): the state layout of
landmarks, pose clones and inverse-depth features, the gated batch update with its
observability-constrained sparse bearing model, inverse-depth features and their conversion,
the trajectory and the estimate. The mappers (:mod:`baselines.ekf.mappers`) add the
initialisation of new landmarks; the measures against linearisation error and the state
limit are described there and in :mod:`baselines.ekf.filter`.
"""

from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np
from scipy.stats import chi2

from bomgraph.angles import angle_residual, wrap_angle
from bomgraph.errors import ConfigError
from bomgraph.geometry import arc_root
from bomgraph.mapper import MapEstimate
from bomgraph.method_limits import Reach, checked_header
from bomgraph.stream import Step, StreamHeader

from .coloured import ColouredBearingError, ray_directions
from .config import BearingEkfConfig
from .filter import BearingEkf, BearingModel, FilterNumericalError, JacobianRows
from .refusals import MAX_EKF_SIGMA, odometry_refusal, predict_substeps
from .models import (bearing_and_jacobian, invdepth_bearing_and_jacobian, invdepth_to_xy,
                     path_heading_noise, second_order_variance)
from .robust import BearingVariances
from .rows import feature_rows, landmark_rows, take_rows
from .variance_scale import InnovationVarianceScale

#: the kinds of state block, first in each block's key ``(kind, id)``: a landmark's xy, a pose
#: clone, an inverse-depth feature, its anchor bearing's error (:mod:`.anchor`), a coloured bias.
BLOCK_LM, BLOCK_CLONE, BLOCK_IDP, BLOCK_ANCHOR, BLOCK_BIAS = "lm", "clone", "idp", "anchor", "bias"
_SIZE = {BLOCK_LM: 2, BLOCK_CLONE: 3, BLOCK_IDP: 4, BLOCK_ANCHOR: 1, BLOCK_BIAS: 1}
_RANGE = np.arange(4)


class EkfSlam:
    """Shared machinery: state layout, predict, gated batch update, trajectory, estimate."""

    def __init__(self, header: StreamHeader, start_pose: tuple[float, float, float],
                 config: BearingEkfConfig) -> None:
        self._header = checked_header(header, "the EKF", MAX_EKF_SIGMA)  # name file, line
        self._reach = Reach(start_pose, "the EKF", MAX_EKF_SIGMA)
        self.filter = BearingEkf(self._reach.start_pose,
                                 np.diag(np.asarray(config.initial_pose_sigma, float) ** 2),
                                 header.bearing_sigma_rad,
                                 observability_constrained=config.jacobians != "plain",
                                 max_state=int(config.max_state),
                                 limit_hint=" (option max_state; raise it with --option "
                                            "max_state=N, the covariance takes 8 N^2 bytes)")
        self._jacobians = config.jacobians
        self._max_turn = config.max_predict_turn_rad
        self._path_noise = bool(config.path_heading_noise)
        p = config.gate_probability
        self._gate = float(chi2.ppf(p, 1)) if p < 1 else np.inf
        self._iterations = int(config.iterations)
        wide = config.wide_prior_heading_sd_rad
        self._wide_var = None if wide is None else float(wide) ** 2
        self._wide_iterations = int(config.wide_prior_iterations)
        rng_m = self.header_range_m = header.sensor_range_m
        self.rho_init = config.rho_init_per_m or (2.0 / rng_m if rng_m else 0.1)
        self.rho_sigma = config.rho_sigma_per_m or (1.0 / rng_m if rng_m else 0.5)
        try:
            representable = all(math.isfinite(v) and v > 0 for v in (
                self.rho_init, self.rho_sigma ** 2, 1.0 / self.rho_init ** 2))
        except (OverflowError, ZeroDivisionError):
            representable = False
        if not representable and self._uses_inverse_depth(config) and config.rho_prior == "range":
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
        self._idp: tuple[list[tuple[str, int]], np.ndarray] | None = None
        self._mapped: dict[int, tuple[str, int]] = {}
        self._last_t: int | None = None
        # the filtered trajectory, in buffers that double when full
        self._n_poses = 0
        self._pose_t = np.zeros(64, np.int64)
        self._poses = np.zeros((64, 3))
        self._pose_covs = np.zeros((64, 3, 3))
        self.n_gated = 0
        self.n_updates = 0
        self.n_failures = 0
        self.last_failure = ""
        self._t = -1
        self.n_nonlinear = 0
        self._max_nonlin = float(config.max_bearing_nonlinearity)
        # the per-landmark coloured bearing error (off in the paper's setup)
        self._coloured = ColouredBearingError(header.bearing_sigma_rad,
                                              float(config.correlated_fraction),
                                              float(config.correlation_length_rad))
        self._white_sigma = self._coloured.white_sigma_rad
        self._scale = (InnovationVarianceScale(self._white_sigma)
                       if config.bearing_variance_scale == "innovation" else None)
        self._variances = BearingVariances(self._scale, config.robust_update,
                                           config.robust_k, self._gate)

    @staticmethod
    def _uses_inverse_depth(config: BearingEkfConfig) -> bool:
        return getattr(config, "candidates", "inverse-depth") == "inverse-depth"

    # -- layout -----------------------------------------------------------------------------
    def _rebuild(self) -> None:
        off = 3
        self._offset = {}
        self._idp = None
        self._mapped = {}         # landmark id -> (kind, offset) of its landmark or feature
        for key, size in self._sizes.items():
            self._offset[key] = off
            if key[0] == BLOCK_LM or key[0] == BLOCK_IDP:
                self._mapped[key[1]] = (key[0], off)
            off += size
        if off != self.filter.dim:
            raise RuntimeError("internal: state layout and filter size disagree")

    def _add_blocks(self, keys: list[tuple[str, int]], value: np.ndarray, idx: np.ndarray,
                    jac: np.ndarray, noise_cov: np.ndarray) -> None:
        is_angle = np.zeros(len(value), bool)
        pos = 0
        for key in keys:
            size = _SIZE[key[0]]
            if key[0] in (BLOCK_CLONE, BLOCK_IDP):
                is_angle[pos + 2] = True
            pos += size
        self.filter.check_room(len(value), f"{len(keys)} new landmark or pose blocks")
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
               at: tuple[np.ndarray, np.ndarray, JacobianRows] | None = None,
               bias_off: np.ndarray | None = None) -> BearingModel:
        """The bearing model for :meth:`BearingEkf.update`, memoised on ``x``.

        Bearings are taken from the poses at ``pose_off`` (0: the robot, else a clone) to the
        blocks at ``offsets`` of size ``kinds`` (2: Euclidean landmark, 4: inverse-depth
        feature). The returned function maps ``x`` to ``h (k,)`` and the Jacobian's nonzero
        blocks ``[(rows (m,), columns (m, s), values (m, s))]``, one per kind
        (:data:`~baselines.ekf.filter.JacobianRows`; observability-constrained when
        ``constrained``). ``at = (x, h, rows)`` seeds the memo with the model's values at
        ``x`` (already computed). ``bias_off`` (k,): the state of each bearing's coloured error
        (:mod:`baselines.ekf.coloured`), added to ``h`` with a Jacobian entry of 1, appended
        as the last column of each row (it is outside the OC-EKF nullspace).
        """
        k = len(offsets)
        groups = []
        for size, fn in ((2, bearing_and_jacobian), (4, invdepth_bearing_and_jacobian)):
            sel = kinds == size
            if sel.any():
                blocks = [self._block_index(pose_off[sel], 3),
                          self._block_index(offsets[sel], size)]
                if bias_off is not None:
                    blocks.append(np.asarray(bias_off, np.int64)[sel, None])
                groups.append((np.flatnonzero(sel), np.concatenate(blocks, 1), fn))
        geo = 3 + np.array([2, 4])             # columns of the geometric part, per kind
        memo: dict[str, Any] = {}
        filt = self.filter
        if at is not None:       # at the filter's own state (version), else at a copy of x
            if at[0] is filt.x:
                memo.update(version=filt.version, x=None, h=at[1], parts=at[2])
            else:
                memo.update(version=None, x=at[0].copy(), h=at[1], parts=at[2])

        def both(x: np.ndarray) -> tuple[np.ndarray, JacobianRows]:
            own = x is filt.x
            if "h" in memo and ((memo["version"] == filt.version) if own and memo["x"] is None
                                else (memo["x"] is not None and np.array_equal(memo["x"], x))):
                return memo["h"], memo["parts"]
            h = np.empty(k)
            parts = []
            for rows, cols, fn in groups:
                v = x[cols]
                s = geo[0] if fn is bearing_and_jacobian else geo[1]
                h[rows], j = fn(v[:, :3], v[:, 3:s])
                if constrained:
                    j = self._constrain(j, cols[:, :s])
                if bias_off is not None:
                    h[rows] += v[:, s]
                    j = np.concatenate([j, np.ones((len(j), 1))], 1)
                parts.append((rows, cols, j))
            if own:
                memo.update(version=filt.version, x=None, h=h, parts=parts)
            else:
                memo.update(version=None, x=x.copy(), h=h, parts=parts)
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

        With ``jacobians="fej"`` a Euclidean landmark's row is instead the model's Jacobian at
        the anchors themselves (the landmark's first estimate ``a_l`` and the pose's prior
        ``a_p``): ``h_l = J d / |d|^2`` with ``d = a_l - a_p``, ``h_p = -h_l``, ``h_psi = -1``
        (Huang, Mourikis and Roumeliotis, ICRA 2008), which satisfies ``h N = 0`` as well.
        With ``jacobians="plain"`` the rows are returned unchanged.

        Parameters
        ----------
        jac : array of shape (m, s)
            Rows over the columns ``cols`` (pose first, then the landmark block).
        cols : int array of shape (m, s)

        Returns
        -------
        ndarray of shape (m, s)
        """
        if self._jacobians == "plain":
            return jac
        N = self.filter.nullspace
        out = jac.copy()
        project = None
        if jac.shape[1] == 5 and self._jacobians == "fej":
            d = np.column_stack([N[cols[:, 4], 2] - N[cols[:, 1], 2],
                                 N[cols[:, 0], 2] - N[cols[:, 3], 2]])      # a_l - a_p
            q = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]
            ok = q > 1e-12
            out[ok, 3] = -d[ok, 1] / q[ok]
            out[ok, 4] = d[ok, 0] / q[ok]
            out[ok, 0:2] = -out[ok, 3:5]
            out[ok, 2] = -1.0
            project = ~ok
        elif jac.shape[1] == 5:
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
        if project is None:
            project = np.ones(len(jac), bool)
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
                      z: np.ndarray, bias_off: np.ndarray | None = None) -> np.ndarray:
        """Gate each bearing on its own NIS, then one batched filterpy update with the rest.

        The NIS of bearing ``i`` is ``y_i^2 / (H_i P H_i^T + var_i)`` with the wrapped
        innovation ``y_i`` and the variance ``var_i`` of
        :func:`~baselines.ekf.models.second_order_variance`; it is compared with the
        chi-square 1-dof quantile. Bearings past ``max_bearing_nonlinearity`` are not used.
        With ``iterations > 1`` the iterates of the iterated update use the model's own
        Jacobians and only the last step the observability-constrained ones. ``bias_off``:
        the states of the bearings' coloured errors (:meth:`_model`); the white part's
        variance is then ``(1 - c) sigma^2``. With ``wide_prior_heading_sd_rad`` set, an update
        whose prior robot heading variance exceeds its square is iterated
        ``wide_prior_iterations`` times.

        Returns
        -------
        ndarray of shape (k,), bool
            The bearings that failed the gate.
        """
        iterations = self._iterations
        if self._wide_var is not None and self.filter.P[2, 2] > self._wide_var:
            iterations = self._wide_iterations
        # the fused kernels build the OC-EKF rows only; "fej" and "plain" take the model path
        if bias_off is None and iterations == 1 and self._jacobians == "oc":
            return self._plain_gated_update(pose_off, kinds, offsets, z)
        return self._model_gated_update(pose_off, kinds, offsets, z, bias_off, iterations)

    def _model_gated_update(self, pose_off: np.ndarray, kinds: np.ndarray,
                            offsets: np.ndarray, z: np.ndarray,
                            bias_off: np.ndarray | None,
                            iterations: int | None = None) -> np.ndarray:
        """:meth:`_gated_update` through the bearing model (:meth:`_model`) and
        :meth:`BearingEkf.update`: any number of ``iterations`` (None: the configured
        ``iterations``), coloured errors."""
        iterations = self._iterations if iterations is None else iterations
        model = self._model(pose_off, kinds, offsets, bias_off=bias_off)
        x, P = self.filter.x, self.filter.P
        h, parts = model(x)
        var = np.empty(len(z))
        index = np.zeros(len(z))
        hph = np.zeros(len(z))
        for rows, cols, j in parts:
            block = P[cols[:, :, None], cols[:, None, :]]          # (m, s, s)
            hph[rows] = np.einsum("mi,mij,mj->m", j, block, j)
            s = cols.shape[1] - (bias_off is not None)             # the geometric part
            var[rows], index[rows] = second_order_variance(x[cols[:, :s]], block[:, :s, :s],
                                                           self._white_sigma)
        usable = index <= self._max_nonlin
        innovation = np.asarray(angle_residual(z, h))
        var = self._variances(innovation, hph, var, usable)
        gated = (innovation ** 2 / (hph + var) > self._gate) & usable
        self.n_nonlinear += int(np.count_nonzero(~usable))
        self.n_gated += int(np.count_nonzero(gated))
        keep = usable & ~gated
        if keep.any():
            bias_kept = None if bias_off is None else bias_off[keep]
            if keep.all():
                kept = model
            else:                           # the kept rows, already evaluated at this x
                kept = self._model(pose_off[keep], kinds[keep], offsets[keep],
                                   at=(x, h[keep], take_rows(parts, keep)),
                                   bias_off=bias_kept)
            plain = (self._model(pose_off[keep], kinds[keep], offsets[keep], constrained=False,
                                 bias_off=bias_kept)
                     if iterations > 1 else None)
            try:
                self.filter.update(z[keep], kept, var[keep], iterations, plain,
                                   innovation=innovation[keep])
            except FilterNumericalError as exc:         # the state is as before the update
                self.n_failures += 1
                self.last_failure = f"step {self._t}: {exc}"
                return np.zeros(len(z), bool)
            self.n_updates += int(np.count_nonzero(keep))
        return gated

    def _plain_gated_update(self, pose_off: np.ndarray, kinds: np.ndarray,
                            offsets: np.ndarray, z: np.ndarray) -> np.ndarray:
        """:meth:`_gated_update` for one EKF update (``iterations = 1``) of white bearings:
        the same model in one pass, without the model object. The bearings to Euclidean
        landmarks go through the fused kernel :func:`~baselines.ekf.rows.landmark_rows`
        (prediction, constrained rows, ``H_i P H_i^T``, second-order variance in a few
        calls), those to inverse-depth features through :func:`~baselines.ekf.rows.
        feature_rows`; the update is :meth:`BearingEkf.update_rows` on each row's own states
        (5 or 7; a landmark row padded to 7 with zeros when both kinds are in the batch)."""
        filt = self.filter
        x, P = filt.x, filt.P
        k = len(z)
        n_lm = int(np.count_nonzero(kinds == 2))
        width = 5 if n_lm == k else 7
        cols = np.empty((k, width), np.int64)
        cols[:, :3] = pose_off[:, None] + _RANGE[:3]
        if n_lm == k:
            cols[:, 3:] = offsets[:, None] + _RANGE[:2]
            h, jac, hph, var, index = landmark_rows(x, P, filt.nullspace, cols,
                                                    self._white_sigma, self._constrain)
        else:
            jac = np.zeros((k, width))
            h, hph, var, index = np.empty(k), np.empty(k), np.empty(k), np.empty(k)
            lm = kinds == 2
            cols[:, 3:] = offsets[:, None] + _RANGE[:4]
            cols[lm, 5:] = cols[lm, 3:5]            # padding: repeated states, zero entries
            if n_lm:
                h[lm], jac[lm, :5], hph[lm], var[lm], index[lm] = landmark_rows(
                    x, P, filt.nullspace, cols[lm, :5], self._white_sigma, self._constrain)
            f = ~lm
            h[f], jac[f], hph[f], var[f] = feature_rows(x, P, filt.nullspace, cols[f],
                                                        self._white_sigma)
            index[f] = 0.0
        usable = index <= self._max_nonlin
        innovation = angle_residual(z, h)
        var = self._variances(innovation, hph, var, usable)
        gated = innovation * innovation > self._gate * (hph + var)
        gated &= usable
        n_unusable = k - int(np.count_nonzero(usable))
        n_gated = int(np.count_nonzero(gated))
        self.n_nonlinear += n_unusable
        self.n_gated += n_gated
        if n_unusable + n_gated == k:
            return gated
        if n_unusable + n_gated:
            keep = usable ^ gated                    # usable and not gated (gated => usable)
            cols, jac, innovation, var = cols[keep], jac[keep], innovation[keep], var[keep]
        try:
            filt.update_rows(cols, jac, innovation, var)
        except FilterNumericalError as exc:             # the state is as before the update
            self.n_failures += 1
            self.last_failure = f"step {self._t}: {exc}"
            return np.zeros(k, bool)
        self.n_updates += len(innovation)
        return gated

    # -- inverse-depth features ---------------------------------------------------------------
    def _add_inverse_depth(self, ids: np.ndarray, z: np.ndarray) -> None:
        """Add first sightings as inverse-depth features anchored at the robot (Civera):
        ``[x, y, psi + z, rho_init]`` with ``rho ~ N(rho_init, rho_sigma^2)``."""
        if ids.size:
            m = ids.size
            col = self._coloured
            self.filter.check_room((5 if col.enabled else 4) * m, f"{m} new landmark features")
            x = self.filter.x
            value = np.column_stack([np.broadcast_to(x[:2], (m, 2)), wrap_angle(x[2] + z),
                                     np.full(m, self.rho_init)]).ravel()
            g = np.tile(np.vstack([np.eye(3), np.zeros((1, 3))]), (m, 1))      # (4m, 3)
            noise = np.tile([0.0, 0.0, self._white_sigma ** 2, self.rho_sigma ** 2], m)
            idx = np.arange(3)
            if col.enabled:         # theta = psi + z - b: the coloured error comes first
                keys = [(BLOCK_BIAS, int(i)) for i in ids]
                self._add_blocks(keys, np.zeros(m), np.zeros(0, np.int64), np.zeros((m, 0)),
                                 np.full(m, col.bias_var_rad2))
                bias = np.array([self._offset[k] for k in keys], np.int64)
                idx = np.concatenate([idx, bias])
                g = np.concatenate([g, np.zeros((4 * m, m))], 1)
                g[4 * np.arange(m) + 2, 3 + np.arange(m)] = -1.0
                col.remember(ids.tolist(), value.reshape(m, 4)[:, 2], float(x[2]))
            self._add_blocks([(BLOCK_IDP, int(i)) for i in ids], value, idx, g, noise)

    def _idp_blocks(self) -> tuple[list[tuple[str, int]], np.ndarray]:
        """The inverse-depth features' keys and state indices ``(k, 4)`` (kept until the
        layout changes)."""
        if self._idp is None:
            keys = [k for k in self._sizes if k[0] == BLOCK_IDP]
            bi = self._block_index(np.array([self._offset[k] for k in keys], np.int64), 4)
            self._idp = keys, bi
        return self._idp

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
        self._add_blocks([(BLOCK_LM, k[1]) for k in old], pts.ravel(), idx, g,
                         np.zeros((2 * m, 2 * m)))
        self._remove_blocks(old)
        for k in old:
            self._gated_run.pop(k[1], None)
        self.n_converted += m

    def _update_mapped(self, ids: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Gate and apply the bearings to landmarks in the state; returns the mask of those."""
        mapped = self._mapped
        found = [(n, *where) for n, i in enumerate(ids.tolist())
                 if (where := mapped.get(i)) is not None]
        in_state = np.zeros(len(ids), bool)
        if found:
            rows, kind_names, offs = zip(*found)
            in_state[list(rows)] = True
            kinds = np.array([_SIZE[k] for k in kind_names], np.int64)
            offsets = np.array(offs, np.int64)
            bias = self._decay_coloured(ids[in_state].tolist(), kinds, offsets)
            gated = self._gated_update(np.zeros(len(found), np.int64), kinds, offsets,
                                       z[in_state], bias)
            # an inverse-depth feature gated again and again was started from an outlier:
            # drop it; the current sighting starts it again. It counts only at steps where a
            # bearing passed: if all fail, the pose is the culprit (docs/measurements.md)
            restart = []
            corroborated = not bool(gated.all())
            for i, kind, g in (zip(ids[in_state].tolist(), kind_names, gated.tolist())
                               if BLOCK_IDP in kind_names else ()):
                if kind == BLOCK_IDP and (corroborated or not g):
                    run_length = self._gated_run.get(i, 0) + 1 if g else 0
                    self._gated_run[i] = run_length
                    if run_length >= self._restart_after:
                        restart.append(i)
            if restart:
                self._remove_blocks([(kind, i) for i in restart for kind in (BLOCK_IDP, BLOCK_BIAS)
                                     if (kind, i) in self._sizes])
                self._coloured.forget(restart)
                for i in restart:
                    del self._gated_run[i]
                in_state &= ~np.isin(ids, restart)
                self.n_restarted += len(restart)
        return in_state

    def _decay_coloured(self, ids: list[int], kinds: np.ndarray, offsets: np.ndarray
                        ) -> np.ndarray | None:
        """Propagate the coloured errors of the landmarks ``ids`` (blocks ``kinds``,
        ``offsets``) to the current viewing geometry (:mod:`baselines.ekf.coloured`); returns
        their state offsets (None when the model is off)."""
        col = self._coloured
        if not col.enabled:
            return None
        bias = np.array([self._offset[(BLOCK_BIAS, i)] for i in ids], np.int64)
        x = self.filter.x
        a = col.factors(ids, ray_directions(x, kinds, offsets), float(x[2]))
        self.filter.decay(bias, a, (1.0 - a * a) * col.bias_var_rad2)
        return bias

    # -- the Mapper protocol ----------------------------------------------------------------
    def step(self, step: Step) -> None:
        """Predict with the step's odometry, update with its bearings, grow the map."""
        if self._last_t is not None and step.t <= self._last_t:
            raise ConfigError(f"steps must come in increasing t: got t = {step.t} after "
                              f"t = {self._last_t}")
        self._t = step.t
        self._reach.advance(step)   # a step's refusal names its line, not a later one's
        if step.odom is not None:
            try:
                self._predict(np.asarray(step.odom, float), step.odometry_sigma(self._header))
            except FilterNumericalError as exc:  # the stream's file and line name the field
                raise odometry_refusal(exc, step, self._header) from None
        ids, z = step.landmark_ids, step.bearings_rad
        if ids.size:
            in_state = self._update_mapped(ids, z)
            self._new_sightings(step.t, ids[~in_state], z[~in_state])
        self._last_t = step.t
        n = self._n_poses
        if n == len(self._pose_t):
            self._pose_t = np.concatenate([self._pose_t, np.zeros_like(self._pose_t)])
            self._poses = np.concatenate([self._poses, np.zeros_like(self._poses)])
            self._pose_covs = np.concatenate([self._pose_covs, np.zeros_like(self._pose_covs)])
        self._pose_t[n] = step.t
        self._poses[n] = self.filter.x[:3]
        self._pose_covs[n] = self.filter.P[:3, :3]
        self._n_poses = n + 1

    def _predict(self, odom: np.ndarray, sigma: np.ndarray) -> None:
        """The odometry predict, in ``k`` sub-steps along the arc when the step turns by more
        than ``max_predict_turn_rad`` (each ``arc_root(odom, k)`` with ``sigma / sqrt(k)``),
        with :func:`~baselines.ekf.models.path_heading_noise` when ``path_heading_noise``."""
        k = predict_substeps(float(odom[2]), self._max_turn)  # refused beyond 10,000
        if k > 1:
            odom, sigma = arc_root(odom, k), np.asarray(sigma, float) / math.sqrt(k)
        extra = (path_heading_noise(odom, float(np.ravel(sigma)[2])),) if self._path_noise else ()
        for _ in range(max(k, 1)):       # (the paper path calls predict(odom, sigma) as always)
            self.filter.predict(odom, sigma, *extra)

    def _new_sightings(self, t: int, ids: np.ndarray, z: np.ndarray) -> None:
        raise NotImplementedError

    def _landmarks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Ids, positions ``(n, 2)`` and covariances ``(n, 2, 2)`` of the reportable landmarks."""
        keys = [k for k in self._sizes if k[0] == BLOCK_LM]
        ids = np.array([k[1] for k in keys], np.int64)
        bi = self._block_index(np.array([self._offset[k] for k in keys], np.int64), 2)
        x, P = self.filter.x, self.filter.P
        return ids, x[bi].reshape(-1, 2), P[bi[:, :, None], bi[:, None, :]].reshape(-1, 2, 2), {}

    def estimate(self) -> MapEstimate:
        """The filtered map, the filtered trajectory (every step) and their covariances."""
        ids, xy, cov, info = self._landmarks()
        order = np.argsort(ids)
        info = {**info, "state_dim": self.filter.dim, "gated_bearings": self.n_gated,
                "nonlinear_bearings": self.n_nonlinear, "used_bearings": self.n_updates,
                "restarted": self.n_restarted, **self._variances.info()}  # options' own too
        if self.n_failures:
            info.update(update_failures=self.n_failures, last_failure=self.last_failure)
        if not (n := self._n_poses):
            return MapEstimate.empty(reason="no steps yet", **info)
        if ids.size == 0:
            info["reason"] = "no landmark initialised yet"
        return MapEstimate(ids[order], xy[order], pose_t=self._pose_t[:n],
                           poses=self._poses[:n], landmark_cov=cov[order],
                           pose_cov=self._pose_covs[:n], info=info)


__all__ = ["EkfSlam", "BLOCK_ANCHOR", "BLOCK_BIAS", "BLOCK_LM", "BLOCK_CLONE", "BLOCK_IDP"]
