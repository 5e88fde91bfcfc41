"""Calibration of a stream's sigmas against its ground truth: residuals, robust statistics, fits.

Used by the importers (``mrclam.py``, ``g2o.py``) and ``scripts/inspect_datasets.py``.

- *Bearings.* :func:`bearing_residuals` gives ``r = angle_residual(measured, predicted from the
  truth pose and truth landmark)`` for every bearing of a stream. :func:`robust_bearing_stats`
  takes location ``m = median(r)`` (the bias), spread ``s = 1.4826 MAD(r)``, calls
  ``|r - m| > OUTLIER_MADS * s`` outliers, and gives the bearing sigma as the RMS of the inlier
  residuals about zero (so a bias, which no mapper can remove, counts as error).
- *Odometry.* Per step the error ``e = odom - between(truth_{t-1}, truth_t)`` is modelled per
  component ``j`` as zero-mean Gaussian with variance ``a_j^2 + (b_j l)^2 + (c_j |dpsi|)^2``
  (``l``, ``dpsi``: the step's odometry length and whole turn). :func:`fit_odometry_sigma` fits
  ``(a, b, c)`` by maximum likelihood (started from a non-negative least-squares fit of
  ``e^2``), excludes steps beyond 5 fitted sigmas and fits once more;
  :func:`odometry_sigma_model` evaluates the model; :func:`calibrate_odometry` does both
  for a keyframed run against its truth poses.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..angles import angle_residual
from ..errors import DatasetError
from ..geometry import between, pair_bearings
from ..stream import Stream

GROSS_OUTLIER_RAD = 0.2
"""A bearing residual beyond this is a gross outlier (MRCLAM SOURCE.md quirk 5)."""

OUTLIER_MADS = 5.0
"""Residuals farther than this many robust sigmas from the median are outliers."""

MIN_BEARING_SIGMA_RAD = 1e-4
"""Lower bound on a calibrated bearing sigma (noise-free input would give 0, not a valid
stream header)."""

_MIN_SIGMA_FLOOR = 1e-4
"""Lower bound on the odometry model's constant term ``a`` (a zero sigma would be infinite
weight)."""


def bearing_residuals(stream: Stream) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Residuals of every bearing in a stream against its truth poses and landmarks.

    Parameters
    ----------
    stream : Stream
        Must carry truth poses and the truth positions of every landmark observed.

    Returns
    -------
    residual_rad : ndarray of shape (m,)
        ``angle_residual(measured, predicted)``.
    step_t : ndarray of shape (m,), int64
        The step of each bearing.
    landmark_ids : ndarray of shape (m,), int64
    """
    truth = stream.truth
    if truth is None or truth.poses is None:
        raise DatasetError("bearing residuals need truth poses; this stream has none")
    counts = np.array([len(s.landmark_ids) for s in stream.steps], dtype=np.int64)
    if counts.sum() == 0:
        z = np.zeros(0)
        return z, z.astype(np.int64), z.astype(np.int64)
    step_t = np.repeat(np.arange(len(stream.steps)), counts)
    ids = np.concatenate([s.landmark_ids for s in stream.steps])
    meas = np.concatenate([s.bearings_rad for s in stream.steps])
    order = np.argsort(truth.landmark_ids)
    pos = np.searchsorted(truth.landmark_ids, ids, sorter=order)
    pos = np.clip(pos, 0, len(order) - 1)
    idx = order[pos]
    missing = truth.landmark_ids[idx] != ids
    if missing.any():
        raise DatasetError(f"landmark {int(ids[missing][0])} is observed but has no truth "
                           f"position")
    pose = truth.poses[step_t]
    lxy = truth.landmarks_xy[idx]
    pred = pair_bearings(pose, lxy)
    return angle_residual(meas, pred), step_t, ids


def robust_bearing_stats(residual_rad: np.ndarray) -> dict[str, Any]:
    """Bias, robust spread, outliers and the resulting bearing sigma of residuals.

    Parameters
    ----------
    residual_rad : ndarray of shape (m,)

    Returns
    -------
    dict
        ``n``, ``bias_rad`` (median), ``spread_rad`` (1.4826 MAD), ``n_outliers``
        (``|r - median| > OUTLIER_MADS * max(spread, MIN_BEARING_SIGMA_RAD)``),
        ``outlier_rate``, ``n_gross`` (``|r| >
        GROSS_OUTLIER_RAD``), ``inlier_std_rad`` (about the inlier mean), ``sigma_rad`` (RMS of
        inliers about zero: bias included; at least ``MIN_BEARING_SIGMA_RAD``),
        ``max_abs_rad``.
    """
    r = np.asarray(residual_rad, dtype=float)
    if r.size < 2:
        raise DatasetError(f"need at least 2 bearing residuals to calibrate, got {r.size}")
    med = float(np.median(r))
    spread = 1.4826 * float(np.median(np.abs(r - med)))
    out = np.abs(r - med) > OUTLIER_MADS * max(spread, MIN_BEARING_SIGMA_RAD)
    inl = r[~out]
    return {"n": int(r.size), "bias_rad": med, "spread_rad": spread,
            "n_outliers": int(out.sum()), "outlier_rate": float(out.mean()),
            "n_gross": int((np.abs(r) > GROSS_OUTLIER_RAD).sum()),
            "inlier_std_rad": float(np.std(inl)),
            "sigma_rad": max(float(np.sqrt(np.mean(inl ** 2))), MIN_BEARING_SIGMA_RAD),
            "max_abs_rad": float(np.max(np.abs(r)))}


def odometry_sigma_model(model: np.ndarray, odoms: np.ndarray) -> np.ndarray:
    """Evaluate the sigma model ``sqrt(a^2 + (b l)^2 + (c |dpsi|)^2)`` per component.

    Parameters
    ----------
    model : array of shape (3, 3)
        Row j = ``(a_j, b_j, c_j)`` for component j of ``[dx, dy, dpsi]``.
    odoms : array of shape (T, 3)

    Returns
    -------
    ndarray of shape (T, 3)
    """
    m = np.asarray(model, dtype=float)
    u = np.asarray(odoms, dtype=float).reshape(-1, 3)
    reg = np.column_stack([np.ones(len(u)), np.hypot(u[:, 0], u[:, 1]), np.abs(u[:, 2])])
    return np.sqrt((reg ** 2) @ (m ** 2).T)


def fit_odometry_sigma(odoms: np.ndarray, errors: np.ndarray) -> tuple[np.ndarray, dict]:
    """Fit the odometry sigma model to observed increment errors (maximum likelihood).

    Parameters
    ----------
    odoms : ndarray of shape (T, 3)
        The odometry increments (regressors: ``l = |(dx, dy)|`` and ``|dpsi|``).
    errors : ndarray of shape (T, 3)
        ``odom - true increment`` per step (heading wrapped).

    Returns
    -------
    model : ndarray of shape (3, 3)
        Row j = ``(a_j, b_j, c_j)``; ``a_j >= 1e-4``.
    info : dict
        ``n_steps``, ``n_excluded`` (errors beyond 5 fitted sigmas, excluded from the refit),
        ``mean_error`` per component.
    """
    u = np.asarray(odoms, dtype=float).reshape(-1, 3)
    e = np.asarray(errors, dtype=float).reshape(-1, 3)
    if len(u) < 6:
        raise DatasetError(f"need at least 6 steps to calibrate the odometry sigma, got "
                           f"{len(u)}; use smaller keyframe thresholds, or the default sigmas "
                           f"(--no-calibrate, calibrate=False)")
    reg2 = np.column_stack([np.ones(len(u)), np.hypot(u[:, 0], u[:, 1]) ** 2, u[:, 2] ** 2])
    model = np.zeros((3, 3))
    keep = np.ones(len(u), dtype=bool)
    for _ in range(2):
        for j in range(3):
            model[j] = _fit_variance(reg2[keep], e[keep, j] ** 2)
        z = np.abs(e) / odometry_sigma_model(model, u)
        keep = np.all(z <= 5.0, axis=1)
    return model, {"n_steps": int(len(u)), "n_excluded": int((~keep).sum()),
                   "mean_error": [float(v) for v in e[keep].mean(axis=0)]}


def _fit_variance(reg2: np.ndarray, e2: np.ndarray) -> np.ndarray:
    """``(a, b, c) >= 0`` maximising the Gaussian likelihood with var = reg2 @ (a,b,c)^2."""
    # here: scipy.optimize takes 0.3 s to import, and a recording's cache key imports this
    # module (through the importers' declared inputs) without calibrating anything
    from scipy.optimize import minimize, nnls

    floor2 = _MIN_SIGMA_FLOOR ** 2
    start, _ = nnls(reg2, e2)
    start = np.maximum(start, [floor2, 0.0, 0.0])
    scale = np.maximum(start, floor2)

    def nll(p: np.ndarray) -> tuple[float, np.ndarray]:
        theta = p * scale
        var = reg2 @ theta
        val = float(np.sum(np.log(var) + e2 / var))
        grad = (reg2 * (1.0 / var - e2 / var ** 2)[:, None]).sum(axis=0) * scale
        return val, grad

    res = minimize(nll, start / scale, jac=True, method="L-BFGS-B",
                   bounds=[(floor2 / scale[0], None), (0.0, None), (0.0, None)])
    theta = (res.x if res.success or res.fun <= nll(start / scale)[0] else start / scale) * scale
    return np.sqrt(np.maximum(theta, 0.0))


def odometry_errors(odoms: np.ndarray, truth_poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Errors of odometry increments against consecutive truth poses.

    Parameters
    ----------
    odoms : ndarray of shape (T, 3)
        ``[dx_m, dy_m, dpsi_rad]`` from pose t to t+1 in the frame of pose t.
    truth_poses : ndarray of shape (T + 1, 3)

    Returns
    -------
    errors : ndarray of shape (T, 3)
        ``odoms - true increment``, heading by :func:`~bomgraph.angles.angle_residual`.
    true_increments : ndarray of shape (T, 3)
    """
    true_inc = between(truth_poses[:-1], truth_poses[1:])
    err = odoms - true_inc
    err[:, 2] = angle_residual(odoms[:, 2], true_inc[:, 2])
    return err, true_inc


def odometry_length_ratio(odoms: np.ndarray, truth_poses: np.ndarray) -> float | None:
    """The odometry's length scale against the truth: ``sum |true step| / sum |odometry
    step|`` over the steps (translation only), or None without a step that moved.

    Bearings cannot observe a map's scale; the odometry sets it, so a robot whose velocity
    commands over-read the distance driven maps everything that much too large. This is the
    factor to multiply the odometry's lengths by (``import_mrclam(..., odometry_scale=)``,
    CLI ``--odometry-scale``). A ratio of path lengths, not a median of per-step ratios:
    short steps' ratios are dominated by noise, and the sum is the same at any keyframing
    (MRCLAM6: 0.938 and 0.938 for robot 2 at 0.3 m / 0.3 rad and at 0.1 m / 10 deg; ninth
    session, ``docs/measurements.md``). Noise inflates each odometry length by about
    ``sigma_lateral^2 / (2 l)``: 0.2 % at 0.1 m steps with 2 cm of lateral noise.

    Parameters
    ----------
    odoms : ndarray of shape (T, 3)
    truth_poses : ndarray of shape (T + 1, 3)
    """
    true_inc = between(truth_poses[:-1], truth_poses[1:])
    lo = float(np.hypot(odoms[:, 0], odoms[:, 1]).sum())
    if not lo > 0:
        return None
    return float(np.hypot(true_inc[:, 0], true_inc[:, 1]).sum()) / lo


def calibrate_odometry(odoms: np.ndarray, regress: np.ndarray, truth_poses: np.ndarray,
                       min_distance_m: float, min_turn_rad: float) -> tuple[np.ndarray, dict]:
    """Fit the odometry sigma model of a keyframed run against its truth poses.

    Parameters
    ----------
    odoms : ndarray of shape (T, 3)
        ``[dx_m, dy_m, dpsi_rad]`` per step (heading wrapped).
    regress : ndarray of shape (T, 3)
        The model's regressors: ``odoms`` with the whole (unwrapped) turn as third column.
    truth_poses : ndarray of shape (T + 1, 3)
    min_distance_m, min_turn_rad : float
        Steps longer (turning more) than half of these give the length (turn) ratios.

    Returns
    -------
    model : ndarray of shape (3, 3)
        :func:`fit_odometry_sigma` of the errors ``odom - between(truth_{t-1}, truth_t)``.
    info : dict
        The fit's info plus ``length_ratio_truth_over_odometry``,
        ``turn_ratio_truth_over_odometry`` (medians, None without such steps), ``rms_error``.
    """
    err, true_inc = odometry_errors(odoms, truth_poses)
    model, info = fit_odometry_sigma(regress, err)
    lo = np.hypot(odoms[:, 0], odoms[:, 1])
    lt = np.hypot(true_inc[:, 0], true_inc[:, 1])
    moving = lo > 0.5 * min_distance_m
    turning = np.abs(odoms[:, 2]) > 0.5 * min_turn_rad
    info["length_ratio_truth_over_odometry"] = (
        float(np.median(lt[moving] / lo[moving])) if moving.any() else None)
    info["turn_ratio_truth_over_odometry"] = (
        float(np.median(true_inc[turning, 2] / odoms[turning, 2])) if turning.any()
        else None)
    info["rms_error"] = [float(v) for v in np.sqrt(np.mean(err ** 2, axis=0))]
    return model, info


__all__ = ["bearing_residuals", "robust_bearing_stats", "odometry_errors", "odometry_sigma_model",
           "odometry_length_ratio",
           "fit_odometry_sigma", "calibrate_odometry", "GROSS_OUTLIER_RAD", "OUTLIER_MADS",
           "MIN_BEARING_SIGMA_RAD"]
