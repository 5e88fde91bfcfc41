"""The window bundle's least-squares problem and its Levenberg-Marquardt solver
(``tri_method="ba"``, :mod:`.bundle`): residuals and Jacobians of the odometry and bearing
terms, the normal equations in blocks (poses, poses x landmarks, 2 x 2 landmark blocks) and
the damped step by the Schur complement on the poses (short windows) or on the landmarks, the
banded pose block factorised first (long windows, :func:`_arrow_step`).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack, solve_triangular

from ..angles import angle_residual
from ..geometry import bearing_offsets, pair_bearings
from .banded import PoseBlock, solve_lower_unit, upper_band

#: Odometry std. devs. below this (m or rad) are raised to it: a zero std. dev. (the paper's
#: simulator has no lateral slip, ``sigma_dy = 0``) would be an infinite weight, and a tiny one
#: makes the normal equations so stiff that Levenberg-Marquardt crawls (1e-6: about 30
#: iterations per solve on the paper setup). The residual of such a component is zero at the
#: truth, so noise-free data stay exact; the factor graphs use the same floor.
SIGMA_FLOOR = 1e-3


def _between_residuals(poses: np.ndarray, odoms: np.ndarray, jacobians: bool = True
                       ) -> tuple[np.ndarray, ...]:
    """Odometry residuals ``between(x_{m-1}, x_m) - u_m`` and their Jacobians.

    Returns ``(res (M, 3), d res / d x_{m-1} (M, 3, 3), d res / d x_m (M, 3, 3))``, or
    ``(res,)`` without ``jacobians``.
    """
    a, b = poses[:-1], poses[1:]
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    delta = b - a
    dx, dy = delta[:, 0], delta[:, 1]
    m = len(a)
    lateral = -s * dx + c * dy
    res = np.empty((m, 3))
    res[:, 0] = c * dx + s * dy - odoms[:, 0]
    res[:, 1] = lateral - odoms[:, 1]
    res[:, 2] = angle_residual(delta[:, 2], odoms[:, 2])
    if not jacobians:
        return (res,)
    jb = np.zeros((m, 3, 3))
    jbf = jb.reshape(m, 9)
    jbf[:, 0], jbf[:, 1], jbf[:, 3], jbf[:, 4], jbf[:, 8] = c, s, -s, c, 1.0
    ja = -jb
    ja[:, 0, 2] = lateral
    ja[:, 1, 2] = -c * dx - s * dy
    return res, ja, jb


def window_bearing_residuals(poses: np.ndarray, points: np.ndarray, k: np.ndarray,
                             lm: np.ndarray, theta: np.ndarray, jacobians: bool = True
                             ) -> tuple[np.ndarray, np.ndarray | None]:
    """Bearing residuals and ``d res / d (p_l)`` (``d / d z_k`` is its negative,
    ``d / d psi_k = -1``; None without ``jacobians``)."""
    if not jacobians:
        return angle_residual(pair_bearings(poses[k], points[lm], wrapped=False), theta), None
    pred, d, r2 = bearing_offsets(poses[k], points[lm])
    dp = np.empty_like(d)
    dp[:, 0] = -d[:, 1] / r2
    dp[:, 1] = d[:, 0] / r2
    return angle_residual(pred, theta), dp


class BundleProblem:
    """One window's least-squares problem over poses 1..W-1 and the landmarks."""

    def __init__(self, odoms: np.ndarray, sigmas: np.ndarray, bearing_sigma_rad: float,
                 k: np.ndarray, lm: np.ndarray, theta: np.ndarray, n_lm: int) -> None:
        self.odoms = odoms
        self.w_odo = 1.0 / np.maximum(sigmas, SIGMA_FLOOR)          # (M, 3)
        self.w_b = 1.0 / bearing_sigma_rad
        self.k, self.lm, self.theta = k, lm, theta
        self.n_pose_vars = 3 * len(odoms)
        self.n = self.n_pose_vars + 2 * n_lm
        m = len(odoms)
        self.rows = 3 * m + len(k)
        # column of each pose's variables (-1: pose 0 is fixed)
        self.pose_col = np.concatenate([[-1], 3 * np.arange(m)])
        self._onehot: tuple | None = None

    def cost(self, poses: np.ndarray, points: np.ndarray) -> float:
        ro = _between_residuals(poses, self.odoms, False)[0] * self.w_odo
        rb = window_bearing_residuals(poses, points, self.k, self.lm, self.theta,
                                      False)[0] * self.w_b
        return float(np.sum(ro * ro) + np.sum(rb * rb))

    def linearise(self, poses: np.ndarray, points: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
        """Whitened residual vector and dense Jacobian, shape ``(rows,)`` and ``(rows, n)``."""
        m = len(self.odoms)
        ro, ja, jb = _between_residuals(poses, self.odoms)
        rb, dp = window_bearing_residuals(poses, points, self.k, self.lm, self.theta)
        jac = np.zeros((self.rows, self.n))
        odo_rows = np.arange(3 * m).reshape(m, 3)
        wo = self.w_odo[:, :, None]
        for j in range(3):                    # the three variables of the pose before / after
            jac[odo_rows[1:], (3 * np.arange(m - 1) + j)[:, None]] = (ja[1:, :, j:j + 1]
                                                                     * wo[1:])[..., 0]
            jac[odo_rows, (3 * np.arange(m) + j)[:, None]] = (jb[:, :, j:j + 1] * wo)[..., 0]
        rows = 3 * m + np.arange(len(self.k))
        self._fill_bearing_rows(jac, rows, dp)
        res = np.concatenate([(ro * self.w_odo).ravel(), rb * self.w_b])
        return res, jac

    def _fill_bearing_rows(self, jac: np.ndarray, rows: np.ndarray, dp: np.ndarray) -> None:
        """Write the whitened bearing Jacobian into ``jac[rows]`` (``dp``: the bearing's
        derivative direction per row, ``(R, 2)``; the pose columns only where the pose is a
        variable)."""
        pc = self.pose_col[self.k]
        seen_from_var = pc >= 0
        r_v, c_v = rows[seen_from_var], pc[seen_from_var]
        jac[r_v, c_v] = -dp[seen_from_var, 0] * self.w_b
        jac[r_v, c_v + 1] = -dp[seen_from_var, 1] * self.w_b
        jac[r_v, c_v + 2] = -self.w_b
        lc = self.n_pose_vars + 2 * self.lm
        jac[rows, lc] = dp[:, 0] * self.w_b
        jac[rows, lc + 1] = dp[:, 1] * self.w_b

    def bearing_rows(self, poses: np.ndarray, points: np.ndarray) -> np.ndarray:
        """The bearing rows of :meth:`linearise`'s Jacobian alone, shape ``(R, n)`` (the same
        numbers, without the odometry rows)."""
        dp = window_bearing_residuals(poses, points, self.k, self.lm, self.theta)[1]
        jac = np.zeros((len(self.k), self.n))
        rows = np.arange(len(self.k))
        self._fill_bearing_rows(jac, rows, dp)
        return jac

    def normal_equations(self, poses: np.ndarray, points: np.ndarray
                         ) -> tuple[float, tuple[np.ndarray, ...]]:
        """The cost and the blocks of ``J^T J`` and ``J^T r`` (whitened), without the dense
        Jacobian: ``(cost, (A (P, P) poses, B (P, 2 L) poses x landmarks, C (L, 2, 2)
        landmark blocks, g_poses (P,), g_landmarks (2 L,)))``, ``P = 3 (W - 1)``; ``A`` is
        a :class:`.banded.PoseBlock` where :func:`uses_arrow` (long windows), dense
        otherwise."""
        cost, lin = self.evaluate(poses, points)
        return cost, self.blocks(lin)

    def evaluate(self, poses: np.ndarray, points: np.ndarray
                 ) -> tuple[float, tuple[np.ndarray, ...]]:
        """The cost and the whitened residuals and Jacobians it came from (for
        :meth:`blocks`): ``(cost, (odometry residuals (M, 3), d / d x_{m-1} (M, 3, 3),
        d / d x_m (M, 3, 3), bearing residuals (R,), d res / d landmark (R, 2)))``."""
        ro, ja, jb = _between_residuals(poses, self.odoms)
        rb, dp = window_bearing_residuals(poses, points, self.k, self.lm, self.theta)
        wo = self.w_odo[:, :, None]
        ja, jb, ro = ja * wo, jb * wo, ro * self.w_odo
        rb = rb * self.w_b
        cost = float(np.sum(ro * ro) + np.sum(rb * rb))
        return cost, (ro, ja, jb, rb, dp * self.w_b)

    def blocks(self, lin: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
        """The blocks of :meth:`normal_equations` from :meth:`evaluate`'s residuals and
        Jacobians. Sums over rays are one product with a fixed one-hot matrix per pose and per
        landmark (:meth:`_setup_onehot`)."""
        ro, ja, jb, rb, jl = lin
        m, n_lm = len(self.odoms), (self.n - self.n_pose_vars) // 2
        if self._onehot is None:
            self._setup_onehot(m, n_lm)
        sel, b_flat, pose_of, lm_of = self._onehot
        jbt, jat = jb.transpose(0, 2, 1), ja[1:].transpose(0, 2, 1)
        jp = np.empty((len(sel), 3))                        # d res / d pose k >= 1
        jp[:, :2] = -jl[sel]
        jp[:, 2] = -self.w_b
        d = jbt @ jb                                        # the 3 x 3 blocks on the diagonal
        d[:-1] += jat @ ja[1:]
        d += (pose_of @ (jp[:, :, None] * jp[:, None, :]).reshape(-1, 9)).reshape(m, 3, 3)
        off = jat @ jb[1:]
        a = PoseBlock(d, off)
        if not uses_arrow(3 * m, 2 * n_lm):       # short windows: the dense Schur complement
            a = a.dense()
        gp = (jbt @ ro[:, :, None])[:, :, 0]
        gp[:-1] += (jat @ ro[1:, :, None])[:, :, 0]
        gp += pose_of @ (jp * rb[sel, None])
        c = (lm_of @ (jl[:, :, None] * jl[:, None, :]).reshape(-1, 4)).reshape(n_lm, 2, 2)
        gl = lm_of @ (jl * rb[:, None])
        b = np.zeros((3 * m, 2 * n_lm))
        np.put(b, b_flat, jp[:, :, None] * jl[sel][:, None, :])
        return a, b, c, gp.ravel(), gl.ravel()

    def _setup_onehot(self, m: int, n_lm: int) -> None:
        """Rays seen from a pose variable, the one-hot matrices summing per pose and per
        landmark (a matrix product is one call; the problem's rays do not change), where each
        ray's pose x landmark products land in ``B``."""
        sel = np.flatnonzero(self.k >= 1)
        k_sel = self.k[sel] - 1
        pose_of = np.zeros((m, len(sel)))
        pose_of[k_sel, np.arange(len(sel))] = 1.0
        lm_of = np.zeros((n_lm, len(self.k)))
        lm_of[self.lm, np.arange(len(self.k))] = 1.0
        # flat index in B (3 M, 2 L) of (pose variable 3 k + a, landmark variable 2 l + b)
        b_flat = ((3 * k_sel[:, None, None] + np.arange(3)[None, :, None]) * (2 * n_lm)
                  + 2 * self.lm[sel][:, None, None] + np.arange(2)[None, None, :])
        self._onehot = (sel, b_flat, pose_of, lm_of)

    def unpack(self, poses: np.ndarray, points: np.ndarray, delta: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
        new_poses = poses.copy()
        new_poses[1:] += delta[:self.n_pose_vars].reshape(-1, 3)
        return new_poses, points + delta[self.n_pose_vars:].reshape(-1, 2)


def levenberg_marquardt(prob: BundleProblem, poses: np.ndarray, points: np.ndarray,
                        max_iter: int, tol: float
                        ) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, ...], bool]:
    """Minimise the window's cost; returns poses, points, the blocks of ``J^T J`` at the end
    (:meth:`BundleProblem.blocks`; :class:`WindowInverse` takes what the fit needs from them),
    converged.

    Each step solves the damped normal equations by the Schur complement on the poses
    (:meth:`BundleProblem.normal_equations`, :func:`_schur_step`): the landmark block is 2 x 2
    block-diagonal, so only a ``3 (W - 1)`` system is factorised (and in long windows only a
    banded one and the landmarks' ``2 L`` one, :func:`_arrow_step`)."""
    lam = 1e-6
    cost, blocks = prob.normal_equations(poses, points)
    converged = False
    for _ in range(max_iter):
        step_ok = False
        while lam < 1e10:
            delta = _schur_step(blocks, lam)
            if delta is None:
                lam *= 10.0
                continue
            cand_poses, cand_points = prob.unpack(poses, points, delta)
            # the cost with the Jacobian rows at once; the normal equations once accepted
            cand_cost, cand_lin = prob.evaluate(cand_poses, cand_points)
            if cand_cost <= cost:
                step_ok = True
                break
            lam *= 10.0
        if not step_ok:
            converged = True                  # no descent direction left at this precision
            break
        poses, points = cand_poses, cand_points
        small = cost - cand_cost <= tol * max(cost, 1e-300)
        lam = max(lam / 10.0, 1e-12)
        cost, blocks = cand_cost, prob.blocks(cand_lin)
        if small:
            converged = True
            break
    return poses, points, blocks, converged


#: Eigenvalues of the Jacobi-scaled ``J^T J`` under this fraction of the largest are directions
#: the window does not determine; :func:`ray_leverages` leaves them out (a pseudo-inverse).
LEVERAGE_RCOND = 1e-10
#: :func:`ray_leverages` takes the leverages from a Cholesky factor when the (estimated)
#: condition of the scaled ``J^T J`` is under this (their relative error is then ~1e-8), from
#: the eigendecomposition otherwise.
CHOLESKY_MAX_COND = 1e8
#: A ray whose leverage is at least this has no redundancy: the fit reproduces it whatever its
#: noise (one of a landmark's only two rays, say), so its residual is zero up to rounding and
#: says nothing about the noise. The outlier test and the bearing-sigma estimate leave it out
#: (:func:`bomgraph.stmds.bundle._fit`).
UNDETERMINED_LEVERAGE = 1.0 - 1e-6


def ray_leverages(info: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Leverage ``h_r = j_r^T (J^T J)^+ j_r`` of each whitened bearing row ``j_r``, in [0, 1],
    shape ``(R,)``; ``info`` is ``J^T J`` ``(n, n)`` and ``rows`` the bearing rows of ``J``
    ``(R, n)`` (:func:`psd_quadratic_forms`). This is the hat matrix's diagonal while the
    scaled ``J``'s singular values stay above ``sqrt(LEVERAGE_RCOND)`` of the largest; below
    that the direction counts as undetermined (forming ``J^T J`` squares the condition)."""
    return np.clip(psd_quadratic_forms(info, rows), 0.0, 1.0)


def psd_quadratic_forms(m: np.ndarray, rows: np.ndarray, jacobi: bool = True) -> np.ndarray:
    """``x_r^T M^+ x_r`` for each row ``x_r`` of ``rows`` ``(R, n)``, ``M`` ``(n, n)`` symmetric
    positive semi-definite, with the directions ``M`` does not determine left out.

    Windows of recordings have ``J^T J`` of condition up to ~1e16 (a landmark barely
    determined); a plain solve there returns leverages off by ~1e-3, and rays of leverage ~1
    then get a standardised residual ``r / sqrt(1 - h)`` that is rounding over rounding. So
    the Jacobi-scaled ``M`` is factorised by Cholesky, and where LAPACK's estimate of its
    condition is under :data:`CHOLESKY_MAX_COND` (most windows; about one in eight of
    ``window-ba``'s on the paper setup is not) the forms come from the factor (accurate to
    ~1e-8); otherwise from an eigendecomposition with the directions under
    :data:`LEVERAGE_RCOND` of the largest eigenvalue left out (a pseudo-inverse). Where ``M``
    is well conditioned both equal a QR of ``J`` (``tests/stmds/test_leverage.py``). Zeros
    when ``M`` is not finite. ``jacobi=False``: ``M`` is taken as scaled already (a Schur
    complement in the scaled variables, whose own diagonal can vanish by cancellation).
    """
    scale = 1.0 / np.sqrt(np.maximum(np.diag(m), 1e-300)) if jacobi else np.ones(len(m))
    scaled = m * scale[:, None] * scale[None, :]
    if not np.all(np.isfinite(scaled)):
        return np.zeros(len(rows))
    rs = rows * scale
    factor, fail = lapack.dpotrf(scaled, lower=1, clean=1)
    if not fail:
        rcond, fail = lapack.dpocon(factor, np.abs(scaled).sum(0).max(), uplo="L")
        if not fail and rcond * CHOLESKY_MAX_COND > 1.0:
            a = solve_triangular(factor, rs.T, lower=True, check_finite=False)
            return np.einsum("ir,ir->r", a, a)
    w, v = np.linalg.eigh(scaled)
    keep = w > LEVERAGE_RCOND * max(w[-1], 1e-300)
    a = rs @ v[:, keep]
    return np.einsum("rk,rk,k->r", a, a, 1.0 / w[keep])


class WindowInverse:
    """What a window's fit needs of ``(J^T J)^-1`` at its solution (``blocks``:
    :meth:`BundleProblem.blocks`): each ray's leverage and the landmarks' covariance.

    Long windows (:func:`uses_arrow`) take them from the arrow structure
    (:func:`arrow_inverse`: the banded pose block, then only the landmarks' ``2 L x 2 L`` Schur
    complement ``T`` is dense; ``O(P^2)`` in the poses against ``O(P^3)``), the leverages with
    :func:`psd_quadratic_forms` on ``T``: the ill-conditioning of a recording's window is
    mostly in its barely determined landmarks, ``T``, while the odometry holds the poses.
    Where it does not (a landmark micrometres from a pose makes the scaled pose block
    numerically singular, and its rounding would reach every leverage), :func:`arrow_inverse`
    refuses (:data:`ARROW_MAX_COND`). Short windows (the paper presets but ``window-ba-long``),
    or a long one the arrow path refuses, take the dense matrix: :func:`ray_leverages` and the
    Jacobi-scaled inverse. On a numerically singular window the two paths are two generalised
    inverses: they agree on rows in the range of ``J``, not on rows with a component along a
    direction near the cut-off (``tests/stmds/test_leverage.py``)."""

    def __init__(self, prob: "BundleProblem", blocks: tuple[np.ndarray, ...]) -> None:
        self.prob, self.blocks = prob, blocks
        n_p = prob.n_pose_vars
        self._arrow = arrow_inverse(blocks) if uses_arrow(n_p, prob.n - n_p) else None
        self._dense: np.ndarray | None = None

    def _info(self) -> np.ndarray:
        if self._dense is None:
            self._dense = _dense_information(self.blocks)
        return self._dense

    def leverages(self, rows: np.ndarray) -> np.ndarray:
        """Each bearing row's leverage (:meth:`BundleProblem.bearing_rows`, ``(R, n)``), in
        [0, 1]."""
        if self._arrow is None:
            return ray_leverages(self._info(), rows)
        js = rows * self._arrow[0]                     # the rows in the scaled variables
        pc, var, kk = self._ray_poses()
        jp = np.take_along_axis(js, np.where(var, pc, 0)[:, None] + np.arange(3), axis=1)
        jp[~var] = 0.0
        return self._arrow_leverages(jp, kk, self._pose_part(jp, kk)
                                     - js[:, self.prob.n_pose_vars:])

    def leverages_at(self, poses: np.ndarray, points: np.ndarray) -> np.ndarray:
        """:meth:`leverages` of the bearing rows at ``poses``, ``points``
        (:meth:`BundleProblem.bearing_rows`), the same numbers; on the arrow path from each row's
        five nonzeros (three pose, two landmark entries), without the dense ``(R, n)`` rows."""
        prob = self.prob
        if self._arrow is None:
            return self.leverages(prob.bearing_rows(poses, points))
        s = self._arrow[0]
        dp = window_bearing_residuals(poses, points, prob.k, prob.lm, prob.theta)[1]
        pc, var, kk = self._ray_poses()
        c = pc[var]
        jp = np.zeros((len(prob.k), 3))
        jp[var, 0] = -dp[var, 0] * prob.w_b * s[c]
        jp[var, 1] = -dp[var, 1] * prob.w_b * s[c + 1]
        jp[var, 2] = -prob.w_b * s[c + 2]
        v = self._pose_part(jp, kk)                    # minus the landmark entries
        ray, lc = np.arange(len(prob.k)), 2 * prob.lm
        v[ray, lc] -= dp[:, 0] * prob.w_b * s[prob.n_pose_vars + lc]
        v[ray, lc + 1] -= dp[:, 1] * prob.w_b * s[prob.n_pose_vars + lc + 1]
        return self._arrow_leverages(jp, kk, v)

    def _ray_poses(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each ray's pose column (-1: the fixed pose 0), whether it is a variable, and
        its pose (0 for the fixed one)."""
        pc = self.prob.pose_col[self.prob.k]
        var = pc >= 0
        return pc, var, np.where(var, pc // 3, 0)

    def _pose_part(self, jp: np.ndarray, kk: np.ndarray) -> np.ndarray:
        """``(A^-1 B)_k^T j_p`` per ray (``jp``: its scaled pose entries), ``(R, 2 L)``."""
        ainv_b = self._arrow[2]
        w3 = ainv_b.reshape(-1, 3, ainv_b.shape[1])[kk]             # (R, 3, 2 L)
        return (jp[:, :, None] * w3).sum(1)

    def _arrow_leverages(self, jp: np.ndarray, kk: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``j_p^T (A^-1)_kk j_p + v^T T^-1 v`` per ray (:func:`arrow_inverse`), in [0, 1]."""
        _, ainv_kk, _, schur = self._arrow
        h = np.einsum("ri,rij,rj->r", jp, ainv_kk[kk], jp) + psd_quadratic_forms(
            schur, v, jacobi=False)
        return np.clip(h, 0.0, 1.0)

    def landmark_covariance(self) -> np.ndarray | None:
        """The landmarks' block of ``(J^T J)^-1`` (``2 L x 2 L``), None if singular."""
        if self._arrow is None:
            return _landmark_covariance(self._info(), self.prob.n_pose_vars)
        s, _, _, schur = self._arrow
        sl = s[self.prob.n_pose_vars:]
        try:
            return _covariance_or_none(np.linalg.inv(schur) * sl[:, None] * sl[None, :])
        except np.linalg.LinAlgError:
            return None


def _landmark_covariance(info: np.ndarray, n_pose_vars: int) -> np.ndarray | None:
    """Landmark block of ``info^-1`` (Jacobi-scaled for conditioning), None if singular."""
    scale = 1.0 / np.sqrt(np.maximum(np.diag(info), 1e-300))
    try:
        inv = np.linalg.inv(info * scale[:, None] * scale[None, :])
    except np.linalg.LinAlgError:
        return None
    return _covariance_or_none((inv * scale[:, None] * scale[None, :])[n_pose_vars:,
                                                                        n_pose_vars:])


def _covariance_or_none(cov: np.ndarray) -> np.ndarray | None:
    """``cov`` if it is finite with a positive diagonal, else None (a singular window)."""
    if not np.all(np.isfinite(cov)) or np.any(np.diag(cov) <= 0):
        return None
    return cov


#: Signs of the 2 x 2 adjugate ``[[d, -b], [-c, a]]`` (flattened).
_ADJUGATE_SIGN = np.array([1.0, -1.0, -1.0, 1.0])


def _schur_step(blocks: tuple[np.ndarray, ...], lam: float) -> np.ndarray | None:
    """The Levenberg-Marquardt step ``-(H + lam diag(H))^-1 g`` from the blocks of ``H``
    (poses ``A``, cross ``B``, 2 x 2 landmark blocks ``C``), landmarks eliminated first;
    None when the damped system is singular or the step is not finite."""
    a, b, c, gp, gl = blocks
    n_p = len(gp)
    c_d = c.reshape(-1, 4).copy()                     # (c00, c01, c10, c11) per landmark
    c_d[:, ::3] += lam * np.maximum(c_d[:, ::3], 1e-12)
    det = c_d[:, 0] * c_d[:, 3] - c_d[:, 1] * c_d[:, 2]
    if not np.all(det > 0):
        return None
    c_inv = (c_d[:, [3, 1, 2, 0]] * _ADJUGATE_SIGN / det[:, None]).reshape(-1, 2, 2)
    g_l = gl.reshape(-1, 2)
    if n_p == 0:
        return -(c_inv * g_l[:, None, :]).sum(2).ravel()
    if uses_arrow(n_p, len(gl)):             # the damped upper band alone
        band_d = upper_band(a).copy()
        band_d[5] += lam * np.maximum(band_d[5], 1e-12)
        return _arrow_step(band_d, b, c_d, gp, gl)
    a = np.asarray(a)
    a_d = a.copy()
    a_d.flat[::n_p + 1] += lam * np.maximum(a.diagonal(), 1e-12)
    b3 = b.reshape(n_p, -1, 2)
    bw = (b3[:, :, 0, None] * c_inv[None, :, 0] + b3[:, :, 1, None] * c_inv[None, :, 1]
          ).reshape(n_p, -1)
    schur = a_d - bw @ b.T
    rhs = bw @ gl - gp
    try:
        x = np.linalg.solve(schur, rhs)
    except np.linalg.LinAlgError:
        return None
    v = g_l + (b.T @ x).reshape(-1, 2)
    y = -(c_inv * v[:, None, :]).sum(2).ravel()
    delta = np.concatenate([x, y])
    return delta if np.all(np.isfinite(delta)) else None


#: :func:`arrow_inverse` gives way to the dense path when its bound on the condition of the
#: scaled pose block, ``|A|_1 trace(A^-1)`` (at least its condition, at most about ``3.3 P``
#: times it: ``P`` pose variables, 11 nonzeros a row), reaches this.
ARROW_MAX_COND = 1e9
#: Windows with at least this many pose variables, and more of them than landmark variables,
#: eliminate the poses first (:func:`_arrow_step`); smaller ones (the paper presets' 10-pose
#: windows among them) keep the dense Schur complement on the poses, which is as fast there.
ARROW_MIN_POSE_VARS = 60


def _arrow_step(band_d: np.ndarray, b: np.ndarray, c_d: np.ndarray, gp: np.ndarray,
                gl: np.ndarray) -> np.ndarray | None:
    """The damped step with the *poses* eliminated first, for long windows.

    The pose block ``a_d`` is block-tridiagonal (odometry links consecutive poses; a bearing
    touches one pose), so it is factorised banded (Cholesky, half-bandwidth 5) in ``O(P)``,
    and only the landmarks' ``2 L x 2 L`` Schur complement ``C - B^T A^-1 B`` is dense: ``O(P
    L^2)`` in all against ``O(P^3)`` for the dense Schur complement on the poses, the same
    step to rounding. ``band_d``: the damped pose block's upper band (:func:`.banded.upper_band`);
    ``c_d``: the damped 2 x 2 landmark blocks flattened ``(L, 4)``. None if a factorisation
    fails (not positive definite) or the step is not finite."""
    from scipy.linalg import LinAlgError, cho_solve_banded, cholesky_banded

    n_p, n_l = len(gp), len(gl)
    rhs = np.empty((n_p, n_l + 1), order="F")     # LAPACK's layout: solved in place
    rhs[:, :n_l] = b
    rhs[:, n_l] = gp
    try:
        factor = cholesky_banded(band_d, lower=False, check_finite=False)
        y = cho_solve_banded((factor, False), rhs, overwrite_b=True, check_finite=False)
    except (LinAlgError, ValueError):
        return None
    ainv_b, ainv_g = y[:, :n_l], y[:, n_l]
    s = -(b.T @ ainv_b)
    lm = np.arange(0, n_l, 2)
    for i in range(2):
        for j in range(2):
            s[lm + i, lm + j] += c_d[:, 2 * i + j]
    try:
        dl = np.linalg.solve(s, b.T @ ainv_g - gl)
    except np.linalg.LinAlgError:
        return None
    delta = np.concatenate([-ainv_g - ainv_b @ dl, dl])
    return delta if np.all(np.isfinite(delta)) else None


def uses_arrow(n_pose_vars: int, n_landmark_vars: int) -> bool:
    """Whether a window eliminates its poses first (:func:`_arrow_step`,
    :func:`arrow_inverse`): long windows with more pose than landmark variables."""
    return n_pose_vars >= ARROW_MIN_POSE_VARS and n_pose_vars > n_landmark_vars


def arrow_inverse(blocks: tuple[np.ndarray, ...]
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The parts of ``(J^T J)^-1`` a long window's fit needs, without the dense inverse.

    With the information ``[[A, B], [B^T, C]]`` (poses first; ``A`` block-tridiagonal, ``C``
    2 x 2 block-diagonal) Jacobi-scaled by ``s = diag(J^T J)^-1/2``, ``A = U^T U`` banded and
    ``T = C - B^T A^-1 B`` the landmarks' Schur complement:

    * ``(J^T J)^-1`` restricted to the landmarks is ``T^-1`` (scaled back);
    * a ray's leverage ``j^T (J^T J)^-1 j`` is ``j_p^T (A^-1)_kk j_p + v^T T^-1 v`` with ``v =
      (A^-1 B)_k^T j_p - j_l`` (``k`` its pose, ``j_p``, ``j_l`` the ray's pose and landmark
      entries; the block inverse of the arrow matrix), so only the 3 x 3 diagonal blocks of
      ``A^-1`` are needed: ``(A^-1)_kk = X_k^T X_k`` over the columns of ``X = U^-T``, one
      banded triangular solve.

    Returns, in the scaled variables, ``(s (P + 2 L,), (A^-1)_kk (P / 3, 3, 3), A^-1 B (P, 2
    L), T (2 L, 2 L))``; None if the banded factorisation fails or the scaled pose block's
    condition bound ``|A|_1 trace(A^-1)`` reaches :data:`ARROW_MAX_COND` (the caller then
    takes the dense path)."""
    from scipy.linalg import LinAlgError, cholesky_banded

    a, b, c, gp, gl = blocks
    n_p, n_l = len(gp), len(gl)
    s = 1.0 / np.sqrt(np.maximum(np.concatenate([a.diagonal(),
                                                 c[:, [0, 1], [0, 1]].ravel()]), 1e-300))
    sp, sl = s[:n_p], s[n_p:]
    band = np.zeros((6, n_p))
    for k in range(6):
        band[5 - k, k:] = a.diagonal(k) * sp[k:] * sp[:n_p - k]
    b_s = b * sp[:, None] * sl[None, :]
    if not (np.all(np.isfinite(band)) and np.all(np.isfinite(b_s))):
        return None
    try:
        factor = cholesky_banded(band, lower=False, check_finite=False)
    except (LinAlgError, ValueError):
        return None
    y = solve_lower_unit(factor, b_s)
    if y is None:
        return None
    x, y_b = y[:, n_l:], y[:, :n_l]                            # U^-T, U^-T B
    if n_l:      # scipy's dtbtrs on zero columns corrupts the heap (a window without landmarks)
        ainv_b, fail = lapack.dtbtrs(factor, y_b, uplo="U", trans="N")   # A^-1 B
        if fail or not np.all(np.isfinite(ainv_b)):
            return None
    else:
        ainv_b = np.zeros((n_p, 0))
    x3 = x.reshape(n_p, n_p // 3, 3)
    ainv_kk = np.einsum("rki,rkj->kij", x3, x3)
    # cond(A) <= |A|_1 trace(A^-1) <= sqrt(11) n cond(A): an ill-conditioned pose block (a
    # landmark micrometres from a pose) would carry its rounding into T and the leverages
    col = np.abs(band).sum(0)
    for k in range(1, 6):
        col[:-k] += np.abs(band[5 - k, k:])
    if not col.max() * np.trace(ainv_kk, axis1=1, axis2=2).sum() < ARROW_MAX_COND:
        return None
    schur = -(y_b.T @ y_b)                                     # - B^T A^-1 B
    lm = np.arange(0, n_l, 2)
    for i in range(2):
        for j in range(2):
            schur[lm + i, lm + j] += c[:, i, j] * sl[lm + i] * sl[lm + j]
    return s, ainv_kk, ainv_b, schur


def _dense_information(blocks: tuple[np.ndarray, ...]) -> np.ndarray:
    """``J^T J`` as one dense matrix (poses first, then landmarks) from its blocks."""
    a, b, c, gp, gl = blocks
    n_p, n_l = len(gp), len(gl)
    info = np.zeros((n_p + n_l, n_p + n_l))
    info[:n_p, :n_p] = np.asarray(a)
    info[:n_p, n_p:] = b
    info[n_p:, :n_p] = b.T
    lm = np.arange(0, n_l, 2)
    for i in range(2):
        for j in range(2):
            info[n_p + lm + i, n_p + lm + j] = c[:, i, j]
    return info


__all__ = ["SIGMA_FLOOR", "BundleProblem", "window_bearing_residuals", "levenberg_marquardt"]
