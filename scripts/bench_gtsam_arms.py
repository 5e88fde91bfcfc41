"""Where the GTSAM arms of the main job spend their CPU, and what a cheaper schedule does to the
maps (issue 14).

For each paper run (seed 0, the 25 runs of ``paper_design(0)``, 300 steps, map every 10 steps)
and each arm, the run is timed (``time.process_time``, single-threaded BLAS) and every
checkpoint recorded: MPE (m), the LM iterations and passes the estimate's ``info`` reports,
its cost, and a hash of the estimate (landmark ids and points, poses; raw float64 bytes).
Variants run beside the arm's default in the same process, alternating run by run, so their
CPU ratios are paired:

* ``default``: the arm as registered;
* ``oracle-warm`` (oracle only): LM started from the previous checkpoint's solution, the new
  poses and landmarks at the truth, instead of the truth for everything;
* ``lambda-carry`` (the LM arms): each Levenberg-Marquardt solve of
  :func:`baselines.lm_report.solve_lm` starts with lambda = the previous solve's final
  lambda / ``--carry-div`` (at least GTSAM's default 1e-5) instead of 1e-5 (its Huber
  passes too); the warm pre-solves (``baselines/lm_window.py``) keep GTSAM's default. Implemented here by wrapping the optimizer class in
  ``baselines.lm_report``'s namespace (an experiment, not a library option);
* ``options``: the arm with config fields overridden (``--option
  warm_relative_error_tol=1e-4``, repeatable; values parsed as Python literals).

Usage::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python scripts/bench_gtsam_arms.py \\
        --arms oracle --variants default oracle-warm --out /tmp/oracle.json
    python scripts/bench_gtsam_arms.py --compare /tmp/oracle.json   # variant vs default

The comparison prints, per arm and variant, the CPU sum over the runs (and vs the default's),
how many runs are bit-identical at every checkpoint, and the largest relative MPE change of a
checkpoint per run (the seventh session's reading of issue 14's 1 % bar), then the README
table cells (mean and median MPE at t = 50, 100, 200, 300 over the runs) and the largest change
of a cell (the issue's acceptance: "accuracy tables unchanged to 1 %"). ``--label L`` records
the ``options`` variant as ``L``, so that option sets run into separate files compare side by
side. Measured numbers:
``docs/measurements.md`` (section "GTSAM arms: where the CPU goes").
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import ast  # noqa: E402
import contextlib  # noqa: E402
import hashlib  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
import types  # noqa: E402
from typing import Any, Callable, Iterator  # noqa: E402

import gtsam  # noqa: E402
import numpy as np  # noqa: E402

import baselines.lm_report as lm_report  # noqa: E402
from baselines.bearing_graph import insert_pose, landmark_key, mid_key, pose_key  # noqa: E402
from baselines.factor_graph import OracleMapper  # noqa: E402
from bomgraph.errors import BomgraphError  # noqa: E402
from bomgraph.evaluate import score_estimate  # noqa: E402
from bomgraph.mapper import MapEstimate, Mapper, create_mapper, run  # noqa: E402
from bomgraph.sim import paper_design, simulate_run  # noqa: E402
from bomgraph.stream import Stream  # noqa: E402

ARMS = ("gtsam-batch", "oracle", "hybrid", "gtsam-isam2", "hybrid-isam2")
VARIANTS = ("default", "oracle-warm", "lambda-carry", "options")


class WarmOracle(OracleMapper):
    """The oracle started from its previous solution (the poses and landmarks new since then
    at the truth) instead of the truth at every checkpoint."""

    _solved_n = 0

    def initial_values(self) -> gtsam.Values:
        if not self._solved_n:
            return super().initial_values()
        v = gtsam.Values(self.state.values)
        for t in range(self._solved_n, self.state.problem.n_steps):
            v.erase(pose_key(t))
            v.erase(mid_key(t))
            insert_pose(v, t, self._true_poses[t], self._true_poses[t - 1])
        for lid in self.state._fresh:
            xy = self._true_xy.get(lid)
            if xy is not None:
                v.update(landmark_key(lid), gtsam.Point2(float(xy[0]), float(xy[1])))
        return v

    def _update(self) -> Callable[[], MapEstimate]:
        out = super()._update()
        self._solved_n = self.state.problem.n_steps
        return out


@contextlib.contextmanager
def lambda_carry(div: float) -> Iterator[None]:
    """Within the block, every LM solve of ``solve_lm`` starts at the previous one's final
    lambda / ``div`` (at least 1e-5)."""
    last: dict[str, float | None] = {"lam": None}

    class Carried:
        def __init__(self, graph: Any, values: Any, params: Any) -> None:
            if last["lam"] is not None:
                params.setlambdaInitial(max(1e-5, last["lam"] / div))
            self._opt = gtsam.LevenbergMarquardtOptimizer(graph, values, params)

        def optimize(self) -> Any:
            out = self._opt.optimize()
            last["lam"] = float(self._opt.lambda_())
            return out

        def __getattr__(self, name: str) -> Any:
            return getattr(self._opt, name)

    proxy = types.SimpleNamespace(**{k: getattr(gtsam, k) for k in dir(gtsam)
                                     if not k.startswith("__")})
    proxy.LevenbergMarquardtOptimizer = Carried
    saved = lm_report.gtsam   # solve_lm's namespace: it builds the optimizers
    lm_report.gtsam = proxy  # type: ignore[assignment]
    try:
        yield
    finally:
        lm_report.gtsam = saved


def estimate_hash(est: MapEstimate) -> str:
    h = hashlib.sha256()
    for a in (est.landmark_ids, est.landmarks_xy, est.pose_t, est.poses):
        if a is not None:
            h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def make(arm: str, variant: str, stream: Stream, options: dict[str, Any] | None = None
         ) -> Mapper:
    if variant == "oracle-warm":
        return WarmOracle(stream.header, truth=stream.truth)
    extra = dict(options or {}) if variant == "options" else {}
    return create_mapper(arm, stream.header, truth=stream.truth, **extra)


def one(arm: str, variant: str, stream: Stream, name: str, carry_div: float = 1.0,
        options: dict[str, Any] | None = None) -> dict[str, Any]:
    """One timed run: CPU seconds and every checkpoint's MPE, iterations, passes, cost, hash."""
    ctx = lambda_carry(carry_div) if variant == "lambda-carry" else contextlib.nullcontext()
    with ctx:
        mapper = make(arm, variant, stream, options)
        c0 = time.process_time()
        result = run(mapper, stream.steps, checkpoint_every=10)
        cpu = time.process_time() - c0
    cps = []
    for cp in result.checkpoints:
        try:
            mpe = float(score_estimate(cp.estimate, stream.truth).mpe_m)
        except BomgraphError:
            mpe = float("nan")
        info = cp.estimate.info
        cps.append({"t": cp.t, "mpe_m": mpe, "hash": estimate_hash(cp.estimate),
                    "iterations": info.get("iterations"), "passes": info.get("passes"),
                    "starts": info.get("starts"), "cost": info.get("cost")})
    return {"arm": arm, "variant": variant, "run": name, "cpu_s": cpu, "checkpoints": cps}


def applies(arm: str, variant: str) -> bool:
    return (variant in ("default", "options") or (variant == "oracle-warm" and arm == "oracle")
            or (variant == "lambda-carry" and arm in ("gtsam-batch", "oracle", "hybrid")))


def compare(rows: list[dict[str, Any]]) -> str:
    """Per arm and variant: CPU sum, vs default, identical runs, worst MPE change per run."""
    by = {(r["arm"], r["variant"], r["run"]): r for r in rows}
    out = []
    for arm in sorted({r["arm"] for r in rows}):
        base = {k[2]: v for k, v in by.items() if k[:2] == (arm, "default")}
        for variant in sorted({r["variant"] for r in rows if r["arm"] == arm}):
            mine = {k[2]: v for k, v in by.items() if k[:2] == (arm, variant)}
            runs = sorted(set(mine) & set(base))
            cpu = sum(mine[n]["cpu_s"] for n in runs)
            cpu0 = sum(base[n]["cpu_s"] for n in runs)
            its = sum(c["iterations"] or 0 for n in runs for c in mine[n]["checkpoints"])
            same, worst = 0, []
            for n in runs:
                a, b = mine[n]["checkpoints"], base[n]["checkpoints"]
                same += all(x["hash"] == y["hash"] for x, y in zip(a, b))
                rel = [abs(x["mpe_m"] - y["mpe_m"]) / y["mpe_m"] for x, y in zip(a, b)
                       if np.isfinite(x["mpe_m"]) and np.isfinite(y["mpe_m"]) and y["mpe_m"]]
                worst.append((max(rel) if rel else 0.0, n))
            worst.sort(reverse=True)
            out.append(f"{arm:13s} {variant:13s} runs {len(runs):2d} cpu {cpu:7.1f} s "
                       f"(x{cpu / cpu0:.3f}) LM its {its:5d} identical {same:2d}/{len(runs)} "
                       f"worst MPE change " + ", ".join(f"{w:.2%} {n}" for w, n in worst[:3]))
    return "\n".join(out)


#: The checkpoints of the README's accuracy tables (issue 14's bar: their cells to 1 %).
TABLE_T = (50, 100, 200, 300)


def table_cells(rows: list[dict[str, Any]]) -> dict[tuple[str, str], dict[str, float]]:
    """Per (arm, variant): the mean and median MPE (m) over the runs at each table checkpoint,
    keyed ``"mean@50"``, ``"median@50"``, ... (the cells of the README's tables)."""
    cells: dict[tuple[str, str], dict[str, float]] = {}
    for key in sorted({(r["arm"], r["variant"]) for r in rows}):
        mine = [r for r in rows if (r["arm"], r["variant"]) == key]
        out = {}
        for t in TABLE_T:
            v = np.array([c["mpe_m"] for r in mine for c in r["checkpoints"] if c["t"] == t])
            v = v[np.isfinite(v)]
            if v.size:
                out[f"mean@{t}"] = float(np.mean(v))
                out[f"median@{t}"] = float(np.median(v))
        cells[key] = out
    return cells


def compare_tables(rows: list[dict[str, Any]]) -> str:
    """Per arm and variant on the runs it shares with the default: the table cells (cm) and
    the largest relative change of a cell against the default (issue 14's bar: 1 %; a lower
    MPE is not a failure, so the worst increase is printed too)."""
    by = {(r["arm"], r["variant"], r["run"]): r for r in rows}
    out = []
    for arm in sorted({r["arm"] for r in rows}):
        base_runs = {k[2] for k in by if k[:2] == (arm, "default")}
        for variant in sorted({r["variant"] for r in rows if r["arm"] == arm}):
            runs = base_runs & {k[2] for k in by if k[:2] == (arm, variant)}
            sub = [by[(arm, v, n)] for v in ("default", variant) for n in sorted(runs)]
            cells = table_cells(sub)
            mine, base = cells[(arm, variant)], cells[(arm, "default")]
            rel = {k: (mine[k] - base[k]) / base[k] for k in base if k in mine and base[k]}
            worst = max(rel.items(), key=lambda kv: abs(kv[1]), default=("-", 0.0))
            up = max(rel.items(), key=lambda kv: kv[1], default=("-", 0.0))
            shown = " ".join(f"{100 * mine[f'mean@{t}']:.2f}/{100 * mine[f'median@{t}']:.2f}"
                             for t in TABLE_T if f"mean@{t}" in mine)
            out.append(f"{arm:13s} {variant:13s} cells(cm, mean/median at {TABLE_T}) {shown}; "
                       f"worst change {worst[1]:+.2%} ({worst[0]}), worst increase "
                       f"{up[1]:+.2%} ({up[0]})")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--arms", nargs="+", choices=ARMS, default=["oracle"])
    ap.add_argument("--variants", nargs="+", choices=VARIANTS, default=["default"])
    ap.add_argument("--runs", default="all", help="'all' or comma-separated indices 0-24")
    ap.add_argument("--carry-div", type=float, default=1.0)
    ap.add_argument("--option", action="append", default=[], metavar="FIELD=VALUE",
                    help="config override of the 'options' variant (repeatable)")
    ap.add_argument("--label", help="record the 'options' variant under this name (to compare "
                    "several option sets from separate files)")
    ap.add_argument("--out", help="write the rows (JSON) here")
    ap.add_argument("--compare", nargs="+", help="JSON files of earlier runs: compare only")
    args = ap.parse_args(argv)
    if args.compare:
        rows = [r for f in args.compare for r in json.load(open(f))]
        print(compare(rows))
        print(compare_tables(rows))
        return 0
    options = {}
    for o in args.option:
        key, _, value = o.partition("=")
        options[key] = ast.literal_eval(value)
    design = paper_design(0)
    idx = range(len(design)) if args.runs == "all" else [int(i) for i in args.runs.split(",")]
    rows = []
    for i in idx:
        stream = simulate_run(design[i])
        for arm in args.arms:
            for variant in args.variants:
                if not applies(arm, variant):
                    continue
                r = one(arm, variant, stream, design[i].name, args.carry_div, options)
                if args.label and variant == "options":
                    r["variant"] = args.label
                rows.append(r)
                its = sum(c["iterations"] or 0 for c in r["checkpoints"])
                print(f"{arm:13s} {variant:13s} {r['run']} cpu {r['cpu_s']:.2f} s LM its {its} "
                      f"final MPE {100 * r['checkpoints'][-1]['mpe_m']:.4f} cm", flush=True)
        if args.out:
            with open(args.out, "w") as f:
                json.dump(rows, f)
    print(compare(rows))
    print(compare_tables(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
