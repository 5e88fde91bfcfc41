"""Import every real dataset and print what a mapper will face (issue 7, parts 1-3 and 6).

For MRCLAM6 robots 1-5 (calibrated against their ground truth): keyframes, rows kept and
dropped, landmarks per keyframe, landmarks shared by consecutive keyframes and their parallax,
calibrated sigmas, bearing bias, outlier rate and field of view, both at the raw measurement
times and at the keyframes. The pooled fit over the five robots is what
``bomgraph.datasets.mrclam`` uses as its defaults when it cannot calibrate (mrclam1). Then
MRCLAM1 (no robot truth), the bearing-only g2o set and Victoria Park.

    python scripts/inspect_datasets.py                 # the statistics
    python scripts/inspect_datasets.py --sweep         # + keyframe-threshold and delay sweeps
    python scripts/inspect_datasets.py --json out.json # also save the numbers

The sweeps are the measurements behind the defaults of ``KeyframeConfig``
(docs/measurements.md). ``BOMGRAPH_DATA`` sets the default data folder.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np

from bomgraph.angles import angle_residual
from bomgraph.datasets.g2o import import_g2o
from bomgraph.datasets.calibration import (bearing_residuals, fit_odometry_sigma,
                                           odometry_errors, odometry_sigma_model,
                                           robust_bearing_stats)
from bomgraph.datasets.mrclam import (KeyframeConfig, import_mrclam, integrate_odometry,
                                      odometry_poses_at, read_mrclam_robot)
from bomgraph.datasets.victoria import import_victoria
from bomgraph.jsonio import jsonable
from bomgraph.stream import Stream

DATA = Path(os.environ.get("BOMGRAPH_DATA",
                          Path(__file__).resolve().parents[2] / "shared" / "data"))


def consecutive_parallax(stream: Stream) -> tuple[np.ndarray, np.ndarray]:
    """Common-landmark counts of consecutive steps and the true parallax of each common one.

    Returns
    -------
    common : ndarray of shape (T-1,)
    parallax_rad : ndarray of shape (m,)
        Angle at the landmark between the rays from the two true poses.
    """
    truth = stream.truth
    if truth is None or truth.poses is None:
        return np.zeros(0), np.zeros(0)
    pos = dict(zip(truth.landmark_ids.tolist(), truth.landmarks_xy))
    common, par = [], []
    for a, b in zip(stream.steps[:-1], stream.steps[1:]):
        ids = np.intersect1d(a.landmark_ids, b.landmark_ids)
        common.append(ids.size)
        if ids.size:
            lxy = np.array([pos[i] for i in ids.tolist()])
            va = lxy - truth.poses[a.t, :2]
            vb = lxy - truth.poses[b.t, :2]
            par.append(np.abs(angle_residual(np.arctan2(vb[:, 1], vb[:, 0]),
                                             np.arctan2(va[:, 1], va[:, 0]))))
    return np.array(common), (np.concatenate(par) if par else np.zeros(0))


def step_odometry_errors(stream: Stream, data_dir: Path, robot: int,
                        keyframe: KeyframeConfig) -> tuple[np.ndarray, np.ndarray]:
    """The sigma-model regressors of steps 1.. and their odometry errors against the truth.

    The regressors are the odometry length and the whole (unwrapped) turn, recomputed from the
    raw odometry at the keyframe times, as the importer does.
    """
    odoms = np.array([s.odom for s in stream.steps[1:]])
    err, _ = odometry_errors(odoms, stream.truth.poses)
    od = read_mrclam_robot(data_dir, robot).odometry
    t = od["time_s"] + keyframe.command_delay_s
    poses = integrate_odometry(t, od["v_mps"], od["w_radps"])
    kf = odometry_poses_at(t, od["v_mps"], od["w_radps"], poses,
                           np.array([s.time_s for s in stream.steps]))
    regress = odoms.copy()
    regress[:, 2] = np.diff(kf[:, 2])
    return regress, err


def fmt(v: Any, nd: int = 4) -> str:
    return np.array2string(np.asarray(v, dtype=float), precision=nd, suppress_small=True)


def inspect_mrclam6(data: Path, out: dict) -> None:
    d = data / "mrclam6"
    print(f"== MRCLAM6 ({d}), default KeyframeConfig: {KeyframeConfig()}")
    pooled_r, pooled_u, pooled_e = [], [], []
    for robot in range(1, 6):
        s = import_mrclam(d, robot)
        m = s.header.meta
        k = np.array([len(st.landmark_ids) for st in s.steps])
        common, par = consecutive_parallax(s)
        r, _, _ = bearing_residuals(s)
        raw_stats = m["raw_bearing_check"]
        kf = m["bearing_calibration"]
        u, e = step_odometry_errors(s, d, robot, KeyframeConfig())
        z = e / np.array([st.odom_sigma for st in s.steps[1:]])
        span = s.steps[-1].time_s - s.steps[0].time_s
        pooled_r.append(r)
        pooled_u.append(u)
        pooled_e.append(e)
        rows = m["rows"]
        print(f"robot {robot}: {len(s.steps)} keyframes over {span:.0f} s from "
              f"{m['n_bursts']} bursts; rows {rows}")
        print(f"  landmarks per keyframe: mean {k.mean():.2f}, median {np.median(k):.0f}, "
              f"max {k.max()}; distinct landmarks {len(s.landmark_ids())}")
        print(f"  consecutive keyframes share {common.mean():.2f} landmarks on average; "
              f"parallax median {np.degrees(np.median(par)):.2f} deg, 90th pct "
              f"{np.degrees(np.percentile(par, 90)):.2f} deg, > 2 deg: "
              f"{(par > np.radians(2)).sum()}, > 5 deg: {(par > np.radians(5)).sum()} of "
              f"{par.size}")
        print(f"  raw detections: n {raw_stats['n']}, bias {raw_stats['bias_rad']:+.4f} rad, "
              f"spread (1.4826 MAD) {raw_stats['spread_rad']:.4f}, outliers (> 5 spreads) "
              f"{raw_stats['n_outliers']} ({100 * raw_stats['outlier_rate']:.2f} %), gross "
              f"(> 0.2 rad) {raw_stats['n_gross']}, max |r| {raw_stats['max_abs_rad']:.3f}, "
              f"FOV {fmt(raw_stats['fov_rad'], 3)} rad")
        print(f"  keyframe bearings: n {kf['n']}, bias {kf['bias_rad']:+.4f}, spread "
              f"{kf['spread_rad']:.4f}, outliers {kf['n_outliers']} "
              f"({100 * kf['outlier_rate']:.2f} %), gross {kf['n_gross']} -> header "
              f"bearing_sigma_rad {s.header.bearing_sigma_rad:.4f}; FOV "
              f"{fmt(m['bearing_fov_rad'], 3)} rad; sensor_range_m {s.header.sensor_range_m}")
        om = m["odometry_model"]
        print(f"  odometry sigma model (a, b, c) per [dx, dy, dpsi]: {fmt(om['abc'])}; header "
              f"odometry_sigma {fmt(s.header.odometry_sigma)}; rms error {fmt(om['rms_error'])}"
              f"; normalised error rms {fmt(np.sqrt(np.mean(z ** 2, axis=0)), 2)}; truth/odo "
              f"length {om['length_ratio_truth_over_odometry']:.3f}, turn "
              f"{om['turn_ratio_truth_over_odometry']:.3f}")
        out.setdefault("mrclam6", {})[robot] = {
            "keyframes": len(s.steps), "bursts": m["n_bursts"], "rows": rows,
            "landmarks_per_keyframe_mean": float(k.mean()),
            "common_mean": float(common.mean()),
            "parallax_median_deg": float(np.degrees(np.median(par))),
            "parallax_gt2deg": int((par > np.radians(2)).sum()),
            "raw_bearing": raw_stats, "keyframe_bearing": kf,
            "bearing_sigma_rad": s.header.bearing_sigma_rad,
            "odometry_sigma": list(s.header.odometry_sigma), "odometry_model": om}
    r = np.concatenate(pooled_r)
    model, info = fit_odometry_sigma(np.concatenate(pooled_u), np.concatenate(pooled_e))
    stats = robust_bearing_stats(r)
    print(f"pooled robots 1-5 (the calibrate=False defaults): bearing sigma "
          f"{stats['sigma_rad']:.4f} rad (bias {stats['bias_rad']:+.4f}, spread "
          f"{stats['spread_rad']:.4f}, outliers {100 * stats['outlier_rate']:.2f} %); "
          f"odometry model (a, b, c): {fmt(model)}, {info}")
    med = np.median(odometry_sigma_model(model, np.concatenate(pooled_u)), axis=0)
    print(f"  pooled model at the median step: {fmt(med)}")
    out["mrclam6_pooled"] = {"bearing": stats, "odometry_model": model.tolist(), **info}


def inspect_mrclam1(data: Path, out: dict) -> None:
    d = data / "mrclam1"
    print(f"== MRCLAM1 ({d}), calibrate=False (no robot ground truth)")
    for robot in range(1, 6):
        s = import_mrclam(d, robot, calibrate=False)
        k = np.array([len(st.landmark_ids) for st in s.steps])
        rows = s.header.meta["rows"]
        print(f"robot {robot}: {len(s.steps)} keyframes, landmarks per keyframe {k.mean():.2f}, "
              f"distinct {len(s.landmark_ids())}; rows {rows}")
        out.setdefault("mrclam1", {})[robot] = {"keyframes": len(s.steps), "rows": rows}


def inspect_g2o(data: Path, out: dict) -> None:
    d = data / "bearing_only_sim_g2o"
    s = import_g2o(d / "slam2D_bearing_only_initial_guess.g2o",
                   truth_path=d / "slam2D_bearing_only_ground_truth.g2o")
    k = np.array([len(st.landmark_ids) for st in s.steps])
    common, par = consecutive_parallax(s)
    tc = s.header.meta["truth_check"]
    print(f"== g2o ({d})")
    print(f"  {len(s.steps)} steps, {k.sum()} bearings, {len(s.landmark_ids())} landmarks; per "
          f"step mean {k.mean():.2f}, max {k.max()}; consecutive share {common.mean():.2f}, "
          f"parallax median {np.degrees(np.median(par)):.2f} deg")
    print(f"  header: bearing_sigma_rad {s.header.bearing_sigma_rad:.5f}, odometry_sigma "
          f"{fmt(s.header.odometry_sigma, 5)}")
    print(f"  against truth: bearing bias {tc['bearing']['bias_rad']:+.5f}, std "
          f"{tc['bearing']['inlier_std_rad']:.5f}, max {tc['bearing']['max_abs_rad']:.4f}; "
          f"odometry rms error {fmt(tc['odometry_rms_error'], 5)}")
    out["g2o"] = {"steps": len(s.steps), "bearings": int(k.sum()),
                  "bearing_sigma_rad": s.header.bearing_sigma_rad,
                  "odometry_sigma": list(s.header.odometry_sigma), "truth_check": tc}


def inspect_victoria(data: Path, out: dict) -> None:
    s = import_victoria(data / "victoria_park" / "victoria_park.txt")
    k = np.array([len(st.landmark_ids) for st in s.steps])
    m = s.header.meta
    print("== Victoria Park")
    print(f"  {len(s.steps)} steps, {k.sum()} bearings, {len(s.landmark_ids())} landmarks; "
          f"steps with bearings {(k > 0).sum()}, per such step {k[k > 0].mean():.2f}")
    print(f"  header: bearing_sigma_rad {s.header.bearing_sigma_rad:.4f} "
          f"(propagated {m['bearing_sigma_propagated_rad']}, GTSAM example "
          f"{m['bearing_sigma_gtsam_example_rad']}), odometry_sigma "
          f"{fmt(s.header.odometry_sigma, 4)}")
    out["victoria"] = {"steps": len(s.steps), "bearings": int(k.sum()),
                       "bearing_sigma_rad": s.header.bearing_sigma_rad}


def sweep(data: Path, out: dict) -> None:
    d = data / "mrclam6"
    print("== keyframe sweep over MRCLAM6 robots 1-5 (sums / means over robots)")
    print("  d_m  turn  win_s  rotate | steps  kept  lm/kf  spread  sigma  common  par>2deg "
          "par>5deg  depth_info")
    grid = [(0.05, 0.05, 0.3, True), (0.1, 0.1, 0.0, True), (0.1, 0.1, 0.3, True),
            (0.2, 0.2, 0.3, True), (0.3, 0.3, 0.0, True), (0.3, 0.3, 0.3, True),
            (0.3, 0.3, 0.3, False), (0.3, 0.3, 0.6, True), (0.3, 0.3, 0.6, False),
            (0.5, 0.3, 0.3, True), (0.5, 0.5, 0.6, True), (0.75, 0.5, 0.6, True),
            (1.0, 0.5, 0.6, True)]
    rows = []
    for dist, turn, win, rot in grid:
        cfg = KeyframeConfig(min_distance_m=dist, min_turn_rad=turn, attach_window_s=win,
                             rotate_bearings=rot)
        acc = []
        for robot in range(1, 6):
            s = import_mrclam(d, robot, keyframe=cfg)
            common, par = consecutive_parallax(s)
            kf = s.header.meta["bearing_calibration"]
            acc.append([len(s.steps), kf["n"], kf["n"] / len(s.steps), kf["spread_rad"],
                        s.header.bearing_sigma_rad, common.mean(),
                        (par > np.radians(2)).sum(), (par > np.radians(5)).sum(),
                        np.sum(par ** 2) / s.header.bearing_sigma_rad ** 2])
        a = np.array(acc)
        row = [dist, turn, win, rot, a[:, 0].sum(), a[:, 1].sum(), a[:, 2].mean(),
               a[:, 3].mean(), a[:, 4].mean(), a[:, 5].mean(), a[:, 6].sum(), a[:, 7].sum(),
               a[:, 8].sum()]
        rows.append(row)
        print(f"  {dist:4.2f} {turn:4.2f} {win:5.2f}  {str(rot):6s} | {row[4]:5.0f} {row[5]:5.0f}"
              f"  {row[6]:5.2f}  {row[7]:.4f} {row[8]:.4f}  {row[9]:5.2f}  {row[10]:7.0f}"
              f"  {row[11]:7.0f}  {row[12]:9.0f}")
    out["sweep"] = rows
    print("== command delay sweep (default keyframes): mean over robots of keyframe odometry "
          "rms error [dx, dy, dpsi] and keyframe bearing spread")
    for delay in (0.0, 0.1, 0.2, 0.3):
        cfg = KeyframeConfig(command_delay_s=delay)
        acc = []
        for robot in range(1, 6):
            s = import_mrclam(d, robot, keyframe=cfg)
            m = s.header.meta
            acc.append(m["odometry_model"]["rms_error"] + [m["bearing_calibration"]["spread_rad"]])
        a = np.mean(acc, axis=0)
        print(f"  delay {delay:.1f} s: odometry rms {fmt(a[:3])}, bearing spread {a[3]:.4f}")
        out.setdefault("delay_sweep", {})[delay] = a.tolist()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", type=Path, default=DATA, help=f"default {DATA}")
    p.add_argument("--sweep", action="store_true", help="also run the keyframe/delay sweeps")
    p.add_argument("--json", type=Path, help="save the numbers to this JSON file")
    args = p.parse_args(argv)
    if not args.data.is_dir():
        print(f"no data folder at {args.data}", file=sys.stderr)
        return 2
    out: dict[str, Any] = {}
    inspect_mrclam6(args.data, out)
    inspect_mrclam1(args.data, out)
    inspect_g2o(args.data, out)
    inspect_victoria(args.data, out)
    if args.sweep:
        sweep(args.data, out)
    if args.json:
        args.json.write_text(json.dumps(jsonable(out), indent=1))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
