"""What an imported stream holds, in the one line ``bomgraph import`` prints after ``wrote
OUT:`` (moved out of :mod:`bomgraph.cli`, h92): steps, bearings, landmarks, the sigmas with
their units, the priors a g2o file carried (its ``# bomgraph header``), a g2o ``FIX`` (a
gauge, recorded in meta and used by no method) and what truth there is."""

from __future__ import annotations

import numpy as np

from ..stream import Stream
from ..tables import counted


def import_summary(stream: Stream) -> str:
    """The summary of an imported ``stream``: ``N steps, N bearings, N landmarks; bearing
    sigma S rad, odometry sigma [per step, median] X m, Y m, T rad[; N priors (landmark
    distances)][; FIX of vertex V (step t) not used: a gauge]; truth: ...`` (the bracketed
    parts only when there are some; ``no odometry`` for the sigmas of a single pose)."""
    header = stream.header
    n_brg = sum(len(st.landmark_ids) for st in stream.steps)
    moved = [st for st in stream.steps if st.odom is not None]
    odo, per_step = header.odometry_sigma, ""
    if any(st.odom_sigma is not None for st in moved):  # each step has its own
        odo = tuple(np.median([st.odometry_sigma(header) for st in moved], axis=0))
        per_step = "per step, median "
    # one pose, no odometry (h93): not "odometry sigma 0.0000 m, ...", as if it were exact
    odo_s = (f"odometry sigma {per_step}{odo[0]:.4f} m, {odo[1]:.4f} m, {odo[2]:.4f} rad"
             if moved else "no odometry")
    parts = [f"{counted(len(stream.steps), 'step')}, {counted(n_brg, 'bearing')}, "
             f"{counted(len(stream.landmark_ids()), 'landmark')}",
             f"bearing sigma {header.bearing_sigma_rad:.4f} rad, {odo_s}"]
    if header.priors:
        parts.append(f"{counted(len(header.priors), 'prior')} (landmark distances)")
    fixed = (header.meta or {}).get("fixed_vertex_ids") or []
    if fixed:
        steps = (header.meta or {}).get("fixed_steps") or []
        where = "" if len(fixed) != 1 or len(steps) != 1 else f" (step {steps[0]})"
        ids = ", ".join(str(v) for v in fixed[:5]) + (", ..." if len(fixed) > 5 else "")
        parts.append(f"FIX of {'vertex' if len(fixed) == 1 else 'vertices'} {ids}{where} "
                     f"not used: a gauge")
    parts.append("no truth" if stream.truth is None else (
        "truth: landmarks only" if stream.truth.poses is None else "truth: poses + landmarks"))
    return "; ".join(parts)


__all__ = ["import_summary"]
