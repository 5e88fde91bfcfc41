"""Experiments as data, and the runner that executes them serially, in local processes, or on
a Dask cluster (paper section IV: Exp. 1 mapping, Exp. 2 SLAM, Exp. 3 priors).

An :class:`Experiment` is a list of :class:`Arm` (a method with options, with or without prior
pairs) crossed with a run design (:func:`bomgraph.sim.paper_design`). Each (arm, run) pair is a
:class:`Task`; :func:`run_task` is a pure function of the task (the stream is simulated from
its seed), so results are identical whether tasks run serially, in processes or on Dask, and a
finished task is cached as a small JSON file so an interrupted sweep resumes.

The core never prints: progress is reported through a callback.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Mapping, Sequence

import numpy as np

from .errors import ConfigError, TooFewLandmarksError
from .evaluate import score_estimate
from .mapper import MapEstimate, create_mapper, method_info, run
from .sim import RunSpec, SimConfig, paper_design, simulate_run
from .stream import Stream, Truth

REPORT_TIMES = (50, 100, 200, 300)

#: What the paper reports (simulation, 25 runs), for the tables: (experiment, arm) -> text.
PAPER_REPORTED: dict[tuple[str, str], str] = {
    ("exp1", "stmds-cs"): "MPE 4.78 cm at t=300",
    ("exp1", "stmds-smacof"): "MPE 2.87 cm at t=300",
    ("exp1", "stmds-cs (improved)"): "(paper: Method 1 MPE 4.78 cm)",
    ("exp1", "stmds-smacof (improved)"): "(paper: Method 2 MPE 2.87 cm)",
    ("exp2", "stmds-cs-loc"): "robot error < 10 cm",
    ("exp2", "stmds-smacof-loc"): "robot error < 6 cm",
    ("exp2", "ekf"): "better than Method 2 before t=100, about equal later; robot error lower",
    ("exp3", "stmds-smacof+priors"): "clearly lower MPE than without priors, above all early",
}


@dataclass(frozen=True)
class Arm:
    """One curve of an experiment: a method, its options, and the prior pairs it is given."""

    label: str
    method: str
    options: Mapping[str, Any] = field(default_factory=dict)
    prior_fraction: float = 0.0

    def __post_init__(self) -> None:
        try:
            json.dumps(dict(self.options), allow_nan=False)
        except (TypeError, ValueError):
            raise ConfigError(f"arm {self.label!r}: options must be plain JSON values (numbers, "
                              f"strings, lists) so results can be cached and compared") from None

    def key(self) -> dict[str, Any]:
        return {"label": self.label, "method": self.method, "options": dict(self.options),
                "prior_fraction": self.prior_fraction}


@dataclass(frozen=True)
class SimSource:
    """A simulated run of a design (``prior_fraction`` > 0 adds Exp. 3 priors)."""

    spec: RunSpec
    sim: SimConfig = SimConfig()
    prior_fraction: float = 0.0
    prior_sigma_xy_m: float = 0.03

    @property
    def name(self) -> str:
        return self.spec.name

    def stream(self) -> Stream:
        return simulate_run(self.spec, self.sim, prior_fraction=self.prior_fraction,
                            prior_sigma_xy_m=self.prior_sigma_xy_m)

    def key(self) -> dict[str, Any]:
        return {"spec": asdict(self.spec), "sim": asdict(self.sim),
                "prior_fraction": self.prior_fraction, "prior_sigma": self.prior_sigma_xy_m}


@dataclass(frozen=True)
class DatasetSource:
    """A real recording, imported on use: ``kind`` is ``mrclam``, ``g2o`` or ``victoria``."""

    kind: str
    path: str
    robot: int | None = None
    truth_path: str | None = None
    label: str = ""

    @property
    def name(self) -> str:
        if self.label:
            return self.label
        base = Path(self.path).name
        return f"{base}-r{self.robot}" if self.robot is not None else base

    def stream(self) -> Stream:
        return _load_dataset(self.kind, self.path, self.robot, self.truth_path)

    def key(self) -> dict[str, Any]:
        return {"kind": self.kind, "path": str(Path(self.path).resolve()), "robot": self.robot,
                "truth": self.truth_path, "files": _files_stamp(self.path, self.truth_path)}


def _files_stamp(*paths: str | None) -> str:
    """Size and modification time of every file under ``paths`` (a change invalidates the
    cache)."""
    h = hashlib.sha256()
    for p in paths:
        if p is None:
            continue
        root = Path(p)
        files = sorted(root.rglob("*")) if root.is_dir() else [root]
        for f in files:
            if f.is_file():
                st = f.stat()
                h.update(f"{f}:{st.st_size}:{st.st_mtime_ns};".encode())
    return h.hexdigest()[:16]


@functools.lru_cache(maxsize=16)
def _load_dataset(kind: str, path: str, robot: int | None, truth_path: str | None) -> Stream:
    from . import datasets

    if kind == "mrclam":
        if robot is None:
            raise ConfigError("an MRCLAM source needs a robot number (1-5)")
        return datasets.import_mrclam(path, robot)
    if kind == "g2o":
        return datasets.import_g2o(path, truth_path=truth_path)
    if kind == "victoria":
        return datasets.import_victoria(path)
    raise ConfigError(f"unknown dataset kind {kind!r}; use mrclam, g2o or victoria")


@dataclass(frozen=True)
class Experiment:
    """Arms crossed with a run design (simulated) or with recorded ``sources``."""

    name: str
    title: str
    arms: tuple[Arm, ...]
    sim: SimConfig = SimConfig()
    seed: int = 0
    n_layouts: int = 5
    n_starts: int = 5
    prior_sigma_xy_m: float = 0.03
    checkpoint_every: int = 10
    sources: tuple[DatasetSource, ...] = ()

    def runs(self) -> list[RunSpec]:
        return paper_design(self.seed, self.n_layouts, self.n_starts)

    def tasks(self) -> list["Task"]:
        if self.sources:
            return [Task(self.name, arm, src, self.checkpoint_every)
                    for arm in self.arms for src in self.sources]
        return [Task(self.name, arm, SimSource(spec, self.sim, arm.prior_fraction,
                                               self.prior_sigma_xy_m), self.checkpoint_every)
                for arm in self.arms for spec in self.runs()]


@dataclass(frozen=True)
class Task:
    """One method on one run (simulated or recorded)."""

    experiment: str
    arm: Arm
    source: SimSource | DatasetSource
    checkpoint_every: int = 10

    def stream(self) -> Stream:
        return self.source.stream()

    def key(self) -> str:
        """A content hash: the same task always has the same key (cache file name)."""
        blob = json.dumps({"arm": self.arm.key(), "source": self.source.key(),
                           "every": self.checkpoint_every, "v": CACHE_VERSION,
                           "code": code_fingerprint()},
                          sort_keys=True)
        return hashlib.sha256(blob.encode()).hexdigest()[:20]


CACHE_VERSION = 1


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """A hash of the installed ``bomgraph`` and ``baselines`` sources: a cached result is
    reused only by the code that produced it."""
    import importlib.util

    h = hashlib.sha256()
    for pkg in ("bomgraph", "baselines"):
        spec = importlib.util.find_spec(pkg)
        if spec is None or not spec.submodule_search_locations:
            continue
        root = Path(list(spec.submodule_search_locations)[0])
        for f in sorted(root.rglob("*.py")):
            h.update(str(f.relative_to(root)).encode())
            h.update(f.read_bytes())
    return h.hexdigest()[:16]


# --------------------------------------------------------------------------------------------
# The paper's experiments
# --------------------------------------------------------------------------------------------

def paper_experiments(*, quick: bool = False, seed: int = 0) -> dict[str, Experiment]:
    """Exp. 1-3 and the all-methods comparison on the paper setup.

    ``quick`` keeps every arm but runs 2 layouts x 1 start of 150 steps (a demo and a test).
    """
    sim = SimConfig(n_steps=150) if quick else SimConfig()
    size = dict(n_layouts=2, n_starts=1) if quick else {}
    imp = {"preset": "improved"}
    wls = {"preset": "window", "tri_method": "lsq", "tri_window": 10}  # issue 8
    # local bundle adjustment in 10-pose windows, a new window every 3 steps (issue 8)
    wba = {"preset": "window", "tri_method": "ba", "tri_window": 10, "tri_stride": 3}
    exps = [
        Experiment("exp1", "Exp. 1: mapping without localisation", (
            Arm("stmds-cs", "stmds-cs"),
            Arm("stmds-smacof", "stmds-smacof"),
            Arm("stmds-cs (paper fusion)", "stmds-cs", {"fusion": "paper"}),
            Arm("stmds-smacof (paper fusion)", "stmds-smacof", {"fusion": "paper"}),
            Arm("stmds-cs (improved)", "stmds-cs", imp),
            Arm("stmds-smacof (improved)", "stmds-smacof", imp),
            Arm("stmds-smacof (window lsq)", "stmds-smacof", wls),
            Arm("stmds-smacof (window ba)", "stmds-smacof", wba),
        ), sim, seed, **size),
        Experiment("exp2", "Exp. 2: simultaneous localisation and mapping", (
            Arm("stmds-cs-loc", "stmds-cs-loc"),
            Arm("stmds-smacof-loc", "stmds-smacof-loc"),
            Arm("stmds-smacof-loc (improved)", "stmds-smacof-loc", imp),
            Arm("ekf", "ekf"),
            Arm("gtsam-batch", "gtsam-batch"),
            Arm("gtsam-isam2", "gtsam-isam2"),
            Arm("hybrid", "hybrid"),
        ), sim, seed, **size),
        Experiment("exp3", "Exp. 3: 10% of the pairs known as priors", (
            Arm("stmds-smacof", "stmds-smacof"),
            Arm("stmds-smacof+priors", "stmds-smacof", prior_fraction=0.1),
            Arm("stmds-smacof (improved)", "stmds-smacof", imp),
            Arm("stmds-smacof (improved)+priors", "stmds-smacof", imp, prior_fraction=0.1),
        ), sim, seed, **size),
        Experiment("all", "Every method side by side", (
            Arm("triangulate", "triangulate"),
            Arm("stmds-cs", "stmds-cs"),
            Arm("stmds-smacof", "stmds-smacof"),
            Arm("stmds-smacof (improved)", "stmds-smacof", imp),
            Arm("stmds-smacof (window lsq)", "stmds-smacof", wls),
            Arm("stmds-smacof (window ba)", "stmds-smacof", wba),
            Arm("stmds-smacof-loc (improved)", "stmds-smacof-loc", imp),
            Arm("ekf", "ekf"),
            Arm("gtsam-batch", "gtsam-batch"),
            Arm("gtsam-isam2", "gtsam-isam2"),
            Arm("hybrid", "hybrid"),
            Arm("oracle", "oracle"),
        ), sim, seed, **size),
    ]
    return {e.name: e for e in exps}


ALL_METHODS = ("triangulate", "stmds-cs", "stmds-smacof", "stmds-smacof-loc", "ekf",
               "ekf-invdepth", "gtsam-batch", "gtsam-isam2", "hybrid", "oracle")

#: Robust kernels of the factor-graph methods on recordings: Cauchy (3 sigma) on the odometry
#: and on the bearings (``FactorGraphConfig.odometry_cauchy_k`` / ``bearing_cauchy_k``).
ROBUST_GRAPH: dict[str, Any] = {"odometry_cauchy_k": 3.0, "bearing_cauchy_k": 3.0}

#: Arms added to the real-data experiments: the variants made for recordings (issues 7, 8),
#: each next to the paper's configuration of the same method.
REAL_VARIANTS: dict[str, tuple[tuple[str, dict[str, Any]], ...]] = {
    "stmds-cs": (("stmds-cs (real)", {"preset": "real"}),),
    "stmds-smacof": (("stmds-smacof (real)", {"preset": "real"}),),
    "stmds-smacof-loc": (("stmds-smacof-loc (real)", {"preset": "real"}),),
    "ekf": (("ekf (real)", {"preset": "real"}),),
    "ekf-invdepth": (("ekf-invdepth (real)", {"preset": "real"}),),
    "gtsam-batch": (("gtsam-batch (robust)", dict(ROBUST_GRAPH)),),
    "hybrid": (("hybrid (real seed)", {"seed_options": {"preset": "real"}}),
               ("hybrid (real seed, robust)", {"seed_options": {"preset": "real"},
                                               **ROBUST_GRAPH})),
    "oracle": (("oracle (robust)", dict(ROBUST_GRAPH)),),
}


def real_experiments(data_dir: str | os.PathLike[str],
                     methods: Sequence[str] = ALL_METHODS) -> dict[str, Experiment]:
    """Every method on the recordings with ground truth: MRCLAM6 robots 1-5 and the
    bearing-only g2o set (``data_dir`` is the shared data folder). Each method runs with its
    defaults (the paper's configuration) and, where one exists, with the variant for
    recordings (:data:`REAL_VARIANTS`)."""
    root = Path(data_dir)
    arms: tuple[Arm, ...] = ()
    for m in methods:
        arms += (Arm(m, m),)
        arms += tuple(Arm(label, m, options) for label, options in REAL_VARIANTS.get(m, ()))
    exps = {}
    if (root / "mrclam6").is_dir():
        exps["mrclam6"] = Experiment(
            "mrclam6", "MRCLAM Dataset 6 (real), robots 1-5", arms,
            sources=tuple(DatasetSource("mrclam", str(root / "mrclam6"), robot=r,
                                        label=f"mrclam6-r{r}") for r in range(1, 6)))
    g2o_dir = root / "bearing_only_sim_g2o"
    if g2o_dir.is_dir():
        gt = g2o_dir / "slam2D_bearing_only_ground_truth.g2o"
        exps["g2o"] = Experiment(
            "g2o", "bearing-only g2o set (Sapienza course, simulated)", arms,
            sources=(DatasetSource("g2o", str(g2o_dir / "slam2D_bearing_only_initial_guess.g2o"),
                                   truth_path=str(gt), label="g2o"),))
    if not exps:
        raise ConfigError(f"no dataset folders (mrclam6, bearing_only_sim_g2o) under {root}")
    return exps


# --------------------------------------------------------------------------------------------
# One task
# --------------------------------------------------------------------------------------------

def _pose_nees(est: MapEstimate, truth: Truth, alignment: Any) -> float:
    """NEES of the latest estimated pose (x, y, psi) in the aligned frame, or NaN."""
    if est.pose_cov is None or est.poses is None or truth.poses is None or not len(est.poses):
        return float("nan")
    from .angles import angle_residual

    k = int(np.argmax(est.pose_t))
    p = alignment.apply_poses(est.poses[k:k + 1])[0]
    true = truth.poses[est.pose_t[k]]
    e = np.array([p[0] - true[0], p[1] - true[1], float(angle_residual(p[2], true[2]))])
    t = np.eye(3)
    t[:2, :2] = alignment.rotation
    t[2, 2] = np.linalg.det(alignment.rotation)
    cov = t @ est.pose_cov[k] @ t.T
    try:
        return float(e @ np.linalg.solve(cov, e))
    except np.linalg.LinAlgError:
        return float("nan")


def _landmark_nees(est: MapEstimate, truth: Truth, alignment: Any) -> float:
    if est.landmark_cov is None:
        return float("nan")
    from .evaluate import landmark_nees

    try:
        return float(np.mean(landmark_nees(est, truth, alignment)))
    except np.linalg.LinAlgError:
        return float("nan")


def _jsonable(v: Any) -> Any:
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v)
    if isinstance(v, str) or v is None:
        return v
    if isinstance(v, (list, tuple, np.ndarray)) and len(v) <= 64:
        return [_jsonable(x) for x in v]
    return None


def run_task(task: Task) -> dict[str, Any]:
    """Simulate the task's run, run its method, and score every checkpoint.

    Returns a JSON-ready dict: per-checkpoint errors, timings, the method's final diagnostics.
    A method that raises is recorded as a failure with the reason, never dropped. The task
    runs with single-threaded BLAS: the matrices are small, parallelism is across tasks, and
    multithreaded BLAS on small matrices stalls on a loaded machine (measured: the EKF tests
    took 58 s instead of 7 s with 2 BLAS threads under a load of 2.8 on 2 cores).
    """
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        return _run_task(task)


def _run_task(task: Task) -> dict[str, Any]:
    out: dict[str, Any] = {"experiment": task.experiment, "arm": task.arm.label,
                           "method": task.arm.method, "run": task.source.name,
                           "key": task.key()}
    try:
        stream = task.stream()
    except Exception as exc:  # a source that cannot be read is a failed run, with the reason
        out.update(ok=False, error=f"{type(exc).__name__}: {exc}")
        return out
    truth = stream.truth
    if truth is None:
        out.update(ok=False, error="the stream has no ground truth to score against")
        return out
    try:
        needs_truth = method_info(task.arm.method).needs_truth
        mapper = create_mapper(task.arm.method, stream.header,
                               truth=truth if needs_truth else None, **dict(task.arm.options))
        result = run(mapper, stream.steps, checkpoint_every=task.checkpoint_every,
                     method=task.arm.label)
    except Exception as exc:  # a failing method is a result, reported with its reason
        out.update(ok=False, error=f"{type(exc).__name__}: {exc}")
        return out
    try:
        rows = _score_checkpoints(result, truth)
    except Exception as exc:  # an unscorable estimate is a failed run, with the reason
        out.update(ok=False, error=f"scoring failed: {type(exc).__name__}: {exc}")
        return out
    info = {k: _jsonable(v) for k, v in result.final.info.items()}
    final = result.final
    try:  # the final map and trajectory in the truth's frame, for the map figures
        al = score_estimate(final, truth).alignment
        out["final_map"] = {
            "landmarks": [[int(i), float(x), float(y)] for i, (x, y)
                          in zip(final.landmark_ids, al.apply(final.landmarks_xy))],
            "poses": ([] if final.poses is None else
                      [[int(t), float(x), float(y)] for t, (x, y)
                       in zip(final.pose_t, al.apply(final.poses[:, :2]))])}
    except TooFewLandmarksError:
        out["final_map"] = None
    out.update(ok=True, checkpoints=rows, total_s=result.total_s,
               step_median_s=float(np.median(result.step_s)),
               converged=info.get("converged"), info=info)
    return out


def _score_checkpoints(result: Any, truth: Truth) -> list[dict[str, Any]]:
    rows = []
    for c in result.checkpoints:
        row: dict[str, Any] = {"t": c.t, "n_mapped": len(c.estimate), "estimate_s": c.estimate_s}
        try:
            s = score_estimate(c.estimate, truth)
            row.update(mpe_m=s.mpe_m, rmse_m=s.rmse_m, median_m=s.median_m, max_m=s.max_m,
                       n_common=s.n_common, robot_last_m=s.robot_last_m,
                       robot_mean_m=s.robot_mean_m,
                       nees_landmark=_landmark_nees(c.estimate, truth, s.alignment),
                       nees_pose=_pose_nees(c.estimate, truth, s.alignment))
        except TooFewLandmarksError:
            common = np.intersect1d(c.estimate.landmark_ids, truth.landmark_ids).size
            row.update(mpe_m=math.nan, rmse_m=math.nan, median_m=math.nan, max_m=math.nan,
                       n_common=int(common), robot_last_m=math.nan, robot_mean_m=math.nan,
                       nees_landmark=math.nan, nees_pose=math.nan)
        rows.append(row)
    return rows


# --------------------------------------------------------------------------------------------
# Executing many tasks
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Executor:
    """Where tasks run: ``"serial"``, ``"processes"`` (joblib, one per core by default) or
    ``"dask"`` (an existing scheduler at ``scheduler`` or a local cluster of
    ``dask_local`` workers)."""

    backend: str = "processes"
    n_jobs: int = -1
    scheduler: str | None = None
    dask_local: int = 0

    def __post_init__(self) -> None:
        if self.backend not in ("serial", "processes", "dask"):
            raise ConfigError(f"backend must be serial, processes or dask, got {self.backend!r}")
        if self.backend == "dask" and not (self.scheduler or self.dask_local > 0):
            raise ConfigError("the dask backend needs a scheduler address or dask_local > 0")


def _cache_path(cache_dir: Path, task: Task) -> Path:
    """One file per (arm, source, code): experiments that share an arm share its runs."""
    return cache_dir / f"{task.key()}.json"


def execute(tasks: Sequence[Task], executor: Executor = Executor(), *,
            cache_dir: str | os.PathLike[str] | None = None,
            progress: Callable[[int, int], None] | None = None) -> list[dict[str, Any]]:
    """Run ``tasks`` and return their results in the order of ``tasks``.

    Finished tasks found in ``cache_dir`` are not run again; new results are written there as
    they arrive, so an interrupted sweep resumes where it stopped.
    """
    results: list[dict[str, Any] | None] = [None] * len(tasks)
    cache = Path(cache_dir) if cache_dir is not None else None
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
        for k, t in enumerate(tasks):
            p = _cache_path(cache, t)
            if p.exists():
                try:
                    cached = json.loads(p.read_text())
                except (json.JSONDecodeError, OSError):
                    continue
                cached.update(experiment=t.experiment, arm=t.arm.label)
                results[k] = cached
    todo = [k for k, r in enumerate(results) if r is None]
    done = len(tasks) - len(todo)
    if progress:
        progress(done, len(tasks))
    for k, res in _dispatch([tasks[k] for k in todo], todo, executor):
        results[k] = res
        if cache is not None and res.get("ok"):  # failures are re-run next time
            tmp = _cache_path(cache, tasks[k]).with_suffix(".tmp")
            tmp.write_text(json.dumps(res, allow_nan=True))
            tmp.replace(_cache_path(cache, tasks[k]))
        done += 1
        if progress:
            progress(done, len(tasks))
    return [r for r in results if r is not None]


def _indexed(k: int, task: Task) -> tuple[int, dict[str, Any]]:
    return k, run_task(task)


def _dispatch(tasks: list[Task], index: list[int],
              executor: Executor) -> Iterator[tuple[int, dict[str, Any]]]:
    if not tasks:
        return
    if executor.backend == "serial":
        for k, t in zip(index, tasks):
            yield k, run_task(t)
    elif executor.backend == "processes":
        from joblib import Parallel, delayed

        par = Parallel(n_jobs=executor.n_jobs, return_as="generator_unordered")
        yield from par(delayed(_indexed)(k, t) for k, t in zip(index, tasks))
    else:
        yield from _dispatch_dask(tasks, index, executor)


def _dispatch_dask(tasks: list[Task], index: list[int],
                   executor: Executor) -> Iterator[tuple[int, dict[str, Any]]]:
    from distributed import Client, LocalCluster, as_completed

    cluster = None
    if executor.scheduler:
        client = Client(executor.scheduler)
    else:
        cluster = LocalCluster(n_workers=executor.dask_local, threads_per_worker=1,
                               processes=True, host="127.0.0.1", dashboard_address=None)
        client = Client(cluster)
    try:
        futures = client.map(_indexed, index, tasks, pure=False)
        for fut in as_completed(futures):
            yield fut.result()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


# --------------------------------------------------------------------------------------------
# Summaries
# --------------------------------------------------------------------------------------------

def _value_at(res: Mapping[str, Any], t: int, key: str) -> float:
    """The metric at checkpoint ``t`` (the last checkpoint at or before ``t``)."""
    best = math.nan
    for row in res.get("checkpoints", []):
        if row["t"] <= t:
            v = row.get(key)
            best = math.nan if v is None else float(v)
    return best


def summarise(results: Sequence[Mapping[str, Any]],
              times: Sequence[int] = REPORT_TIMES) -> list[dict[str, Any]]:
    """One row per (experiment, arm): MPE at ``times`` (mean, median, std), robot error,
    convergence, NEES, wall time. Failed runs are counted, not hidden."""
    groups: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for r in results:
        groups.setdefault((r["experiment"], r["arm"]), []).append(r)
    exp_last: dict[str, int] = {}
    for r in results:
        if r.get("ok") and r["checkpoints"]:
            exp_last[r["experiment"]] = max(exp_last.get(r["experiment"], 0),
                                            r["checkpoints"][-1]["t"])
    rows = []
    for (exp, arm), rs in groups.items():
        ok = [r for r in rs if r.get("ok")]
        last_t = exp_last.get(exp, 0)
        row: dict[str, Any] = {"experiment": exp, "arm": arm, "method": rs[0]["method"],
                               "runs": len(rs), "failed": len(rs) - len(ok),
                               "errors": sorted({r.get("error", "") for r in rs
                                                 if not r.get("ok")})}
        for t in sorted({*[t for t in times if t <= last_t], last_t} - {0}):
            v = np.array([_value_at(r, t, "mpe_m") for r in ok])
            row[f"n_scored@{t}"] = int(np.sum(np.isfinite(v)))
            row[f"mpe_mean_m@{t}"] = float(np.nanmean(v)) if np.any(np.isfinite(v)) else math.nan
            row[f"mpe_median_m@{t}"] = float(np.nanmedian(v)) if np.any(np.isfinite(v)) else math.nan
            row[f"mpe_std_m@{t}"] = (float(np.nanstd(v, ddof=1)) if np.sum(np.isfinite(v)) > 1
                                     else math.nan)
        robot = np.array([_value_at(r, last_t, "robot_last_m") for r in ok])
        row["robot_last_mean_m"] = float(np.nanmean(robot)) if np.any(np.isfinite(robot)) else math.nan
        rm = np.array([np.nanmean([c["robot_last_m"] for c in r["checkpoints"]])
                       if any(np.isfinite(c["robot_last_m"]) for c in r["checkpoints"])
                       else math.nan for r in ok])
        row["robot_over_time_mean_m"] = float(np.nanmean(rm)) if np.any(np.isfinite(rm)) else math.nan
        conv = [r.get("converged") for r in ok if r.get("converged") is not None]
        row["converged_rate"] = float(np.mean(conv)) if conv else math.nan
        nees = np.array([_value_at(r, last_t, "nees_pose") for r in ok])
        row["nees_pose_mean"] = float(np.nanmean(nees)) if np.any(np.isfinite(nees)) else math.nan
        nl = np.array([_value_at(r, last_t, "nees_landmark") for r in ok])
        row["nees_landmark_mean"] = float(np.nanmean(nl)) if np.any(np.isfinite(nl)) else math.nan
        wall = np.array([r["total_s"] for r in ok])
        row["wall_s_mean"] = float(wall.mean()) if wall.size else math.nan
        row["paper"] = PAPER_REPORTED.get((exp, arm), "")
        row["last_t"] = last_t
        rows.append(row)
    return rows


def final_by_run(results: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """One row per run: the final checkpoint's landmark MPE, landmarks mapped and robot error,
    or the failure. For experiments whose runs are different recordings (the real data), where
    a mean over runs hides which recording a method fails on."""
    rows = []
    for r in results:
        row: dict[str, Any] = {"experiment": r["experiment"], "arm": r["arm"], "run": r["run"],
                               "ok": bool(r.get("ok")), "error": r.get("error", "")}
        last = r["checkpoints"][-1] if r.get("ok") and r.get("checkpoints") else {}
        row["t"] = last.get("t", math.nan)
        row["n_mapped"] = last.get("n_mapped", 0)
        for key in ("mpe_m", "robot_last_m"):
            v = last.get(key)
            row[key] = math.nan if v is None else float(v)
        row["converged"] = r.get("converged")
        row["total_s"] = r.get("total_s", math.nan)
        rows.append(row)
    return rows


def error_curves(results: Sequence[Mapping[str, Any]], metric: str = "mpe_m"
                 ) -> dict[tuple[str, str], tuple[np.ndarray, np.ndarray]]:
    """Per (experiment, arm): checkpoint times ``(k,)`` and the metric ``(runs, k)``."""
    out: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]] = {}
    groups: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for r in results:
        if r.get("ok"):
            groups.setdefault((r["experiment"], r["arm"]), []).append(r)
    for key, rs in groups.items():
        ts = np.array([c["t"] for c in rs[0]["checkpoints"]])
        vals = np.array([[_value_at(r, t, metric) for t in ts] for r in rs])
        out[key] = (ts, vals)
    return out


def results_to_csv_rows(results: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Long format: one row per (experiment, arm, run, checkpoint)."""
    rows = []
    for r in results:
        if not r.get("ok"):
            rows.append({"experiment": r["experiment"], "arm": r["arm"], "run": r["run"],
                         "ok": False, "error": r.get("error", "")})
            continue
        for c in r["checkpoints"]:
            rows.append({"experiment": r["experiment"], "arm": r["arm"], "run": r["run"],
                         "ok": True, "error": "", **c})
    return rows


def strip_timings(results: Iterable[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Results without wall times (which differ between runs), for reproducibility checks."""
    out = []
    for r in results:
        r2 = {k: v for k, v in r.items() if k not in ("total_s", "step_median_s")}
        if "checkpoints" in r2:
            r2["checkpoints"] = [{k: v for k, v in c.items() if k != "estimate_s"}
                                 for c in r2["checkpoints"]]
        if "info" in r2 and isinstance(r2["info"], dict):
            r2["info"] = {k: v for k, v in r2["info"].items() if not k.endswith("_s")}
        out.append(r2)
    return out


__all__ = ["Arm", "Experiment", "Task", "Executor", "paper_experiments", "real_experiments",
           "SimSource", "DatasetSource", "compare", "CompareResult", "code_fingerprint", "run_task", "execute",
           "summarise", "error_curves", "results_to_csv_rows", "strip_timings",
           "PAPER_REPORTED", "REPORT_TIMES"]


# --------------------------------------------------------------------------------------------
# The comparison: run, summarise, write
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class CompareResult:
    """What :func:`compare` produced: raw results, the summary table and the files written."""

    results: tuple[dict[str, Any], ...]
    summary: tuple[dict[str, Any], ...]
    files: tuple[str, ...]
    wall_s: float


def _write_csv(path: Path, rows: Sequence[Mapping[str, Any]]) -> None:
    import csv

    cols: list[str] = []
    for r in rows:
        for k in r:
            if k not in cols:
                cols.append(k)
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=cols)
        w.writeheader()
        for r in rows:
            w.writerow({k: (";".join(map(str, v)) if isinstance(v, list) else v)
                        for k, v in r.items()})


def compare(experiments: Sequence[Experiment], out_dir: str | os.PathLike[str], *,
            executor: Executor = Executor(), use_cache: bool = True, figures: bool = True,
            progress: Callable[[int, int], None] | None = None) -> CompareResult:
    """Run ``experiments``, write ``results.json``, ``results.csv``, ``summary.csv`` and the
    figures (PNG) into ``out_dir``, and return the summary.

    Finished runs are cached in ``out_dir/cache`` so an interrupted sweep resumes.
    """
    import time

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    tasks = [t for e in experiments for t in e.tasks()]
    results = execute(tasks, executor, cache_dir=out / "cache" if use_cache else None,
                      progress=progress)
    summary = summarise(results)
    wall = time.perf_counter() - start
    files = [out / "results.json", out / "results.csv", out / "summary.csv"]
    (out / "results.json").write_text(json.dumps(
        {"experiments": [{"name": e.name, "title": e.title,
                          "arms": [a.key() for a in e.arms], "seed": e.seed,
                          "runs": len(e.runs()), "n_steps": e.sim.n_steps}
                         for e in experiments],
         "summary": summary, "results": results, "wall_s": wall}, allow_nan=True, indent=1))
    _write_csv(out / "results.csv", results_to_csv_rows(results))
    _write_csv(out / "summary.csv", summary)
    _write_csv(out / "final_by_run.csv", final_by_run(results))
    files.append(out / "final_by_run.csv")
    if figures:
        from .plots import write_compare_figures

        files += write_compare_figures(out, experiments, results)
    return CompareResult(tuple(results), tuple(summary), tuple(str(f) for f in files), wall)


def example_estimate(method: str, experiment: Experiment, *, run_index: int = 0,
                     t: int | None = None) -> tuple[Stream, MapEstimate]:
    """One run of ``method`` on the experiment's first run; the estimate at checkpoint ``t``
    (the last one by default). For the map figures (paper fig. 3 and 5)."""
    spec = experiment.runs()[run_index]
    stream = simulate_run(spec, experiment.sim)
    needs_truth = method_info(method).needs_truth
    mapper = create_mapper(method, stream.header, truth=stream.truth if needs_truth else None)
    res = run(mapper, stream.steps, checkpoint_every=experiment.checkpoint_every)
    return stream, (res.final if t is None else res.at(t))
