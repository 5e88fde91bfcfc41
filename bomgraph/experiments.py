"""Experiments as data (paper section IV: Exp. 1 mapping, Exp. 2 SLAM, Exp. 3 priors, and
the recordings with ground truth).

An :class:`Experiment` is a tuple of :class:`Arm` (a method with a named preset, with or
without prior pairs) crossed with a run design (:func:`bomgraph.sim.paper_design`) or with
recorded :class:`DatasetSource` s. Each (arm, run) pair is a :class:`Task`, a pure description:
:mod:`bomgraph.bench` runs it, :mod:`bomgraph.evaluate` scores it, :mod:`bomgraph.report`
summarises it. Arms name presets only (``{"preset": NAME}``), so every configuration the
comparison shows is one a user can ask for by name. The sources of the runs are
:mod:`bomgraph.sources` (re-exported here).
"""

from __future__ import annotations

import json
import os
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping, Sequence

from .checks import file_name, fraction, instance, integer, items, option_named
from .errors import ConfigError, UnknownMethodError, shown_path
from .jsonio import options_to_json
from .mapper import available_methods, method_config_class, method_info
from .sim import RunSpec, SimConfig, paper_design
from .sources import (SIMULATED, DatasetSource, FileSource, SimSource, SimulatedStreams, World,
                      WorldSource)
from .stream import Stream
from .tables import plural

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
    ``checkpoint_every`` overrides the experiment's cadence for this arm (the task's
    ``every`` in the cache key says which one ran).
    """

    label: str
    method: str
    options: Mapping[str, Any] = field(default_factory=dict)
    prior_fraction: float = 0.0
    checkpoint_every: int | None = None

    def __post_init__(self) -> None:
        where = f"arm {self.label!r}"
        instance(self.label, str, f"{where}: label", ConfigError)
        instance(self.method, str, f"{where}: method (a method's name)", ConfigError)
        fraction(self.prior_fraction, f"{where}: prior_fraction", ConfigError)
        if self.checkpoint_every is not None:
            integer(self.checkpoint_every, f"{where}: checkpoint_every", ConfigError, minimum=1)
        try:   # infinities as options_to_json records them (a string so spelled refused)
            json.dumps(options_to_json(dict(self.options)), allow_nan=False)
        except ConfigError as exc:
            raise ConfigError(f"arm {self.label!r}: {exc}") from None
        except (TypeError, ValueError):
            raise ConfigError(f"arm {self.label!r}: options must be plain JSON values (numbers, "
                              f"infinities, strings, lists) so results can be cached and "
                              f"compared") from None

    def key(self) -> dict[str, Any]:
        """The arm as JSON data (the cache key's, results.json's): the options as recorded,
        an infinity as ``"Infinity"`` (:func:`bomgraph.jsonio.options_to_json`; no string
        option is spelled so, so two different values never share a key)."""
        return {"label": self.label, "method": self.method,
                "options": options_to_json(dict(self.options)),
                "prior_fraction": self.prior_fraction}


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
    sources: tuple[DatasetSource | FileSource, ...] = ()
    worlds: tuple[World, ...] = ()
    reference: Arm | None = None

    def __post_init__(self) -> None:
        where = f"experiment {self.name!r}"
        instance(self.name, str, f"{where}: name", ConfigError)
        for key, kinds in (("arms", Arm), ("sources", (DatasetSource, FileSource)),
                           ("worlds", World)):
            value = items(getattr(self, key), kinds, f"{where}: {key}", ConfigError)
            if not isinstance(getattr(self, key), (list, tuple)):  # an iterator is read once
                object.__setattr__(self, key, value)
        instance(self.sim, SimConfig, f"{where}: sim", ConfigError)
        instance(self.reference, (Arm, type(None)), f"{where}: reference", ConfigError)
        for key, low in (("seed", 0), ("n_layouts", 1), ("n_starts", 1), ("checkpoint_every", 1)):
            integer(getattr(self, key), f"{where}: {key}", ConfigError, minimum=low)
        runs = [s.name for s in self.sources] + [s.name for w in self.worlds
                                                 for s in w.sources(0.0)]
        # not list.count: quadratic, 3.8 s for a glob of 20,000 streams (h101, as h96's)
        twice = sorted(r for r, n in Counter(runs).items() if n > 1)
        if twice:  # a run's name keys its estimate file, its table column and its figure
            raise ConfigError(f"{where}: two runs are named {twice[0]!r} (a source's label and "
                              f"a world's run WORLD-seedN, or two sources): their estimates and "
                              f"table columns would collide; rename the world or the source")

    @property
    def designed(self) -> bool:
        """Whether the runs are the paper's design (no recorded sources, no worlds)."""
        return not self.sources and not self.worlds

    def runs(self) -> list[RunSpec]:
        return paper_design(self.seed, self.n_layouts, self.n_starts)

    def n_runs(self) -> int:
        """Runs per arm: the design's, or the sources and world seeds."""
        if self.designed:
            return len(self.runs())
        return len(self.sources) + sum(len(w.seeds) for w in self.worlds)

    def tasks(self) -> list["Task"]:
        """Every arm on every run, arm by arm. Streams without truth are scored against
        ``reference`` (when given) by the runner."""
        def task(arm: Arm, src: Any) -> Task:
            return Task(self.name, arm, src, arm.checkpoint_every or self.checkpoint_every,
                        self.reference)
        if not self.designed:
            return [task(arm, src) for arm in self.arms
                    for src in (*self.sources,
                                *[s for w in self.worlds for s in w.sources(arm.prior_fraction)])]
        return [task(arm, SimSource(spec, self.sim, arm.prior_fraction, self.prior_sigma_xy_m))
                for arm in self.arms for spec in self.runs()]


@dataclass(frozen=True)
class Task:
    """One method on one run (simulated or recorded)."""

    experiment: str
    arm: Arm
    source: SimSource | DatasetSource | FileSource | WorldSource
    checkpoint_every: int = 10
    reference: Arm | None = None
    #: the result also carries the final estimate as an estimate file's text
    #: (``compare --estimates``)
    keep_estimate: bool = False

    def __post_init__(self) -> None:
        instance(self.arm, Arm, "Task: arm", ConfigError)
        instance(self.source, (SimSource, DatasetSource, FileSource, WorldSource),
                 "Task: source", ConfigError)
        instance(self.reference, (Arm, type(None)), "Task: reference", ConfigError)
        integer(self.checkpoint_every, "Task: checkpoint_every", ConfigError, minimum=1)

    def stream(self) -> Stream:
        return self.source.stream()

    def methods(self) -> list[str]:
        """Every method the task runs: the arm's, the reference's, and the registered methods
        its options name (a ``*method`` key, nested tables too: ``hybrid``'s ``seed_method``),
        so that a plugin run as a seed is in the cache key and the worker checks too."""
        arms = [self.arm] + ([self.reference] if self.reference is not None else [])
        return list(dict.fromkeys(m for a in arms for m in (a.method, *_named_methods(a.options))))

    def identity(self) -> dict[str, Any]:
        """What makes the task what it is (the arm, the source, the checkpoints, the
        reference method, whether the estimate is kept): the runner hashes it with the code's
        fingerprint into the cache key."""
        out = {"arm": self.arm.key(), "source": self.source.key(),
               "every": self.checkpoint_every}
        if self.reference is not None:
            out["reference"] = self.reference.key()
        if self.keep_estimate:
            out["estimate"] = True
        return out


def _named_methods(options: Any) -> list[str]:
    """The registered methods named by ``options``' ``*method`` keys, at any depth."""
    out: list[str] = []
    for key, value in (options.items() if isinstance(options, Mapping) else ()):
        if isinstance(value, Mapping):
            out += _named_methods(value)
        elif isinstance(value, str) and str(key).endswith("method"):
            try:
                method_info(value)
            except UnknownMethodError:  # not a method's name (``tri_method="ba"``)
                continue
            out.append(value)
    return out


def paper_experiments(*, quick: bool = False, seed: int = 0) -> dict[str, Experiment]:
    """Exp. 1-3 and the all-methods comparison on the paper setup: the sweep file shipped as
    ``bomgraph/sweeps/paper.toml`` (``bomgraph compare --config paper``).

    ``quick`` keeps every arm but runs 2 layouts x 1 start of 150 steps (a demo and a test);
    ``seed`` is the design's seed.
    """
    return {e.name: e for e in designed_variant(load_experiments("paper").experiments,
                                                quick=quick, seed=seed)}


def designed_variant(experiments: Sequence[Experiment], *, quick: bool = False,
                     seed: int | None = None) -> list[Experiment]:
    """``experiments`` with their design (the paper's runs) made quick (2 layouts x 1 start
    of 150 steps) and/or given another ``seed``; experiments on streams or worlds as given."""
    out = []
    for e in items(experiments, Experiment, "designed_variant(): experiments", ConfigError):
        if e.designed:
            if quick:
                e = replace(e, sim=replace(e.sim, n_steps=150), n_layouts=2, n_starts=1)
            if seed is not None:
                e = replace(e, seed=seed)
        out.append(e)
    return out


@dataclass(frozen=True)
class Sweep:
    """Experiments read from a sweep file, with its executor settings (``jobs``,
    ``dask_local``, ``scheduler``; absent keys are left to the caller)."""

    experiments: tuple[Experiment, ...]
    executor: Mapping[str, Any]
    path: str


def load_experiments(path_or_name: Any) -> Sweep:
    """The experiments of a sweep file (:mod:`bomgraph.sweep` reads and checks it), of a
    shipped one by name (``"paper"``: :func:`bomgraph.sweep.shipped`), or of a ready
    :class:`bomgraph.sweep.SweepSpec` (e.g. :func:`bomgraph.command_line_sweep.command_line_spec`).

    Raises
    ------
    SweepError
        The file is missing, is not TOML, or a key is unknown or has a bad value (the message
        names the file and the key).
    """
    from .sweep import SweepSpec, read_sweep

    spec = path_or_name if isinstance(path_or_name, SweepSpec) else read_sweep(path_or_name)
    exps = []
    for e in spec.experiments:
        def arm(m: Any) -> Arm:
            return Arm(m.label, m.method, m.options, m.prior_fraction, m.checkpoint_every)
        design = next((w for w in e.worlds if w.design is not None), None)
        common = dict(checkpoint_every=e.checkpoint_every,
                      reference=None if e.reference is None else arm(e.reference))
        arms = tuple(arm(m) for m in e.methods)
        if design is not None:
            d = design.design
            exps.append(Experiment(e.name, e.title, arms, design.sim, d["seed"], d["layouts"],
                                   d["starts"], design.prior_sigma_xy_m, **common))
            continue
        exps.append(Experiment(
            e.name, e.title, arms, **common,
            sources=tuple(FileSource(p, label) for p, label in e.streams),
            worlds=tuple(World(w.name, w.sim, w.seeds, w.prior_sigma_xy_m) for w in e.worlds)))
    return Sweep(tuple(exps), dict(spec.executor), spec.path)


def compare_experiments(*, config: str | None = None, streams: Sequence[str] | None = None,
                        methods: str | None = None, options: Sequence[str] = (),
                        reference: str | None = None, checkpoint_every: int | None = None,
                        real: str | None = None, quick: bool = False, seed: int | None = None,
                        names: Sequence[str] = ()) -> tuple[list[Experiment], dict[str, Any]]:
    """What ``bomgraph compare`` runs, from its options: a sweep file (``config``; default
    the shipped ``paper``, whose design ``quick`` and ``seed`` change), stream files with
    ``methods`` (``"NAME[@PRESET],..."``), ``options`` (``"NAME:KEY=VALUE"``) and a
    ``reference``, or the recordings under ``real``; then the experiments called ``names``.
    Returns them and the sweep file's executor settings (with ``file``, its path, if any).

    Raises
    ------
    ConfigError
        Options that do not go together (the message says which); a SweepError for a bad
        sweep file or stream list.
    """
    from .command_line_sweep import command_line_spec

    where = "compare_experiments()"
    if streams is not None:
        items(streams, (str, os.PathLike), f"{where}: streams", ConfigError,
              want="stream file names")
    instance(methods, (str, type(None)), f"{where}: methods ('NAME[@PRESET],...', as "
                                         f"--methods)", ConfigError)
    items(options, str, f"{where}: options", ConfigError, want="'NAME:KEY=VALUE' strings")
    if checkpoint_every is not None:   # 0 used to mean the default, 10
        integer(checkpoint_every, f"{where}: checkpoint_every", ConfigError, minimum=1)
    # named as the command line's options while a command runs, else as the parameters (h107)
    lead, opt = option_named("compare", where), option_named  # compare_experiments():
    sources = [opt(o, p) for o, p in (("--config", "config"), ("--streams", "streams"),
                                      ("--real", "real"))]
    given = [n for n, v in zip(sources, (config, streams, real)) if v]
    if len(given) > 1:
        raise ConfigError(f"{lead}: give one of {', '.join(sources)}, not {' and '.join(given)}")
    for flag, value, where in (("--methods", methods, "[[methods]] tables"),
                               ("--option", options, "options = {...}"),
                               ("--reference", reference, 'reference = "NAME"'),
                               ("--checkpoint-every", checkpoint_every, "checkpoint_every = N")):
        if value and not streams and not (real and flag == "--methods"):
            param = flag[2:].replace("-", "_") + ("s" if flag == "--option" else "")
            raise ConfigError(f"{lead}: {opt(flag, param)} goes with "
                              f"{opt('--streams FILE...', 'streams')}"
                              f"{' or ' + opt('--real DIR', 'real') if flag == '--methods' else ''}"
                              f" (in a sweep file: {where})")
    settings: dict[str, Any] = {}
    if real:
        exps = real_experiments(real, _real_method_names(methods) if methods else None)
    elif streams:
        sweep = load_experiments(command_line_spec(
            streams, [m.strip() for m in (methods or "").split(",") if m.strip()], options,
            reference=reference, checkpoint_every=checkpoint_every or 10))
        exps = {e.name: e for e in sweep.experiments}
    else:
        sweep = load_experiments(config or "paper")
        settings = dict(sweep.executor)
        if settings:       # named in the errors about its scheduler (Executor.choose)
            settings["file"] = sweep.path
        exps = {e.name: e for e in designed_variant(sweep.experiments, quick=quick, seed=seed)}
    return select(exps, names), settings


def _real_method_names(methods: str) -> list[str]:
    """The methods of ``compare --real --methods A,B``: names only (each runs with its
    defaults and its recording variants, :func:`real_variants`), each known (plugins
    included), none twice."""
    names = [m.strip() for m in methods.split(",") if m.strip()]
    lead = option_named("compare --real --methods", "compare_experiments(): methods with real")
    for name in names:
        if "@" in name:
            raise ConfigError(f"{lead}: give names without a preset "
                              f"({name!r}): each method runs with its defaults and its "
                              f"recording variants")
        method_info(name)
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ConfigError(f"{lead}: {', '.join(twice)} appears twice")
    if not names:
        raise ConfigError(f"{lead}: give at least one method")
    return names


#: Registered methods the real-data experiments leave out by default (as before the redesign:
#: Method 1 runs there as the mapping arm ``stmds-cs``, localisation as ``stmds-smacof-loc``).
REAL_SKIPPED = ("stmds-cs-loc",)


def real_methods() -> list[str]:
    """The methods of :func:`real_experiments` by default: every built-in method (in
    registration order) except :data:`REAL_SKIPPED` (plugins run through ``compare
    --streams`` or a sweep file)."""
    return [m.name for m in available_methods()
            if m.name not in REAL_SKIPPED and m.origin == "builtin"]


#: Arms added to the real-data experiments: the variants made for recordings (issues 7, 8),
#: each next to the paper's configuration of the same method.
REAL_VARIANTS: dict[str, tuple[tuple[str, dict[str, Any]], ...]] = {
    "stmds-cs": (("stmds-cs (real)", {"preset": "real"}),),
    "stmds-smacof": (("stmds-smacof (real)", {"preset": "real"}),),
    "stmds-smacof-loc": (("stmds-smacof-loc (real)", {"preset": "real"}),),
    "ekf": (("ekf (real)", {"preset": "real"}),),
    "ekf-invdepth": (("ekf-invdepth (real)", {"preset": "real"}),),
    "gtsam-batch": (("gtsam-batch (real)", {"preset": "real"}),),
    "gtsam-isam2": (("gtsam-isam2 (real)", {"preset": "real"}),),
    "hybrid": (("hybrid (real seed)", {"preset": "real-seed"}),
               ("hybrid (real)", {"preset": "real"})),
    "hybrid-isam2": (("hybrid-isam2 (real)", {"preset": "real"}),),
    "oracle": (("oracle (real)", {"preset": "real"}),),
}


def real_variants(method: str) -> tuple[tuple[str, dict[str, Any]], ...]:
    """The recording arms of ``method`` beside its defaults: :data:`REAL_VARIANTS` for a
    built-in method (none for one it does not list, e.g. ``triangulate``); for any other (a
    plugin, a method registered at run time) ``"NAME (real)"`` with ``preset="real"`` when its
    configuration has a ``real`` preset, else none."""
    if method in REAL_VARIANTS or method_info(method).origin == "builtin":
        return REAL_VARIANTS.get(method, ())
    presets = getattr(method_config_class(method), "PRESETS", None) or {}
    return ((f"{method} (real)", {"preset": "real"}),) if "real" in presets else ()


def real_experiments(data_dir: str | os.PathLike[str],
                     methods: Sequence[str] | None = None) -> dict[str, Experiment]:
    """Every method on the recordings with ground truth: MRCLAM6 robots 1-5 and the
    bearing-only g2o set (``data_dir`` is the shared data folder). Each method runs with its
    defaults (the paper's configuration) and, where one exists, with the variant for
    recordings (:func:`real_variants`: a plugin's ``real`` preset included). ``methods``
    defaults to :func:`real_methods`."""
    root = Path(file_name(data_dir, "real_experiments(): data_dir", ConfigError))
    if methods is not None:
        for m in items(methods, str, "real_experiments(): methods", ConfigError,
                       want="method names"):
            method_info(m)   # an UnknownMethodError naming the known ones
    arms: tuple[Arm, ...] = ()
    for m in (real_methods() if methods is None else methods):
        arms += (Arm(m, m),)
        arms += tuple(Arm(label, m, options) for label, options in real_variants(m))
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
        raise ConfigError(f"no dataset folders (mrclam6, bearing_only_sim_g2o) under "
                          f"{shown_path(root)}")
    return exps


def select(experiments: Mapping[str, Experiment], names: Sequence[str] = ()) -> list[Experiment]:
    """The experiments called ``names`` (all of them when empty), in that order.

    Raises
    ------
    ConfigError
        A name is not one of ``experiments``.
    """
    instance(experiments, Mapping, "select(): experiments (name -> Experiment)", ConfigError)
    names = list(items(names, str, "select(): names", ConfigError, want="experiment names")
                 ) or list(experiments)
    unknown = [n for n in names if n not in experiments]
    if unknown:
        raise ConfigError(f"unknown {plural(len(unknown), 'experiment')} {unknown}; choose from "
                          f"{list(experiments)}")
    return [experiments[n] for n in names]


__all__ = ["SimulatedStreams", "SIMULATED", "Arm", "SimSource", "DatasetSource", "FileSource",
           "WorldSource", "World",
           "Experiment", "Task", "Sweep", "load_experiments", "designed_variant",
           "compare_experiments",
           "paper_experiments",
           "real_experiments", "real_methods", "real_variants", "select", "REAL_VARIANTS",
           "REAL_SKIPPED",
           "PAPER_REPORTED"]
