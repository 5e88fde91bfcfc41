"""Experiments as data (paper section IV: Exp. 1 mapping, Exp. 2 SLAM, Exp. 3 priors, and
the recordings with ground truth).

An :class:`Experiment` is a tuple of :class:`Arm` (a method with a named preset, with or
without prior pairs) crossed with a run design (:func:`bomgraph.sim.paper_design`) or with
recorded :class:`DatasetSource` s. Each (arm, run) pair is a :class:`Task`, a pure description:
:mod:`bomgraph.bench` runs it, :mod:`bomgraph.evaluate` scores it, :mod:`bomgraph.report`
summarises it. Arms name presets only (``{"preset": NAME}``), so every configuration the
comparison shows is one a user can ask for by name.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

from .errors import ConfigError
from .mapper import available_methods
from .sim import RunSpec, SimConfig, paper_design, simulate_run
from .stream import Stream

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
    """One curve of an experiment: a method, its options, and the prior pairs it is given.

    ``options`` are the method factory's keyword options, plain JSON values (they are hashed
    into the cache key): ``{"preset": NAME}`` in the library's experiments.
    """

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

    def identity(self) -> dict[str, Any]:
        """What makes the task what it is (the arm, the source, the checkpoints): the runner
        hashes it with the code's fingerprint into the cache key."""
        return {"arm": self.arm.key(), "source": self.source.key(),
                "every": self.checkpoint_every}


def paper_experiments(*, quick: bool = False, seed: int = 0) -> dict[str, Experiment]:
    """Exp. 1-3 and the all-methods comparison on the paper setup.

    ``quick`` keeps every arm but runs 2 layouts x 1 start of 150 steps (a demo and a test).
    """
    sim = SimConfig(n_steps=150) if quick else SimConfig()
    size = dict(n_layouts=2, n_starts=1) if quick else {}
    imp = {"preset": "improved"}
    wls = {"preset": "window-lsq"}  # least squares over 10-pose windows (issue 8)
    wba = {"preset": "window-ba"}  # bundle adjustment in 10-pose windows, stride 3 (issue 8)
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


#: Registered methods the real-data experiments leave out by default (as before the redesign:
#: Method 1 runs there as the mapping arm ``stmds-cs``, localisation as ``stmds-smacof-loc``).
REAL_SKIPPED = ("stmds-cs-loc",)


def real_methods() -> list[str]:
    """The methods of :func:`real_experiments` by default: every registered method (in
    registration order) except :data:`REAL_SKIPPED`."""
    return [m.name for m in available_methods() if m.name not in REAL_SKIPPED]


#: Arms added to the real-data experiments: the variants made for recordings (issues 7, 8),
#: each next to the paper's configuration of the same method.
REAL_VARIANTS: dict[str, tuple[tuple[str, dict[str, Any]], ...]] = {
    "stmds-cs": (("stmds-cs (real)", {"preset": "real"}),),
    "stmds-smacof": (("stmds-smacof (real)", {"preset": "real"}),),
    "stmds-smacof-loc": (("stmds-smacof-loc (real)", {"preset": "real"}),),
    "ekf": (("ekf (real)", {"preset": "real"}),),
    "ekf-invdepth": (("ekf-invdepth (real)", {"preset": "real"}),),
    "gtsam-batch": (("gtsam-batch (robust)", {"preset": "robust"}),),
    "hybrid": (("hybrid (real seed)", {"preset": "real-seed"}),
               ("hybrid (real seed, robust)", {"preset": "real-seed-robust"})),
    "hybrid-isam2": (("hybrid-isam2 (real)", {"preset": "real"}),),
    "oracle": (("oracle (robust)", {"preset": "robust"}),),
}


def real_experiments(data_dir: str | os.PathLike[str],
                     methods: Sequence[str] | None = None) -> dict[str, Experiment]:
    """Every method on the recordings with ground truth: MRCLAM6 robots 1-5 and the
    bearing-only g2o set (``data_dir`` is the shared data folder). Each method runs with its
    defaults (the paper's configuration) and, where one exists, with the variant for
    recordings (:data:`REAL_VARIANTS`). ``methods`` defaults to :func:`real_methods`."""
    root = Path(data_dir)
    arms: tuple[Arm, ...] = ()
    for m in (real_methods() if methods is None else methods):
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


def select(experiments: Mapping[str, Experiment], names: Sequence[str] = ()) -> list[Experiment]:
    """The experiments called ``names`` (all of them when empty), in that order.

    Raises
    ------
    ConfigError
        A name is not one of ``experiments``.
    """
    names = list(names) or list(experiments)
    unknown = [n for n in names if n not in experiments]
    if unknown:
        raise ConfigError(f"unknown experiment(s) {unknown}; choose from {list(experiments)}")
    return [experiments[n] for n in names]


__all__ = ["Arm", "SimSource", "DatasetSource", "Experiment", "Task", "paper_experiments",
           "real_experiments", "real_methods", "select", "REAL_VARIANTS", "REAL_SKIPPED",
           "PAPER_REPORTED"]
