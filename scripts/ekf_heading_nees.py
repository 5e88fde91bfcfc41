"""Heading consistency of an EKF baseline on a stream with truth poses, step by step.

Runs ``ekf`` or ``ekf-invdepth`` on a stream file and prints, every ``--every`` steps, the
error of the filtered heading against the stream's truth, its std. dev., the heading NEES and
the error of the robot position; then the time-averaged heading NEES, the share of steps
beyond the 99 % chi-square (1 dof) quantile, and the largest information any bearing update
added along the unobservable directions (global translation and rotation, the filter's
``nullspace`` ``N``: ``max |(H N)^T S^-1 (H N)|``). The filter's map frame is its first pose,
which the mapper takes as the origin: the truth is expressed in the frame of its own first pose.

Usage::

    python scripts/ekf_heading_nees.py STREAM [--method ekf-invdepth] [--every 5]
                                       [--option preset=real ...]

Options are parsed by ``bomgraph.jsonio.parse_options``; ``preset=real`` is the default.
docs/measurements.md holds what it measured.
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.stats import chi2

from baselines.ekf import filter as ekf_filter
from bomgraph.angles import angle_residual
from bomgraph.geometry import rotation
from bomgraph.jsonio import parse_options
from bomgraph.mapper import create_mapper
from bomgraph.stream_file import StreamReader


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("stream")
    ap.add_argument("--method", default="ekf-invdepth", choices=["ekf", "ekf-invdepth"])
    ap.add_argument("--every", type=int, default=5)
    ap.add_argument("--option", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args()
    options = {"preset": "real", **parse_options(args.option)}

    worst = [0.0]
    update = ekf_filter.BearingEkf.update_compact

    def checked_update(self, cols, hu, y, var):        # the information added along N
        hn = hu @ self.nullspace[cols]
        s = hu @ self.P[np.ix_(cols, cols)] @ hu.T + np.diag(var)
        worst[0] = max(worst[0], float(np.abs(hn.T @ np.linalg.solve(s, hn)).max()))
        return update(self, cols, hu, y, var)

    ekf_filter.BearingEkf.update_compact = checked_update
    with StreamReader(args.stream) as reader:
        mapper = create_mapper(args.method, reader.header, **options)
        rows = []
        first = None
        for step in reader:
            mapper.step(step)
            true = reader.truth.poses[step.t] if reader.truth.poses is not None else None
            if true is None:
                raise SystemExit("the stream has no truth poses")
            if first is None:
                first = true
            rel = rotation(-first[2]) @ (true[:2] - first[:2])
            x, cov = mapper.filter.x[:3], mapper.filter.P[:3, :3]
            e_psi = float(angle_residual(x[2], angle_residual(true[2], first[2])))
            nees = e_psi * e_psi / cov[2, 2] if cov[2, 2] > 0 else np.nan
            rows.append((step.t, e_psi, np.sqrt(cov[2, 2]), nees, np.hypot(*(x[:2] - rel))))
    rows = np.array(rows)
    print(f"{args.method} {options} on {args.stream}")
    print("    t   e_psi_rad  sd_psi_rad  nees_psi  e_pos_m")
    for i in sorted(set(range(0, len(rows), args.every)) | {len(rows) - 1}):
        t, e, sd, nees, ep = rows[i]
        print(f"{int(t):5d}  {e:+9.3f}  {sd:10.4f}  {nees:8.1f}  {ep:7.3f}")
    nees = rows[1:, 3]
    print(f"mean heading NEES {np.nanmean(nees):.2f} (1 if consistent); "
          f"{100 * np.mean(nees > chi2.ppf(0.99, 1)):.0f} % of steps above the 99 % quantile; "
          f"largest information along N {worst[0]:.2e}")


if __name__ == "__main__":
    main()
