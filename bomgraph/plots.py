"""Figures: ``plot_*_on_axes(ax, ...)`` functions that draw on the axes they are given and
return them, and ``*_figure`` builders that return a ``matplotlib.figure.Figure``. They take
arrays and estimates only: nothing here runs a mapper, reads a dataset or scores a map
(:mod:`bomgraph.report` does that and writes the files). matplotlib is imported only here; no
pyplot, so the caller's backend is left alone; nothing is shown or saved.

The paper's figures: fig. 3/5 (map and trajectory), fig. 4/6/7/8 (errors against time).
"""

from __future__ import annotations

import textwrap
import warnings
from dataclasses import dataclass
from typing import Mapping, Protocol, Sequence

import numpy as np


# What the figures read of the library's types, so that plots imports none of them (no mapper,
# scorer or dataset): bomgraph.mapper.MapEstimate, bomgraph.stream.Truth and
# bomgraph.evaluate.Alignment satisfy these.

class TruthLike(Protocol):
    """True landmarks ``(n,)`` ids and ``(n, 2)`` metres; poses ``(T+1, 3)`` or None."""

    landmark_ids: np.ndarray
    landmarks_xy: np.ndarray
    poses: np.ndarray | None


class EstimateLike(TruthLike, Protocol):
    """An estimated map (as :class:`TruthLike`) with the steps ``pose_t`` of its poses."""

    pose_t: np.ndarray

    def __len__(self) -> int: ...


class AlignmentLike(Protocol):
    """A transform of ``(n, 2)`` points into the frame of the figure."""

    def apply(self, points_xy: np.ndarray) -> np.ndarray: ...


#: One colour per method (by registry name), the same in every figure: a label is coloured by
#: the longest method name it starts with; variants of a method ("(improved)", "+priors", ...)
#: get a lighter or darker shade of it, fixed by the variant's text (crc32: stable across runs).
METHOD_COLOURS = {
    "triangulate": "#7f7f7f", "stmds-cs": "#ff7f0e", "stmds-smacof": "#d62728",
    "stmds-cs-loc": "#e377c2", "stmds-smacof-loc": "#9467bd", "ekf": "#2ca02c",
    "ekf-invdepth": "#bcbd22", "gtsam-batch": "#1f77b4", "gtsam-isam2": "#17becf",
    "hybrid": "#8c564b", "oracle": "#000000",
}
_OTHER = ("#393b79", "#637939", "#8c6d31", "#843c39", "#7b4173", "#3182bd", "#e6550d")
_SHADES = (-0.3, 0.35, -0.18, 0.5, 0.2, -0.38)


def _crc(text: str) -> int:
    import zlib

    return zlib.crc32(text.encode("utf-8"))


def method_colour(label: str) -> str:
    """The colour of a method or arm label (``"#rrggbb"``), the same in every figure."""
    base = max((m for m in METHOD_COLOURS if label == m or label.startswith(m + " ")
                or label.startswith(m + "+")), key=len, default=None)
    if base is None:
        return _OTHER[_crc(label) % len(_OTHER)]
    rgb = np.array([int(METHOD_COLOURS[base][k:k + 2], 16) for k in (1, 3, 5)]) / 255.0
    variant = label[len(base):].strip()
    if variant:
        f = _SHADES[_crc(variant) % len(_SHADES)]
        rgb = rgb + (1 - rgb) * f if f > 0 else rgb * (1 + f)
    return "#" + "".join(f"{int(round(255 * v)):02x}" for v in np.clip(rgb, 0, 1))


def method_linestyle(label: str) -> str:
    """Solid for a method, dashed or dotted for its variants (by the variant's text)."""
    base = max((m for m in METHOD_COLOURS if label.startswith(m)), key=len, default=label)
    variant = label[len(base):].strip()
    return "-" if not variant else ("--", "-.", ":")[_crc(variant) % 3]



def _plain_log_ticks(axis) -> None:
    """Tick labels of a log axis as plain numbers (2, 5, 10, 20), not 2 x 10^0."""
    from matplotlib.ticker import FuncFormatter

    fmt = FuncFormatter(lambda v, _: f"{v:g}")
    axis.set_major_formatter(fmt)
    axis.set_minor_formatter(FuncFormatter(
        lambda v, _: f"{v:g}" if f"{v:g}"[0] in "25" else ""))


def _moved(alignment: AlignmentLike | None, points_xy: np.ndarray) -> np.ndarray:
    """``(n, 2)`` points through ``alignment`` (None: as they are)."""
    return np.asarray(points_xy, dtype=float) if alignment is None else alignment.apply(points_xy)


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
        (line,) = ax.plot(t, mean, label=label, lw=1.6, color=method_colour(label),
                          ls=method_linestyle(label))
        ax.fill_between(t, lo, hi, color=line.get_color(), alpha=0.18, lw=0)
    ax.set_xlabel("time step t")
    stat = "median, band 25-75%" if band == "iqr" else "mean, band +-1 std"
    ax.set_ylabel(f"{ylabel} ({stat})")
    if log:
        ax.set_yscale("log")
        _plain_log_ticks(ax.yaxis)
    else:
        ax.set_ylim(bottom=0)
    ax.grid(True, alpha=0.3)
    if title:
        ax.set_title(title)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize="small")
    return ax


def plot_map_on_axes(ax, truth: TruthLike, estimate: EstimateLike | None = None,
                     alignment: AlignmentLike | None = None, *, title: str | None = None,
                     trajectory_t: Sequence[int] | None = None):
    """True landmarks and trajectory, and an aligned estimate with error lines (fig. 3/5)."""
    ax.plot(truth.landmarks_xy[:, 0], truth.landmarks_xy[:, 1], "k^", ms=6, mfc="none",
            label="true landmarks")
    if truth.poses is not None:
        sel = truth.poses if trajectory_t is None else truth.poses[np.asarray(trajectory_t)]
        ax.plot(sel[:, 0], sel[:, 1], "k--", lw=0.9, label="true trajectory")
    if estimate is not None and len(estimate):
        xy = _moved(alignment, estimate.landmarks_xy)
        ax.plot(xy[:, 0], xy[:, 1], "o", color="tab:red", ms=4, label="estimated landmarks")
        common, ie, it = np.intersect1d(estimate.landmark_ids, truth.landmark_ids,
                                        return_indices=True)
        for a, b in zip(xy[ie], truth.landmarks_xy[it]):
            ax.plot([a[0], b[0]], [a[1], b[1]], "-", color="tab:red", lw=0.7)
        if estimate.poses is not None and len(estimate.poses):
            p = _moved(alignment, estimate.poses[:, :2])
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


def _figure(**kw):
    from matplotlib.figure import Figure  # no pyplot: the caller's backend is left alone

    return Figure(**kw)


def error_vs_time_figure(curves: Mapping[str, tuple[np.ndarray, np.ndarray]], *,
                         title: str,
                         robot_curves: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None):
    """Landmark MPE against time (and the robot error beside it when ``robot_curves`` holds
    any), the paper's figs. 4, 6, 7, 8. Curves as in :func:`plot_error_vs_time_on_axes`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    ncol = 2 if robot_curves else 1
    fig = _figure(figsize=(6.4 * ncol, 4.4))
    axes = fig.subplots(1, ncol, squeeze=False)
    plot_error_vs_time_on_axes(axes[0, 0], curves, title=title)
    if robot_curves:
        plot_error_vs_time_on_axes(axes[0, 1], robot_curves, ylabel="robot position error [cm]",
                                   title="robot position (latest pose)")
    fig.tight_layout()
    return fig


def map_figure(truth: TruthLike, estimate: EstimateLike | None = None,
               alignment: AlignmentLike | None = None, *, title: str | None = None,
               trajectory_t: Sequence[int] | None = None):
    """One map (paper fig. 3 and 5): :func:`plot_map_on_axes` on a 6 x 6 inch figure."""
    fig = _figure(figsize=(6.0, 6.0))
    plot_map_on_axes(fig.subplots(), truth, estimate, alignment, title=title,
                     trajectory_t=trajectory_t)
    fig.tight_layout()
    return fig


@dataclass(frozen=True)
class MapPanel:
    """One panel of :func:`final_maps_figure`: a method's final map in the truth's frame.

    ``landmarks`` is ``(n, 3)`` rows ``(id, x [m], y [m])`` and ``poses`` ``(m, 3)`` rows
    ``(t, x [m], y [m])``, both already aligned to the truth; ``landmarks`` None means no map,
    with ``failure`` saying why. ``mpe_m`` (NaN: unknown) goes into the title.
    """

    label: str
    landmarks: np.ndarray | None
    poses: np.ndarray | None = None
    failure: str = ""
    mpe_m: float = float("nan")


def final_maps_figure(truth: TruthLike, panels: Sequence[MapPanel], *, title: str):
    """Every method's final map over the truth of one recording, three panels a row, all on
    the truth's extent (plus 0.5 m).

    Returns
    -------
    matplotlib.figure.Figure
    """
    n = len(panels)
    ncol = min(n, 3)
    nrow = (n + ncol - 1) // ncol
    fig = _figure(figsize=(4.6 * ncol, 4.4 * nrow))
    axes = fig.subplots(nrow, ncol, squeeze=False)
    pts = truth.landmarks_xy if truth.poses is None else np.vstack(
        [truth.landmarks_xy, truth.poses[:, :2]])
    lo, hi = pts.min(0) - 0.5, pts.max(0) + 0.5
    ids = dict(zip(truth.landmark_ids.tolist(), truth.landmarks_xy))
    for ax, panel in zip(axes.ravel(), panels):
        plot_map_on_axes(ax, truth, title=panel.label)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        if panel.landmarks is None:
            ax.text(0.5, 0.5, f"FAILED\n{textwrap.fill(panel.failure[:120], 40)}",
                    transform=ax.transAxes, ha="center", va="center", color="tab:red",
                    fontsize=8, bbox={"fc": "white", "ec": "none", "alpha": 0.85})
            continue
        lm = np.asarray(panel.landmarks, dtype=float).reshape(-1, 3)
        ax.plot(lm[:, 1], lm[:, 2], "o", color="tab:red", ms=4, label="estimate")
        for i, x, y in lm:
            if int(i) in ids:
                tx, ty = ids[int(i)]
                ax.plot([x, tx], [y, ty], "-", color="tab:red", lw=0.7)
        if panel.poses is not None and len(panel.poses):
            p = np.asarray(panel.poses, dtype=float)
            ax.plot(p[:, 1], p[:, 2], "-", color="tab:blue", lw=0.9, label="est. trajectory")
        mpe = panel.mpe_m
        ax.set_title(f"{panel.label}: MPE {100 * mpe:.1f} cm" if mpe == mpe else panel.label)
        ax.legend(fontsize="x-small", loc="upper right")
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    fig.suptitle(title)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.4 / (4.4 * nrow)))   # room for the suptitle
    return fig


def map_comparison_figure(estimates: Mapping[str, EstimateLike | None], *,
                          reference: EstimateLike | None = None,
                          alignments: Mapping[str, AlignmentLike | None] | None = None,
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

    alignments = alignments or {}
    notes = notes or {}
    n = max(len(estimates), 1)
    ncol = max(1, min(ncol, n))
    nrow = (n + ncol - 1) // ncol
    fig = _figure(figsize=(4.4 * ncol, 4.2 * nrow))
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
            al = alignments.get(label)
            if est.poses is not None and len(est.poses):
                p = _moved(al, est.poses[:, :2])
                ax.plot(p[:, 0], p[:, 1], "-", color="tab:blue", lw=0.6, label="trajectory")
            xy = _moved(al, est.landmarks_xy)
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


CHI2_2D_95 = 5.991464547107979
"""The 95 % quantile of chi-square with 2 degrees of freedom (the ellipses' size)."""


def _ellipse_xy(centre: np.ndarray, cov: np.ndarray, k2: float = CHI2_2D_95,
                n: int = 48) -> np.ndarray:
    """``(n, 2)`` points of ``{x : (x - c)^T cov^-1 (x - c) = k2}``."""
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    a = np.linspace(0, 2 * np.pi, n)
    circle = np.column_stack([np.cos(a), np.sin(a)]) * np.sqrt(np.clip(w, 0, None) * k2)
    return centre + circle @ v.T


def _outside_legend(ax) -> None:
    """The legend under the axes, outside the data."""
    ax.legend(fontsize="small", loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=3,
              frameon=False)


def run_figure(truth: TruthLike | None, estimate: EstimateLike, alignment: AlignmentLike | None,
               *, label: str, errors_m: Mapping[int, float] | None = None,
               pose_errors: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
               landmark_cov: np.ndarray | None = None, title: str | None = None):
    """One run: the aligned map over the truth with error lines, the landmarks coloured by
    their error, 95 % ellipses where ``landmark_cov`` ``(n, 2, 2)`` is given (in the
    estimate's frame; rotated and scaled with the alignment), the trajectory over the true
    one in the method's colour; beside it the robot's position and heading error against t.

    Parameters
    ----------
    errors_m : landmark id -> error [m] after alignment (None: uncoloured)
    pose_errors : ``(t (k,), translation_m (k,), heading_rad (k,))`` or None

    Returns
    -------
    matplotlib.figure.Figure
    """
    colour = method_colour(label)
    two = pose_errors is not None and len(pose_errors[0]) > 0
    fig = _figure(figsize=(11.5 if two else 6.4, 6.0), layout="constrained")
    axes = fig.subplots(1, 2, width_ratios=(1.25, 1)) if two else [fig.subplots()]
    ax = axes[0]
    if truth is not None:
        ax.plot(truth.landmarks_xy[:, 0], truth.landmarks_xy[:, 1], "k^", ms=6, mfc="none",
                label="true landmarks")
        if truth.poses is not None:
            ax.plot(truth.poses[:, 0], truth.poses[:, 1], "--", color="0.35", lw=0.9,
                    label="true trajectory")
    xy = _moved(alignment, estimate.landmarks_xy)
    if estimate.poses is not None and len(estimate.poses):
        order = np.argsort(estimate.pose_t)
        p = _moved(alignment, estimate.poses[order, :2])
        ax.plot(p[:, 0], p[:, 1], "-", color=colour, lw=1.3, label=f"{label} trajectory")
    if landmark_cov is not None:
        rot = np.asarray(getattr(alignment, "rotation", np.eye(2)), float)
        sc = float(getattr(alignment, "scale", 1.0))
        cov_xy = np.asarray(landmark_cov, float)
        defined = ~np.isnan(cov_xy).all(axis=(1, 2))   # all NaN: no covariance, no ellipse
        for k, (c, cov) in enumerate(zip(xy[defined], cov_xy[defined])):
            e = _ellipse_xy(c, sc * sc * rot @ cov @ rot.T)
            ax.plot(e[:, 0], e[:, 1], "-", color=colour, lw=0.6, alpha=0.8,
                    label="95 % ellipses" if k == 0 else None)
    if truth is not None:
        common, ie, it = np.intersect1d(estimate.landmark_ids, truth.landmark_ids,
                                        return_indices=True)
        for a, b in zip(xy[ie], truth.landmarks_xy[it]):
            ax.plot([a[0], b[0]], [a[1], b[1]], "-", color="tab:red", lw=0.7)
    if errors_m:
        err = np.array([errors_m.get(int(i), np.nan) for i in estimate.landmark_ids]) * 100
        pts = ax.scatter(xy[:, 0], xy[:, 1], c=err, cmap="viridis", s=22, zorder=3,
                         edgecolors="k", linewidths=0.3, label=f"{label} landmarks")
        fig.colorbar(pts, ax=ax, label="landmark error [cm]", shrink=0.8)
    else:
        ax.plot(xy[:, 0], xy[:, 1], "o", color=colour, ms=4, label=f"{label} landmarks")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, alpha=0.3)
    _outside_legend(ax)
    if two:
        t, trans, head = (np.asarray(v, float) for v in pose_errors)
        order = np.argsort(t)
        ax2 = axes[1]
        ax2.plot(t[order], 100 * trans[order], "-", color=colour, lw=1.2,
                 label="position error [cm]")
        ax2.set_xlabel("time step t")
        ax2.set_ylabel("robot position error [cm]")
        ax2.grid(True, alpha=0.3)
        axh = ax2.twinx()
        axh.plot(t[order], np.degrees(head[order]), ":", color=colour, lw=1.0,
                 label="heading error [deg]")
        axh.set_ylabel("heading error [deg]")
        h1, l1 = ax2.get_legend_handles_labels()
        h2, l2 = axh.get_legend_handles_labels()
        ax2.legend(h1 + h2, l1 + l2, fontsize="small", loc="upper center",
                   bbox_to_anchor=(0.5, -0.13), ncol=2, frameon=False)
        ax2.set_title("robot (aligned)")
    if title:

        fig.suptitle(textwrap.fill(title, 95 if two else 60))
    return fig


def _no_map(n_failed: int, n_runs: int) -> str:
    """Why an arm has no final MPE to draw: its runs failed, mapped too little, or both."""
    if n_failed >= n_runs:
        return "FAILED"
    if not n_failed:
        return "no map"
    return f"{n_failed} of {n_runs} FAILED, the other{'s' * (n_runs - n_failed > 1)} no map"


def results_figure(final: Mapping[str, Mapping[str, np.ndarray]],
                   curves: Mapping[str, Mapping[str, tuple[np.ndarray, np.ndarray]]], *,
                   kind: str = "box", titles: Mapping[str, str] | None = None,
                   failed: Mapping[str, Mapping[str, int]] | None = None):
    """A comparison across runs, one row per experiment: the final landmark MPE per arm as
    box or violin plots (``kind``), and the MPE against time (median and 25-75 % band).

    Parameters
    ----------
    final : experiment -> arm -> final MPE [m] of each run (NaN: no map, left out)
    curves : experiment -> arm -> (t (k,), MPE [m] (runs, k))
    failed : experiment -> arm -> how many of its runs failed: an arm without a map is
        labelled FAILED when they all did, not "no map"

    Returns
    -------
    matplotlib.figure.Figure
    """
    if kind not in ("box", "violin"):
        raise ValueError(f"kind must be 'box' or 'violin', got {kind!r}")
    titles = titles or {}
    exps = list(final)
    nmax = max((len(final[e]) for e in exps), default=1)
    fig = _figure(figsize=(max(11.0, 5 + 0.45 * nmax) + 3.5, 4.8 * max(len(exps), 1)),
                  layout="constrained")
    axes = fig.subplots(max(len(exps), 1), 2, squeeze=False, width_ratios=(1.1, 1))
    for row, exp in zip(axes, exps):
        arms = list(final[exp])
        raw = [np.asarray(final[exp][a], float) * 100 for a in arms]
        data = [d[np.isfinite(d)] for d in raw]
        pos = [k for k, d in enumerate(data) if d.size]
        ax = row[0]
        if pos:
            if kind == "box":
                bp = ax.boxplot([data[k] for k in pos], positions=pos, widths=0.6,
                                patch_artist=True, showfliers=True)
                for k, patch in zip(pos, bp["boxes"]):
                    patch.set_facecolor(method_colour(arms[k]))
                    patch.set_alpha(0.75)
                for med in bp["medians"]:
                    med.set_color("k")
            else:
                vp = ax.violinplot([data[k] for k in pos], positions=pos, showmedians=True)
                for k, body in zip(pos, vp["bodies"]):
                    body.set_facecolor(method_colour(arms[k]))
                    body.set_alpha(0.75)
        n_failed = (failed or {}).get(exp, {})
        ticks = [a if data[k].size else f"{a} ({_no_map(n_failed.get(a, 0), len(data_all))})"
                 for k, (a, data_all) in enumerate(zip(arms, raw))]
        ax.set_xticks(range(len(arms)), ticks, rotation=55, ha="right", fontsize=8)
        ax.set_yscale("log")
        _plain_log_ticks(ax.yaxis)
        ax.set_ylabel("final landmark MPE [cm]")
        ax.grid(True, axis="y", alpha=0.3)
        ax.set_title(f"{titles.get(exp, exp)}: final map, across runs")
        plot_error_vs_time_on_axes(row[1], curves.get(exp, {}), title=titles.get(exp, exp))
        if row[1].get_legend_handles_labels()[0]:  # outside the data, on the right
            row[1].legend(fontsize="x-small", loc="upper left", bbox_to_anchor=(1.02, 1),
                          frameon=False)
    return fig


__all__ = ["METHOD_COLOURS", "method_colour", "method_linestyle", "CHI2_2D_95", "run_figure",
           "results_figure", "plot_error_vs_time_on_axes", "plot_map_on_axes", "error_vs_time_figure",
           "map_figure", "MapPanel", "final_maps_figure", "map_comparison_figure"]
