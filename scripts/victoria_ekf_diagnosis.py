"""Why the EKF baselines lose Victoria Park: the evidence behind docs/measurements.md
("The EKFs on Victoria Park: the odometry's heading error is not white").

    python scripts/victoria_ekf_diagnosis.py [--data FILE] [--reference EST] [--causal-steps 1000]
                                             [--seed 0] [--filter-option KEY=VALUE ...]

There is no ground truth; ``gtsam-batch``'s map and trajectory stand in for it (the reference:
``--reference`` an estimate file written by ``scripts/victoria_map.py`` into ``estimates/``,
else it is run here, about a minute). Five parts, each printed as a table:

1. **Odometry.** The file's heading increments against the reference's, summed over windows of
   ``n`` steps, beside the ``sqrt(n) sigma_psi`` the declared (white) covariance gives them. A
   white error keeps the ratio near 1 at every ``n``.
2. **Timeline.** Each EKF's heading error against the reference, its own heading std. dev.,
   and the dead-reckoned heading's error; for the first ``--causal-steps`` steps also the
   latest pose of ``gtsam-batch`` run on the data up to that step only (checkpoints every 10
   steps): what the same data allow a causal estimator at that step.
3. **Updates.** For the whole run: bearings gated, not used for nonlinearity, and used; the NIS
   of the bearings used; the RMS residual of each step's bearings against the filter's pose and
   map at that step (after its update), beside the README's bearing RMS (the filtered poses
   against the final map): how much of that column is the metric pairing poses and a map of
   different times.
4. **Synthetic Victoria.** The reference map and trajectory as truth, the file's steps, landmark
   ids and per-step sigmas. A: white odometry noise at the declared sigmas and simulated
   bearings; B: the file's odometry and simulated bearings; C: white odometry and the file's
   bearings. The EKFs as registered (no option changed).
5. **A lean range-bearing EKF** (independent of ``baselines.ekf``: textbook EKF-SLAM, the file's
   ranges kept, its covariances, a chi-square gate at 0.999), with the declared heading sigma
   and with it times 3 and 10 (a diagnosis, not a setting).

``--filter-option`` adds an option to every EKF of parts 2-4 (e.g. ``gate_probability=1``:
the gate off, to see what the gated bearings would have done; a diagnosis, not a setting).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from scipy.stats import chi2

from bomgraph.angles import angle_residual, wrap_angle
from bomgraph.datasets.victoria import import_victoria
from bomgraph.errors import DatasetError, StreamFormatError
from bomgraph.estimate_file import read_estimate
from bomgraph.geometry import between, chain_odometry
from bomgraph.jsonio import parse_options
from bomgraph.mapper import MapEstimate, create_mapper, run
from bomgraph.stream import Step, Stream
from bomgraph.trajectory import bearing_residuals

ROOT = Path(__file__).resolve().parents[1]
DATA = (Path(os.environ.get("BOMGRAPH_DATA", ROOT.parent / "shared" / "data"))
        / "victoria_park" / "victoria_park.txt")
#: The filters examined: (label, registered method, options).
FILTERS = [("ekf", "ekf", {}), ("ekf (real)", "ekf", {"preset": "real"}),
           ("ekf-invdepth", "ekf-invdepth", {}),
           ("ekf-invdepth (real)", "ekf-invdepth", {"preset": "real"})]
WINDOWS = (1, 10, 30, 100, 300, 1000)


def reference(stream: Stream, path: str | None) -> MapEstimate:
    """``gtsam-batch``'s final estimate: read from ``path``, else run (checkpoints every 100
    steps, as scripts/victoria_map.py does)."""
    if path is not None:
        return read_estimate(path).final
    return run(create_mapper("gtsam-batch", stream.header), stream.steps,
               checkpoint_every=100).final


def odometry_heading_windows(steps: Sequence[Step], poses: np.ndarray, sigma_psi_rad: float,
                             windows: Sequence[int] = WINDOWS) -> dict[str, Any]:
    """The odometry's heading error against ``poses`` (the reference, one per step).

    Returns ``{"per_step": e (T-1,), "windows": [(n, rms of the sums of n consecutive errors,
    sqrt(n) sigma_psi_rad)], "autocorrelation": {lag: r}}`` (empty for a constant error); ``e = psi_ref increment - odometry
    dpsi`` [rad].
    """
    odom = np.array([st.odom for st in steps[1:]], float)
    e = angle_residual(between(poses[:-1], poses[1:])[:, 2], odom[:, 2])
    rows = []
    for n in windows:
        k = len(e) // n
        if k:
            sums = e[:k * n].reshape(k, n).sum(1)
            rows.append((n, float(np.sqrt(np.mean(sums ** 2))), math.sqrt(n) * sigma_psi_rad))
    z = e - e.mean()
    var = float(z @ z)
    auto = ({lag: float(z[:-lag] @ z[lag:]) / var for lag in (1, 5, 20, 100) if lag < len(z)}
            if var > 0 else {})       # a constant error has no autocorrelation to give
    return {"per_step": e, "windows": rows, "autocorrelation": auto}


def filter_trace(stream: Stream, method: str, options: dict[str, Any],
                 ref_poses: np.ndarray) -> dict[str, Any]:
    """Run one EKF step by step and record, per step: heading error against ``ref_poses`` and
    the filter's heading std. dev.; over the run: gated / nonlinear / used bearings, the NIS of
    the bearings used, the residuals of each step's bearings against the filter's pose and map
    at that step, and the README's metric (filtered poses against the final map)."""
    mapper = create_mapper(method, stream.header, **options)
    filt = mapper.filter
    nis: list[np.ndarray] = []
    apply = filt._apply                 # every update ends here: record y^2 / (H P H^T + R)

    def recording(hp: np.ndarray, s: np.ndarray, y: np.ndarray, var: np.ndarray) -> None:
        nis.append(y ** 2 / (np.diag(s) + var))
        apply(hp, s, y, var)

    filt._apply = recording
    herr = np.zeros(len(stream.steps))
    hsd = np.zeros(len(stream.steps))
    at_time = []
    for k, st in enumerate(stream.steps):
        mapper.step(st)
        x = mapper.filter.x
        herr[k] = angle_residual(x[2], ref_poses[st.t, 2])
        hsd[k] = math.sqrt(mapper.filter.P[2, 2])
        if st.landmark_ids.size:
            est = mapper.estimate()
            if len(est):
                at_time.append(bearing_residuals(est.landmark_ids, est.landmarks_xy,
                                                 est.pose_t[-1:], est.poses[-1:], [st]))
    final = mapper.estimate()
    metric = bearing_residuals(final.landmark_ids, final.landmarks_xy, final.pose_t,
                               final.poses, stream.steps)
    return {"herr": herr, "hsd": hsd, "nis": np.concatenate(nis or [np.zeros(0)]),
            "at_time": np.concatenate(at_time or [np.zeros(0)]), "metric": metric,
            "gated": final.info["gated_bearings"], "nonlinear": final.info["nonlinear_bearings"],
            "used": final.info["used_bearings"], "landmarks": len(final)}


def causal_headings(stream: Stream, n_steps: int, every: int = 10) -> dict[int, float]:
    """``gtsam-batch``'s latest heading at each checkpoint, from the data up to it only."""
    res = run(create_mapper("gtsam-batch", stream.header), stream.steps[:n_steps],
              checkpoint_every=every)
    out = {}
    for c in res.checkpoints:
        e = c.estimate
        if e.poses is not None and len(e.pose_t):
            out[int(e.pose_t[-1])] = float(e.poses[-1, 2])
    return out


def victoria_like(stream: Stream, ref: MapEstimate, variant: str,
                  rng: np.random.Generator) -> Stream:
    """A stream on ``ref``'s map and trajectory with the file's steps and landmark ids.

    ``"A"``: odometry ``between(ref) + N(0, sigma)`` at each step's own sigmas, bearings from
    ``ref`` plus ``N(0, bearing_sigma)`` (only the landmarks ``ref`` maps); ``"B"``: the
    file's odometry, bearings as in A; ``"C"``: odometry as in A, the file's bearings.
    """
    poses = ref.poses
    xy = dict(zip(ref.landmark_ids.tolist(), ref.landmarks_xy))
    sb = stream.header.bearing_sigma_rad
    steps = []
    for st in stream.steps:
        odom = st.odom
        if st.t and variant in ("A", "C"):
            odom = between(poses[st.t - 1], poses[st.t]) + rng.normal(
                0.0, st.odometry_sigma(stream.header))
        ids, z = st.landmark_ids, st.bearings_rad
        if variant in ("A", "B"):
            ids = np.array([i for i in ids.tolist() if i in xy], np.int64)
            q = np.array([xy[i] for i in ids.tolist()]).reshape(-1, 2)
            z = wrap_angle(np.arctan2(q[:, 1] - poses[st.t, 1], q[:, 0] - poses[st.t, 0])
                           - poses[st.t, 2] + rng.normal(0.0, sb, len(ids)))
        steps.append(Step(t=st.t, odom=odom, landmark_ids=ids, bearings_rad=z,
                          odom_sigma=st.odom_sigma))
    return Stream(stream.header, tuple(steps), None)


def read_ranges(path: str | os.PathLike[str]) -> tuple[list[tuple[np.ndarray, np.ndarray]],
                                                       list[list[tuple[int, float, float]]]]:
    """GTSAM's Victoria file with its ranges: per step of the odometry chain, the odometry
    ``(u, covariance (3, 3))`` that leads to it (step 0: none) and ``[(id, range_m,
    bearing_rad)]``. (The importer drops the ranges; this reader is for part 5 only.)"""
    odo: dict[int, tuple[int, np.ndarray, np.ndarray]] = {}
    seen: dict[int, list[tuple[int, float, float]]] = {}
    with open(path, encoding="utf-8") as fh:
        for line in fh:
            tok = line.split()
            if tok and tok[0] == "ODOMETRY":
                c = [float(v) for v in tok[6:12]]
                cov = np.array([[c[0], c[1], c[2]], [c[1], c[3], c[4]], [c[2], c[4], c[5]]])
                odo[int(tok[1])] = (int(tok[2]), np.array([float(v) for v in tok[3:6]]), cov)
            elif tok and tok[0] == "LANDMARK":
                x, y = float(tok[3]), float(tok[4])
                seen.setdefault(int(tok[1]), []).append((int(tok[2]), math.hypot(x, y),
                                                        math.atan2(y, x)))
    starts = set(odo) - {j for j, _, _ in odo.values()}
    pid = starts.pop()
    motion, sightings = [], []
    while True:
        sightings.append(seen.get(pid, []))
        if pid not in odo:
            break
        pid, u, cov = odo[pid]
        motion.append((u, cov))
    return motion, sightings


def lean_range_bearing_ekf(motion: Sequence[tuple[np.ndarray, np.ndarray]],
                           sightings: Sequence[Sequence[tuple[int, float, float]]],
                           ref_poses: np.ndarray, *, heading_sigma_scale: float = 1.0,
                           range_var_m2: float = 0.4, bearing_sigma_rad: float = 0.0504,
                           gate_probability: float = 0.999) -> dict[str, Any]:
    """Textbook EKF-SLAM with ranges and bearings, written apart from ``baselines.ekf``.

    The odometry covariance is the file's, in the frame of the pose left (the file's
    off-diagonal entries are zero and the turns small), with its heading variance times
    ``heading_sigma_scale**2``; a landmark enters at its first sighting; one update per
    sighting, gated on its 2-dof NIS. Returns the heading error against ``ref_poses`` and the
    heading std. dev. per step, the number gated and used, the final map ``{id: (2,)}``.
    """
    n_max = 3 + 2 * len({i for s in sightings for i, _, _ in s})
    x = np.zeros(n_max)
    P = np.zeros((n_max, n_max))  # noqa: N806
    n = 3
    where: dict[int, int] = {}
    R = np.diag([range_var_m2, bearing_sigma_rad ** 2])  # noqa: N806
    gate = float(chi2.ppf(gate_probability, 2))
    herr, hsd = np.zeros(len(sightings)), np.zeros(len(sightings))
    n_gated = n_used = 0
    for t, seen in enumerate(sightings):
        if t:
            u, cov = motion[t - 1]
            c, s = math.cos(x[2]), math.sin(x[2])
            F = np.array([[1, 0, -s * u[0] - c * u[1]], [0, 1, c * u[0] - s * u[1]], [0, 0, 1]])  # noqa: N806
            G = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])  # noqa: N806
            Q = np.diag(np.diag(cov) * [1, 1, heading_sigma_scale ** 2])  # noqa: N806
            x[:3] = [x[0] + c * u[0] - s * u[1], x[1] + s * u[0] + c * u[1],
                     wrap_angle(x[2] + u[2])]
            P[:3, 3:n] = F @ P[:3, 3:n]
            P[3:n, :3] = P[:3, 3:n].T
            P[:3, :3] = F @ P[:3, :3] @ F.T + G @ Q @ G.T
        for lid, r, b in seen:
            if lid not in where:
                a = x[2] + b
                c, s = math.cos(a), math.sin(a)
                gx = np.array([[1, 0, -r * s], [0, 1, r * c]])
                gz = np.array([[c, -r * s], [s, r * c]])
                where[lid] = n
                x[n:n + 2] = [x[0] + r * c, x[1] + r * s]
                P[n:n + 2, :n] = gx @ P[:3, :n]
                P[:n, n:n + 2] = P[n:n + 2, :n].T
                P[n:n + 2, n:n + 2] = gx @ P[:3, :3] @ gx.T + gz @ R @ gz.T
                n += 2
                continue
            j = where[lid]
            d = x[j:j + 2] - x[:2]
            q = float(d @ d)
            rr = math.sqrt(q)
            H = np.zeros((2, n))  # noqa: N806
            H[:, :3] = [[-d[0] / rr, -d[1] / rr, 0], [d[1] / q, -d[0] / q, -1]]
            H[:, j:j + 2] = [[d[0] / rr, d[1] / rr], [-d[1] / q, d[0] / q]]
            y = np.array([r - rr, angle_residual(b, math.atan2(d[1], d[0]) - x[2])])
            ph = P[:n, :n] @ H.T
            S = H @ ph + R  # noqa: N806
            if y @ np.linalg.solve(S, y) > gate:
                n_gated += 1
                continue
            K = np.linalg.solve(S, ph.T).T  # noqa: N806
            x[:n] += K @ y
            x[2] = wrap_angle(x[2])
            P[:n, :n] -= K @ S @ K.T
            n_used += 1
        herr[t] = angle_residual(x[2], ref_poses[t, 2])
        hsd[t] = math.sqrt(max(P[2, 2], 0.0))
    return {"herr": herr, "hsd": hsd, "gated": n_gated, "used": n_used,
            "map": {i: x[j:j + 2].copy() for i, j in where.items()}}


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(a ** 2))) if a.size else math.nan


def _nees(herr: np.ndarray, hsd: np.ndarray) -> float:
    ok = hsd > 0
    return float(np.mean(herr[ok] ** 2 / hsd[ok] ** 2))


def _data_error(path: str, exc: Exception) -> int:
    """One line on stderr for input that cannot be read (no traceback), and exit status 2."""
    hint = ("" if Path(path).exists() else "; the default is $BOMGRAPH_DATA/victoria_park/"
            "victoria_park.txt: set BOMGRAPH_DATA to the shared data folder, or pass --data FILE")
    print(f"{Path(__file__).name}: error: {exc}{hint}", file=sys.stderr)
    return 2


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=str(DATA), help="victoria_park.txt (GTSAM's format)")
    ap.add_argument("--reference", default=None,
                    help="gtsam-batch's estimate file (victoria_map.py's estimates/); "
                         "default: run it here")
    ap.add_argument("--causal-steps", type=int, default=1000,
                    help="steps over which gtsam-batch is also run causally (part 2)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the synthetic streams")
    ap.add_argument("--filter-option", action="append", default=[], metavar="KEY=VALUE",
                    help="an option given to every EKF of parts 2-4 (repeatable)")
    a = ap.parse_args(argv)
    extra = parse_options(a.filter_option)
    filters = [(lab, m, {**o, **extra}) for lab, m, o in FILTERS]
    try:
        stream = import_victoria(a.data)
        ref = reference(stream, a.reference)
    except (DatasetError, StreamFormatError) as exc:  # the data or the reference file
        return _data_error(a.data, exc)
    if ref.poses is None or len(ref.pose_t) != len(stream.steps):
        ap.error("the reference must hold a pose for every step of the stream")
    poses = ref.poses
    sigma_psi = float(np.median([st.odometry_sigma(stream.header)[2] for st in stream.steps[1:]]))

    print("1. The file's odometry heading error against gtsam-batch's trajectory")
    od = odometry_heading_windows(stream.steps, poses, sigma_psi)
    e = od["per_step"]
    print(f"   per step: RMS {_rms(e):.5f} rad = {_rms(e) / sigma_psi:.2f} sigma_psi, mean "
          f"{e.mean():.5f} rad = {e.mean() / sigma_psi:.2f} sigma_psi; autocorrelation "
          + ", ".join(f"lag {k}: {v:.2f}" for k, v in od["autocorrelation"].items()))
    print(f"   {'n steps':>8} {'RMS of sums':>12} {'sqrt(n) sigma':>14} {'ratio':>6}")
    for n, rms, declared in od["windows"]:
        print(f"   {n:>8} {rms:>12.4f} {declared:>14.4f} {rms / declared:>6.1f}")

    print("\n2. Heading error against gtsam-batch (rad): filters, dead reckoning, causal batch")
    _, dr_psi = chain_odometry(np.array([st.odom for st in stream.steps[1:]], float))
    dr_err = angle_residual(dr_psi, poses[:, 2])
    causal = causal_headings(stream, min(a.causal_steps, len(stream.steps)))
    traces = {label: filter_trace(stream, m, o, poses) for label, m, o in filters}
    labels = [lab for lab, _, _ in filters]
    print(f"   {'t':>5} {'DR':>7} {'causal':>7} " + " ".join(f"{lab:>19}" for lab in labels))
    marks = sorted(set(range(0, min(a.causal_steps, len(poses)), 50))
                   | set(range(0, len(poses), 500)) | {len(poses) - 1})
    for t in marks:
        c = causal.get(t)
        cs = f"{angle_residual(c, poses[t, 2]):7.3f}" if c is not None else f"{'':>7}"
        print(f"   {t:>5} {dr_err[t]:7.3f} {cs} " + " ".join(
            f"{traces[lab]['herr'][t]:>10.3f} sd {traces[lab]['hsd'][t]:.3f}" for lab in labels))

    print("\n3. Updates over the whole run (rad)")
    print(f"   {'filter':<20} {'lm':>4} {'gated':>6} {'nonlin':>6} {'used':>6} {'NIS mean':>8} "
          f"{'median':>7} {'at-time RMS':>11} {'(n)':>6} {'metric RMS':>10} {'(n)':>6} "
          f"{'heading NEES':>12}")
    for lab in labels:
        tr = traces[lab]
        print(f"   {lab:<20} {tr['landmarks']:>4} {tr['gated']:>6} {tr['nonlinear']:>6} "
              f"{tr['used']:>6} {tr['nis'].mean():>8.2f} {np.median(tr['nis']):>7.3f} "
              f"{_rms(tr['at_time']):>11.3f} {tr['at_time'].size:>6} {_rms(tr['metric']):>10.3f} "
              f"{tr['metric'].size:>6} {_nees(tr['herr'], tr['hsd']):>12.1f}")

    print("\n4. Synthetic Victoria on gtsam-batch's map and trajectory (rad; heading vs the truth)")
    print(f"   {'variant':<44} {'filter':<20} {'lm':>4} {'gated':>6} {'at-time RMS':>11} "
          f"{'metric RMS':>10} "
          f"{'|heading err| med':>17} {'max':>6} {'heading NEES':>12}")
    names = {"A": "A: white odometry, simulated bearings",
             "B": "B: the file's odometry, simulated bearings",
             "C": "C: white odometry, the file's bearings"}
    for variant, name in names.items():
        syn = victoria_like(stream, ref, variant, np.random.default_rng(a.seed))
        for lab, m, o in filters:
            tr = filter_trace(syn, m, o, poses)
            print(f"   {name:<44} {lab:<20} {tr['landmarks']:>4} {tr['gated']:>6} "
                  f"{_rms(tr['at_time']):>11.3f} {_rms(tr['metric']):>10.3f} {np.median(np.abs(tr['herr'])):>17.3f} "
                  f"{np.abs(tr['herr']).max():>6.3f} {_nees(tr['herr'], tr['hsd']):>12.1f}")

    print("\n5. A lean range-bearing EKF (not baselines.ekf) on the file, ranges kept")
    motion, sightings = read_ranges(a.data)
    ref_xy = dict(zip(ref.landmark_ids.tolist(), ref.landmarks_xy))
    for scale in (1.0, 3.0, 10.0):
        lean = lean_range_bearing_ekf(motion, sightings, poses, heading_sigma_scale=scale,
                                      bearing_sigma_rad=stream.header.bearing_sigma_rad)
        both = [i for i in ref_xy if i in lean["map"]]
        err = np.array([lean["map"][i] - ref_xy[i] for i in both])
        print(f"   heading sigma x{scale:<4g} gated {lean['gated']:>5} used {lean['used']:>5}; "
              f"|heading err| median {np.median(np.abs(lean['herr'])):.3f} max "
              f"{np.abs(lean['herr']).max():.3f}; heading NEES {_nees(lean['herr'], lean['hsd']):.1f}; "
              f"landmarks vs gtsam-batch (no alignment) RMS {_rms(np.hypot(*err.T)):.2f} m over "
              f"{len(both)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
