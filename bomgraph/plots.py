"""Figures: ``plot_*_on_axes(ax, ...)`` functions. matplotlib is imported only here and in the
CLI. Each function draws on the axes it is given and returns them; it never shows or saves.

The paper's figures: fig. 3/5 (map and trajectory), fig. 4/6/7/8 (errors against time).
"""

from __future__ import annotations

import warnings
from typing import Mapping, Sequence

import numpy as np

from .evaluate import Alignment
from .mapper import MapEstimate
from .stream import Truth


def plot_error_vs_time_on_axes(ax, curves: Mapping[str, tuple[np.ndarray, np.ndarray]], *,
                               ylabel: str = "landmark MPE [cm]", scale: float = 100.0,
                               band: str = "iqr", title: str | None = None,
                               log: bool = True):
    """Median (line) and spread (band) of an error over time, one curve per label.

    Parameters
    ----------
    curves : mapping label -> (t (k,), values (runs, k)) in metres
    band : ``"iqr"`` (median, 25-75 percentiles: one diverged run cannot hide the others)
        or ``"std"`` (mean +- one std)
    log : logarithmic error axis (the methods differ by two orders of magnitude)
    """
    for k, (label, (t, vals)) in enumerate(curves.items()):
        v = np.asarray(vals, dtype=float) * scale
        if not np.any(np.isfinite(v)):
            continue
        with warnings.catch_warnings():  # columns where no run has a map yet are NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            if band == "std":
                mean = np.nanmean(v, axis=0)
                lo, hi = mean - np.nanstd(v, axis=0), mean + np.nanstd(v, axis=0)
            else:
                mean = np.nanmedian(v, axis=0)
                lo, hi = np.nanpercentile(v, 25, axis=0), np.nanpercentile(v, 75, axis=0)
        # ten colours, then the same colours dashed: no two curves look alike
        (line,) = ax.plot(t, mean, label=label, lw=1.6, color=f"C{k % 10}",
                          ls="-" if k < 10 else "--")
        ax.fill_between(t, lo, hi, color=line.get_color(), alpha=0.18, lw=0)
    ax.set_xlabel("time step t")
    stat = "median, band 25-75%" if band == "iqr" else "mean, band +-1 std"
    ax.set_ylabel(f"{ylabel} ({stat})")
    if log:
        ax.set_yscale("log")
    else:
        ax.set_ylim(bottom=0)
    ax.grid(True, alpha=0.3)
    if title:
        ax.set_title(title)
    ax.legend(fontsize="small")
    return ax


def plot_map_on_axes(ax, truth: Truth, estimate: MapEstimate | None = None,
                     alignment: Alignment | None = None, *, title: str | None = None,
                     trajectory_t: Sequence[int] | None = None):
    """True landmarks and trajectory, and an aligned estimate with error lines (fig. 3/5)."""
    ax.plot(truth.landmarks_xy[:, 0], truth.landmarks_xy[:, 1], "k^", ms=6, mfc="none",
            label="true landmarks")
    if truth.poses is not None:
        sel = truth.poses if trajectory_t is None else truth.poses[np.asarray(trajectory_t)]
        ax.plot(sel[:, 0], sel[:, 1], "k--", lw=0.9, label="true trajectory")
    if estimate is not None and len(estimate):
        al = alignment or Alignment(np.eye(2), np.zeros(2))
        xy = al.apply(estimate.landmarks_xy)
        ax.plot(xy[:, 0], xy[:, 1], "o", color="tab:red", ms=4, label="estimated landmarks")
        common, ie, it = np.intersect1d(estimate.landmark_ids, truth.landmark_ids,
                                        return_indices=True)
        for a, b in zip(xy[ie], truth.landmarks_xy[it]):
            ax.plot([a[0], b[0]], [a[1], b[1]], "-", color="tab:red", lw=0.7)
        if estimate.poses is not None and len(estimate.poses):
            p = al.apply(estimate.poses[:, :2])
            ax.plot(p[:, 0], p[:, 1], "-", color="tab:blue", lw=1.2,
                    label="estimated trajectory")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, alpha=0.3)
    if title:
        ax.set_title(title)
    ax.legend(fontsize="small", loc="upper right")
    return ax


def write_compare_figures(out_dir, experiments, results) -> list:
    """The comparison's figures as PNG files in ``out_dir``; returns their paths.

    One error-against-time figure per experiment (landmark MPE; robot error too for Exp. 2,
    the paper's figs. 4, 6, 7, 8) and an example map with trajectory (figs. 3 and 5).
    """
    from pathlib import Path

    from matplotlib.figure import Figure  # no pyplot: the caller's backend is left alone

    from .bench import error_curves, example_estimate
    from .evaluate import score_estimate

    out = Path(out_dir)
    files = []
    mpe = error_curves(results, "mpe_m")
    robot = error_curves(results, "robot_last_m")
    for exp in experiments:
        curves = {arm: c for (e, arm), c in mpe.items() if e == exp.name}
        if not curves:
            continue
        rob = {arm: c for (e, arm), c in robot.items()
               if e == exp.name and np.any(np.isfinite(c[1]))}
        ncol = 2 if rob else 1
        fig = Figure(figsize=(6.4 * ncol, 4.4))
        axes = fig.subplots(1, ncol, squeeze=False)
        plot_error_vs_time_on_axes(axes[0, 0], curves,
                                   title=f"{exp.title}: landmarks ({len(exp.runs())} runs)")
        if rob:
            plot_error_vs_time_on_axes(axes[0, 1], rob, ylabel="robot position error [cm]",
                                       title="robot position (latest pose)")
        fig.tight_layout()
        path = out / f"{exp.name}_error_vs_time.png"
        fig.savefig(path, dpi=120)
        files.append(path)
    for exp in experiments:
        if exp.sources:
            files += _write_source_maps(out, exp, results, Figure)
    sim_exps = [e for e in experiments if not e.sources]
    if not sim_exps:
        return files
    # Example map (fig. 5: Method 2 with localisation at t = 100; fig. 3: the truth)
    exp = sim_exps[0]
    try:
        t_show = 100 if exp.sim.n_steps >= 100 else None
        stream, est = example_estimate("stmds-smacof-loc", exp, t=t_show)
        al = score_estimate(est, stream.truth).alignment
        traj = np.arange(0, (t_show or exp.sim.n_steps) + 1)
        fig = Figure(figsize=(6.0, 6.0))
        ax = fig.subplots()
        plot_map_on_axes(ax, stream.truth, est, al, trajectory_t=traj,
                         title=f"stmds-smacof-loc, run {exp.runs()[0].name}, "
                               f"t = {t_show or exp.sim.n_steps}")
        fig.tight_layout()
        path = out / "example_map.png"
        fig.savefig(path, dpi=120)
        files.append(path)
    except Exception as exc:  # the map figure is optional; say why it is missing
        (out / "example_map.txt").write_text(f"example map not drawn: {type(exc).__name__}: "
                                             f"{exc}\n")
        files.append(out / "example_map.txt")
    return files


def _write_source_maps(out, exp, results, Figure) -> list:
    """One figure per recorded source: every method's final map (aligned) over the truth."""
    files = []
    for src in exp.sources:
        truth = src.stream().truth
        rs = [r for r in results if r["experiment"] == exp.name and r["run"] == src.name]
        n = len(rs)
        if not n or truth is None:
            continue
        ncol = min(n, 3)
        nrow = (n + ncol - 1) // ncol
        fig = Figure(figsize=(4.6 * ncol, 4.4 * nrow))
        axes = fig.subplots(nrow, ncol, squeeze=False)
        pts = truth.landmarks_xy if truth.poses is None else np.vstack(
            [truth.landmarks_xy, truth.poses[:, :2]])
        lo, hi = pts.min(0) - 0.5, pts.max(0) + 0.5
        for ax, r in zip(axes.ravel(), rs):
            plot_map_on_axes(ax, truth, title=f"{r['arm']}")
            ax.set_xlim(lo[0], hi[0])
            ax.set_ylim(lo[1], hi[1])
            fm = r.get("final_map")
            if not r.get("ok") or not fm:
                reason = r.get("error", "no map (fewer than 3 landmarks)")
                ax.text(0.5, 0.5, f"FAILED\n{reason[:60]}", transform=ax.transAxes,
                        ha="center", va="center", color="tab:red", fontsize=8, wrap=True)
                continue
            lm = np.array(fm["landmarks"], dtype=float).reshape(-1, 3)
            ax.plot(lm[:, 1], lm[:, 2], "o", color="tab:red", ms=4, label="estimate")
            ids = dict(zip(truth.landmark_ids.tolist(), truth.landmarks_xy))
            for i, x, y in lm:
                if int(i) in ids:
                    tx, ty = ids[int(i)]
                    ax.plot([x, tx], [y, ty], "-", color="tab:red", lw=0.7)
            if fm["poses"]:
                p = np.array(fm["poses"], dtype=float)
                ax.plot(p[:, 1], p[:, 2], "-", color="tab:blue", lw=0.9, label="est. trajectory")
            mpe = r["checkpoints"][-1].get("mpe_m")
            ax.set_title(f"{r['arm']}: MPE {100 * mpe:.1f} cm" if mpe == mpe else r["arm"])
            ax.legend(fontsize="x-small", loc="upper right")
        for ax in axes.ravel()[n:]:
            ax.set_visible(False)
        fig.suptitle(f"{exp.title}: {src.name}")
        fig.tight_layout()
        path = out / f"{exp.name}_{src.name}_maps.png"
        fig.savefig(path, dpi=100)
        files.append(path)
    return files


def map_comparison_figure(estimates: Mapping[str, MapEstimate | None], *,
                          reference: MapEstimate | None = None,
                          alignments: Mapping[str, Alignment | None] | None = None,
                          notes: Mapping[str, str] | None = None,
                          title: str | None = None, ncol: int = 3):
    """Maps of a recording without ground truth: one panel per method, on a reference map.

    Each panel draws the reference landmarks (hollow triangles, e.g. the ``gtsam-batch``
    map), then the method's landmarks and trajectory moved by its alignment onto that
    reference. All panels share the reference's extent (plus a margin). A method whose
    estimate is None failed: its panel says so with its note.

    Parameters
    ----------
    estimates : mapping label -> MapEstimate or None (None: the method failed)
    reference : MapEstimate, optional
        The map every other one was aligned to (drawn in each panel).
    alignments : mapping label -> Alignment or None, optional
        Method frame -> reference frame (None or missing: drawn as estimated).
    notes : mapping label -> str, optional
        A line under each panel's title (numbers, or the reason of a failure).

    Returns
    -------
    matplotlib.figure.Figure
    """
    import textwrap

    from matplotlib.figure import Figure  # no pyplot: the caller's backend is left alone

    alignments = alignments or {}
    notes = notes or {}
    n = max(len(estimates), 1)
    ncol = max(1, min(ncol, n))
    nrow = (n + ncol - 1) // ncol
    fig = Figure(figsize=(4.4 * ncol, 4.2 * nrow))
    axes = fig.subplots(nrow, ncol, squeeze=False)
    lim = None
    if reference is not None and len(reference):
        pts = reference.landmarks_xy
        if reference.poses is not None and len(reference.poses):
            pts = np.vstack([pts, reference.poses[:, :2]])
        lo, hi = pts.min(0), pts.max(0)
        pad = 0.08 * float(np.max(hi - lo)) + 1e-9
        lim = (lo - pad, hi + pad)
    for ax, (label, est) in zip(axes.ravel(), estimates.items()):
        if reference is not None and len(reference):
            ax.plot(reference.landmarks_xy[:, 0], reference.landmarks_xy[:, 1], "k^", ms=4,
                    mfc="none", mew=0.6, label="reference landmarks")
        note = notes.get(label, "")
        if est is None or not len(est):
            head = "FAILED" if est is None else "NO MAP"
            ax.text(0.5, 0.5, f"{head}\n{textwrap.fill(note, 40)}",
                    transform=ax.transAxes, ha="center", va="center", color="tab:red",
                    fontsize=8, bbox={"fc": "white", "ec": "none", "alpha": 0.85})
            ax.set_title(label, fontsize=9)
        else:
            al = alignments.get(label) or Alignment(np.eye(2), np.zeros(2))
            if est.poses is not None and len(est.poses):
                p = al.apply(est.poses[:, :2])
                ax.plot(p[:, 0], p[:, 1], "-", color="tab:blue", lw=0.6, label="trajectory")
            xy = al.apply(est.landmarks_xy)
            ax.plot(xy[:, 0], xy[:, 1], "o", color="tab:red", ms=2.5, label="landmarks")
            ax.set_title(f"{label}\n{textwrap.shorten(note, 60)}" if note else label,
                         fontsize=9)
        if lim is not None:
            ax.set_xlim(lim[0][0], lim[1][0])
            ax.set_ylim(lim[0][1], lim[1][1])
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]", fontsize=8)
        ax.set_ylabel("y [m]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, alpha=0.3)
    axes.ravel()[0].legend(fontsize="x-small", loc="upper right")
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 1 - (0.4 / (4.2 * nrow) if title else 0)))
    return fig
