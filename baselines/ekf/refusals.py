"""The EKF mappers' refusals of values of a valid stream (an odometry increment or sigma the
predict overflows on; the refusals every method shares, a bearing sigma above pi among them,
are :mod:`bomgraph.method_limits`'s) as :class:`StreamValueError`: they name
the step and the field, and ``bomgraph run`` and ``compare`` name the stream's file and line
(:func:`bomgraph.stream_file.located`), as they do for the reader's refusals and STMDS's."""

from __future__ import annotations

import math

import numpy as np

from bomgraph.errors import StreamValueError
from bomgraph.stream import Step, StreamHeader

from .filter import FilterNumericalError


def odometry_refusal(exc: FilterNumericalError, step: Step,
                     header: StreamHeader) -> StreamValueError:
    """Step ``step``'s predict overflowed (``exc``): the refusal names the field at fault,
    the larger of the move and its sigma: ``odom``, else the step's ``odom_sigma`` or, when
    the step has none, the header's ``odometry_sigma`` (line 1)."""
    odom = np.abs(np.asarray(step.odom, float))
    sigma = np.abs(np.asarray(step.odometry_sigma(header), float))
    if not float(np.nanmax(sigma, initial=0.0)) > float(np.nanmax(odom, initial=0.0)):
        key, t, what = "odom", step.t, "odometry"
    elif step.odom_sigma is not None:
        key, t, what = "odom_sigma", step.t, "sigmas"
    else:
        key, t, what = "odometry_sigma", None, "sigmas"
    whose = "this step's" if t is not None else f"step {step.t}'s"
    return StreamValueError(f"the EKF cannot use {whose} odometry: {exc}; fix the stream's "
                            f"{what}", t=t, key=key, method="the EKF")


#: The largest odometry std. dev. (m or rad, header or step) the EKFs accept (h151): a step
#: of 3e5 m left ``ekf-invdepth``'s landmark covariances not positive semi-definite (their
#: 1e-3 m^2 entries beside a pose variance of 1e11 m^2: the estimate was refused as it was
#: written, naming no line of the stream), one of 1e100 m overflowed the predict 18 steps
#: later, at that step's line; 1e5 m (the reader's warning, ``MAX_STEP_ODOMETRY_SIGMA``) in
#: every 7th step of a 300-step run, or in the header, maps as before in both EKFs.
MAX_EKF_SIGMA = 1e5

#: The most sub-steps ``max_predict_turn_rad`` splits one step's predict into (h148: a step
#: turning 1e12 rad, which the reader accepts with a warning, was 2e12 predicts, without end).
MAX_PREDICT_SUBSTEPS = 10_000


def predict_substeps(turn: float, max_turn: float | None) -> int:
    """How many sub-steps a step turning ``turn`` rad is predicted in: one without
    ``max_predict_turn_rad``, else ``ceil(|turn| / max_turn)``, refused as
    :class:`FilterNumericalError` (which :func:`odometry_refusal` names) beyond
    :data:`MAX_PREDICT_SUBSTEPS`."""
    if max_turn is None:
        return 1
    ratio = abs(turn) / max_turn
    if not ratio <= MAX_PREDICT_SUBSTEPS:
        raise FilterNumericalError(
            f"it turns {turn:g} rad, more than {MAX_PREDICT_SUBSTEPS:,} predicts of "
            f"max_predict_turn_rad = {max_turn:g} rad each")
    return max(math.ceil(ratio), 1)


__all__ = ["MAX_EKF_SIGMA", "MAX_PREDICT_SUBSTEPS", "odometry_refusal", "predict_substeps"]
