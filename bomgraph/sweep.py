"""Sweep files: what ``bomgraph compare --config FILE`` runs, read and checked.

A sweep file is TOML (``tomllib``). One experiment at the top level::

    name = "mine"                       # optional (default: the file's stem)
    streams = ["runs/*.jsonl"]          # globs, relative to the file
    checkpoint_every = 10               # optional (default 10)
    reference = "gtsam-isam2@real"      # optional: scores streams without ground truth

    [[worlds]]                          # simulated runs: SimConfig fields plus seeds
    n_steps = 200
    noise_scale = 0.5
    seeds = [0, 1, 2]                   # or a count: seeds = 3 (0, 1, 2)

    [[methods]]
    name = "stmds-smacof"
    preset = "real"                     # optional
    options = { window = 40 }           # optional: the factory's keyword options
    checkpoint_every = 20               # optional, this method only

    [executor]                          # optional; the command line's flags win
    jobs = 2                            # or dask_local = 2, or scheduler = "tcp://host:8786"

or several in ``[[experiments]]`` tables of the same keys (``checkpoint_every``,
``reference`` and ``[executor]`` at the top level are defaults for all of them). A world may
instead be the paper's design, ``design = { seed = 0, layouts = 5, starts = 5 }`` (the 25
runs of section IV), alone in its experiment; a method may carry ``label`` and
``prior_fraction`` (Exp. 3's priors on simulated runs). ``methods`` may also be a list of
strings ``"NAME"`` / ``"NAME@PRESET"``. The paper's experiments are such a file, shipped in
the package (``bomgraph/sweeps/paper.toml``, ``--config paper``).

:func:`read_sweep` returns plain, checked data (:class:`SweepSpec`); a mistake raises
:class:`SweepError` with one line naming the file and the key.
:func:`bomgraph.command_line_sweep.command_line_spec` turns ``compare --streams ...
--methods ...`` into the same data with this module's checks (:func:`parse_method`,
:func:`checked_method`, :func:`check_unique`, :func:`named_streams`), so a sweep file and the
equivalent command line run the same tasks with the same cache keys.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import tomllib
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

from .checks import echo, file_name
from .errors import BomgraphError, ConfigError, shown_path
from .jsonio import BOM_ADVICE
from .sim import SimConfig
from .stream_globs import GlobTooWideError, bounded_glob
from .tables import counted

#: The folder of the sweep files shipped in the package (``--config NAME``).
SHIPPED_DIR = Path(__file__).with_name("sweeps")

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+-]*$")
_SIM_FIELDS = {f.name: f for f in dataclasses.fields(SimConfig)}
_TOP = {"name", "title", "streams", "worlds", "methods", "reference", "checkpoint_every",
        "executor", "experiments"}
_EXPERIMENT = {"name", "title", "streams", "worlds", "methods", "reference", "checkpoint_every"}
_METHOD = {"name", "preset", "options", "label", "checkpoint_every", "prior_fraction"}
_WORLD_EXTRA = {"name", "seeds", "design", "prior_sigma_xy_m"}
_EXECUTOR = {"jobs", "dask_local", "scheduler"}
#: a sweep file is read whole; beyond this it is not one (the shipped ones are 2-3 KiB).
MAX_SWEEP_BYTES = 16 * 2**20
#: the most simulated runs of one world (its seeds, or a design's layouts x starts): a bound
#: on a typo (``seeds = 1000000000``), far beyond any sweep one machine finishes.
MAX_WORLD_RUNS = 100_000
#: the most tasks of one sweep (its runs, simulated or streams, times its methods, the
#: reference counted as one): the same bound on the whole file, whose worlds and methods are
#: otherwise not counted (2,000 worlds of 100,000 seeds each ran out of memory while the
#: file was read, before h91's fix).
MAX_SWEEP_TASKS = 1_000_000


class SweepError(ConfigError):
    """A sweep file (or its command-line equivalent) that cannot be run: the message names
    the file and the key."""


@dataclass(frozen=True)
class MethodSpec:
    """One arm: the curve's ``label``, the registered ``method`` and its factory options
    (``{"preset": NAME, ...}``)."""

    label: str
    method: str
    options: Mapping[str, Any] = field(default_factory=dict)
    prior_fraction: float = 0.0
    checkpoint_every: int | None = None


@dataclass(frozen=True)
class WorldSpec:
    """Simulated runs: ``sim`` with ``seeds`` (``bomgraph simulate --seed``), or the paper's
    ``design`` (``{"seed", "layouts", "starts"}``)."""

    name: str
    sim: SimConfig
    seeds: tuple[int, ...] = ()
    design: Mapping[str, int] | None = None
    prior_sigma_xy_m: float = 0.03


@dataclass(frozen=True)
class ExperimentSpec:
    name: str
    title: str
    methods: tuple[MethodSpec, ...]
    streams: tuple[tuple[str, str], ...] = ()  # (path, run label)
    worlds: tuple[WorldSpec, ...] = ()
    reference: MethodSpec | None = None
    checkpoint_every: int = 10


@dataclass(frozen=True)
class SweepSpec:
    path: str
    experiments: tuple[ExperimentSpec, ...]
    executor: Mapping[str, Any] = field(default_factory=dict)


def shipped() -> list[str]:
    """The names of the sweep files shipped in the package (``--config NAME``)."""
    return sorted(p.stem for p in SHIPPED_DIR.glob("*.toml"))


def resolve_path(path_or_name: str | os.PathLike[str]) -> Path:
    """A sweep file's path: ``path_or_name`` itself, or a shipped file of that name."""
    p = Path(file_name(path_or_name, "the sweep file (a path or a shipped name)", SweepError))
    if p.is_file():
        return p
    if (SHIPPED_DIR / f"{p}.toml").is_file() and p.suffix != ".toml":
        return SHIPPED_DIR / f"{p}.toml"
    raise SweepError(f"{shown_path(path_or_name)}: "
                     f"{'is a folder, not a' if p.is_dir() else 'no such'} "
                     f"sweep file (a path, or a shipped one: {', '.join(shipped())})")


def read_sweep(path_or_name: str | os.PathLike[str]) -> SweepSpec:
    """Read and check a sweep file (a path, or the name of a shipped one).

    Raises
    ------
    SweepError
        One line: the file, the key (e.g. ``methods[2].preset``) and what is wrong.
    """
    path = resolve_path(path_or_name)
    try:
        with open(path, "rb") as fh:
            raw = fh.read(MAX_SWEEP_BYTES + 1)
        if len(raw) > MAX_SWEEP_BYTES:
            raise SweepError(f"{shown_path(path)}: larger than {MAX_SWEEP_BYTES // 2**20} MiB; "
                             f"not a sweep "
                             f"file")
        data = tomllib.loads(raw.decode("utf-8"))
    except tomllib.TOMLDecodeError as exc:  # of a byte-order mark: "Invalid statement"
        why = BOM_ADVICE if raw.startswith(b"\xef\xbb\xbf") else f"not valid TOML: {exc}"
        raise SweepError(f"{shown_path(path)}: {why}") from None
    except RecursionError:
        raise SweepError(f"{shown_path(path)}: not valid TOML: arrays or tables nested too "
                         f"deeply") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SweepError(f"{shown_path(path)}: cannot be read: {exc}") from None
    return _Reader(path).sweep(data)


def parse_method(token: str, where: str = "token") -> MethodSpec:
    """``"NAME"`` or ``"NAME@PRESET"`` as an arm labelled ``token``; a refusal names it as
    ``where`` (a sweep file's key, a command line's option; by default the parameter)."""
    name, _, preset = token.partition("@")
    if not name or (("@" in token) and not preset):
        raise SweepError(f"{where}: {token!r} is not NAME or NAME@PRESET")
    return checked_method(MethodSpec(token, name, {"preset": preset} if preset else {}), where)


def stream_header_problem(paths: Sequence[str]) -> str:
    """The reader's message for the first of ``paths`` whose header (its first line only)
    does not read as a stream's, "" when all do: a file that is not a stream is refused
    before anything runs; a fault further in is found by its run."""
    from .errors import StreamFormatError
    from .stream_file import StreamReader

    for p in paths:
        try:
            with StreamReader(p, warn=False):
                pass
        except StreamFormatError as exc:
            return str(exc)
    return ""


def named_streams(paths: list[str]) -> tuple[tuple[str, str], ...]:
    """Each path with its run label, unique: the file stem, or ``folder-stem`` when two files
    share a stem (``folder-stem-K``, K the path's place in ``paths``, when that is not
    enough; ``-K`` once more while another file's stem is that already: ``x-a-0.jsonl`` beside
    two ``a.jsonl`` in folders ``x`` and ``y`` made a second ``x-a-0``, and the experiment
    refused its two runs of one name)."""
    stems = [Path(p).stem for p in paths]
    times = Counter(stems)  # not list.count: quadratic in a glob of 100,000 files (h96)
    labels = [s if times[s] == 1 else f"{Path(p).parent.name}-{s}"
              for p, s in zip(paths, stems)]
    times = Counter(labels)
    kept = {lb for lb, n in times.items() if n == 1}

    def numbered(lb: str, k: int) -> str:
        # two numbered labels never match: what follows their last '-' is their own K
        while (lb := f"{lb}-{k}") in kept:
            pass
        return lb

    labels = [lb if times[lb] == 1 else numbered(lb, k) for k, lb in enumerate(labels)]
    return tuple(zip(paths, labels))


def unique_paths(paths: Sequence[str], seen: set[str] | None = None
                 ) -> tuple[list[str], list[str]]:
    """``paths`` each file once, as given: those whose resolved path (links and ``..``
    followed) is not in ``seen`` (updated) nor before them, and those dropped as the same
    file again (a sweep file's globs and ``compare --streams`` alike, h116). Only the same
    file through another spelling or link is dropped: a copy, or a hard link, is another run
    (its own label, the same bytes and cache key)."""
    seen = set() if seen is None else seen   # a membership test a file, not a scan (h96)
    kept, dropped = [], []
    for p in paths:
        full = str(Path(p).resolve())
        (dropped if full in seen else kept).append(p)
        seen.add(full)
    return kept, dropped


def check_unique(labels: Sequence[str], where: str) -> None:
    # not list.count: 460,000 worlds fit a sweep file's 16 MiB, hours of comparisons (h96)
    dup = sorted(x for x, n in Counter(labels).items() if n > 1)
    if dup:
        raise SweepError(f"{where}: {dup[0]!r} appears twice (give one a label)")


def checked_method(m: MethodSpec, where: str) -> MethodSpec:
    """Refuse an unknown method or preset (the preset against the method's config class)
    and options the method's configuration refuses."""
    from .mapper import check_method_options, method_config_class, method_info

    try:
        method_info(m.method)
        cls = method_config_class(m.method)
    except BomgraphError as exc:
        raise SweepError(f"{where}: {exc}") from None
    preset = m.options.get("preset")
    if preset is not None and not isinstance(preset, str):
        raise SweepError(f"{where}: preset must be a name, got {preset!r}")
    presets = getattr(cls, "PRESETS", None)
    if preset is not None and presets is not None and preset not in presets:
        raise SweepError(f"{where}: unknown preset {preset!r} of {m.method}; choose one of "
                         f"{', '.join(presets)}")
    try:  # every run would fail alike: refuse the sweep before it starts
        check_method_options(m.method, m.options)
    except ConfigError as exc:
        raise SweepError(f"{where}: options {echo(dict(m.options))}: {exc}") from None
    return m


def scheduler_address_problem(address: str) -> str:
    """Why ``address`` cannot be a Dask scheduler's address ("" when it can): Dask's own
    parser (``tcp://host:port``, ``host:port``, ``tls://``, ``inproc://``, ...), and a TCP or
    TLS port within 1-65535."""
    from distributed.comm.addressing import parse_address, parse_host_port
    from distributed.comm.registry import get_backend

    try:
        scheme, loc = parse_address(address)
        get_backend(scheme)  # http:// (a dashboard's) is none of Dask's
        if scheme in ("tcp", "tls"):
            _, port = parse_host_port(loc)
            if not 1 <= int(port) <= 65535:
                return f"port {port} is not in 1-65535; give e.g. tcp://HOST:8786"
    except (ValueError, TypeError, ImportError) as exc:
        return f"not a Dask scheduler address ({exc}); give e.g. tcp://HOST:8786"
    return ""


def _finite(v: int | float) -> bool:
    """Whether a TOML number is a finite float (an integer too large for a float is not)."""
    try:
        return math.isfinite(v)
    except OverflowError:
        return False


class _Reader:
    """Checks the parsed TOML, key by key, naming ``file: key`` in every error."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.runs = 0  # simulated runs of the worlds read so far
        self.tasks = 0  # runs x methods of the experiments read so far

    def count(self, attr: str, n: int, key: str) -> None:
        """Add ``n`` runs (or tasks) to the sweep's count, before they are made."""
        setattr(self, attr, getattr(self, attr) + n)
        if getattr(self, attr) > MAX_SWEEP_TASKS:
            what = "simulated runs" if attr == "runs" else "runs x methods"
            raise self.fail(key, f"the sweep's {what} would exceed {MAX_SWEEP_TASKS:,}; "
                                 f"split it into several sweep files")

    def fail(self, key: str, message: str) -> SweepError:
        return SweepError(f"{shown_path(self.path)}: {key}: {message}")

    def keys(self, table: Any, allowed: set[str], where: str) -> Mapping[str, Any]:
        if not isinstance(table, dict):
            raise self.fail(where, f"must be a table, got {type(table).__name__}")
        unknown = sorted(set(table) - allowed)
        if unknown:
            raise self.fail(f"{where}.{unknown[0]}" if where else unknown[0],
                            f"unknown key; allowed: {', '.join(sorted(allowed))}")
        return table

    def int_(self, value: Any, key: str, low: int) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise self.fail(key, f"must be an integer >= {low}, got {value!r}")
        return value

    def str_(self, value: Any, key: str) -> str:
        if not isinstance(value, str) or not value:
            raise self.fail(key, f"must be a non-empty string, got {value!r}")
        return value

    def sweep(self, data: Mapping[str, Any]) -> SweepSpec:
        top = self.keys(data, _TOP, "")
        executor = self.executor(top.get("executor", {}))
        defaults = {k: top[k] for k in ("checkpoint_every", "reference") if k in top}
        if "experiments" in top:
            own = sorted(set(top) & (_EXPERIMENT - {"checkpoint_every", "reference"}))
            if own:
                raise self.fail(own[0], "with [[experiments]], put it inside each experiment")
            tables = top["experiments"]
            if not isinstance(tables, list) or not tables:
                raise self.fail("experiments", "must be a non-empty array of tables")
            exps = [self.experiment({**defaults, **self.keys(t, _EXPERIMENT,
                                                             f"experiments[{k}]")},
                                    f"experiments[{k}].") for k, t in enumerate(tables)]
        else:
            exps = [self.experiment({k: v for k, v in top.items() if k in _EXPERIMENT}, "")]
        _unique_or(self, [e.name for e in exps], "experiments[].name")
        return SweepSpec(str(self.path), tuple(exps), executor)

    def executor(self, table: Any) -> dict[str, Any]:
        t = self.keys(table, _EXECUTOR, "executor")
        out: dict[str, Any] = {}
        if "jobs" in t:
            jobs = t["jobs"]
            if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs == 0 or jobs < -1:
                raise self.fail("executor.jobs", f"must be -1 (one per core) or >= 1, got "
                                                 f"{jobs!r}")
            out["jobs"] = jobs
        if "dask_local" in t:
            # >= 1, as --dask-local (h103: 0 ran local processes, one per core, silently)
            out["dask_local"] = self.int_(t["dask_local"], "executor.dask_local", 1)
        if "scheduler" in t:
            out["scheduler"] = self.str_(t["scheduler"], "executor.scheduler")
            problem = scheduler_address_problem(out["scheduler"])
            if problem:
                raise self.fail("executor.scheduler", problem)
        if "dask_local" in out and "scheduler" in out:   # as --dask-local N --scheduler A
            raise self.fail("executor", "give one of dask_local and scheduler, not both (a "
                                        "local cluster or an existing one)")
        return out

    def experiment(self, t: Mapping[str, Any], at: str) -> ExperimentSpec:
        name = t.get("name", self.path.stem)
        if not isinstance(name, str) or not _NAME.match(name):
            raise self.fail(f"{at}name", f"must be letters, digits and _.+- , got {name!r}")
        every = self.int_(t.get("checkpoint_every", 10), f"{at}checkpoint_every", 1)
        streams = self.streams(t.get("streams", []), f"{at}streams")
        worlds = t.get("worlds", [])
        if not isinstance(worlds, list):
            raise self.fail(f"{at}worlds", "must be an array of tables ([[worlds]])")
        worlds = [self.world(w, f"{at}worlds[{k}]", k) for k, w in enumerate(worlds)]
        if any(w.design is not None for w in worlds) and (len(worlds) > 1 or streams):
            raise self.fail(f"{at}worlds", "a world with a design must be the experiment's "
                                           "only source (put the others in another "
                                           "[[experiments]] table)")
        if not streams and not worlds:
            raise self.fail(f"{at}streams", "give streams or [[worlds]] to run the methods on")
        _unique_or(self, [w.name for w in worlds], f"{at}worlds[].name")
        runs = {f"{w.name}-seed{seed}": w.name for w in worlds for seed in w.seeds}
        for path, label in streams:
            if label in runs:
                raise self.fail(f"{at}worlds", f"world {runs[label]!r} has a run named "
                                               f"{label!r}, as is the stream {path}: their "
                                               f"estimates and table columns would collide; "
                                               f"rename the world")
        methods = t.get("methods")
        if not isinstance(methods, list) or not methods:
            raise self.fail(f"{at}methods", "give at least one method ([[methods]] with a "
                                            "name, or methods = [\"NAME@PRESET\", ...])")
        n_runs = len(streams) + sum(
            len(w.seeds) if w.design is None else w.design["layouts"] * w.design["starts"]
            for w in worlds)
        self.count("tasks", n_runs * (len(methods) + (t.get("reference") is not None)),
                   f"{at}methods")
        arms = tuple(self.method(m, f"{at}methods[{k}]") for k, m in enumerate(methods))
        _unique_or(self, [a.label for a in arms], f"{at}methods[].label")
        ref = t.get("reference")
        reference = None if ref is None else self.method(ref, f"{at}reference")
        title = t.get("title", f"{name}: {counted(len(streams), 'stream')}, "
                               f"{counted(sum(len(w.seeds) for w in worlds), 'simulated run')}")
        return ExperimentSpec(name, self.str_(title, f"{at}title"), arms, streams,
                              tuple(worlds), reference, every)

    def streams(self, patterns: Any, key: str) -> tuple[tuple[str, str], ...]:
        if isinstance(patterns, str):
            patterns = [patterns]
        if not isinstance(patterns, list):
            raise self.fail(key, "must be a list of file names or globs")
        paths: list[str] = []
        seen: set[str] = set()   # of resolved paths (unique_paths)
        for k, pat in enumerate(patterns):
            pat = self.str_(pat, f"{key}[{k}]")
            full = pat if os.path.isabs(pat) else str(self.path.parent / pat)
            try:
                found = bounded_glob(full)
            except GlobTooWideError as exc:
                raise self.fail(f"{key}[{k}]", f"{pat!r}: {exc}") from None
            found = [str(Path(f).resolve()) for f in found if os.path.isfile(f)]
            if not found:
                raise self.fail(f"{key}[{k}]", f"{pat!r} matches no file (relative to "
                                               f"{self.path.parent.resolve()})")
            paths += unique_paths(found, seen)[0]  # globs may overlap: dropped silently
        problem = stream_header_problem(paths)
        if problem:
            raise self.fail(key, problem)
        return named_streams(paths)

    def world(self, t: Any, key: str, index: int) -> WorldSpec:
        t = self.keys(t, set(_SIM_FIELDS) | _WORLD_EXTRA, key)
        values: dict[str, Any] = {}
        for k, v in t.items():
            if k in _WORLD_EXTRA:
                continue
            default = _SIM_FIELDS[k].default
            ok = (isinstance(v, int) if isinstance(default, int) else
                  isinstance(v, (int, float)) and _finite(v)) and not isinstance(v, bool)
            if not ok:
                raise self.fail(f"{key}.{k}", f"must be {'an integer' if isinstance(default, int) else 'a finite number'}, got {v!r:.40}")
            values[k] = float(v) if isinstance(default, float) else v
        try:
            sim = SimConfig(**values)
        except ConfigError as exc:
            raise self.fail(key, str(exc)) from None
        name = t.get("name", f"world{index + 1}")
        if not isinstance(name, str) or not _NAME.match(name):
            raise self.fail(f"{key}.name", f"must be letters, digits and _.+- , got {name!r}")
        sigma = t.get("prior_sigma_xy_m", 0.03)
        if isinstance(sigma, bool) or not isinstance(sigma, (int, float)) \
                or not 0 < sigma < math.inf:
            raise self.fail(f"{key}.prior_sigma_xy_m", f"must be a finite number > 0, got "
                                                       f"{sigma!r}")
        if "design" in t:
            if "seeds" in t:
                raise self.fail(f"{key}.seeds", "give seeds or a design, not both")
            d = self.keys(t["design"], {"seed", "layouts", "starts"}, f"{key}.design")
            design = {"seed": self.int_(d.get("seed", 0), f"{key}.design.seed", 0),
                      "layouts": self.int_(d.get("layouts", 5), f"{key}.design.layouts", 1),
                      "starts": self.int_(d.get("starts", 5), f"{key}.design.starts", 1)}
            if design["layouts"] * design["starts"] > MAX_WORLD_RUNS:
                raise self.fail(f"{key}.design", f"layouts x starts must be at most "
                                                 f"{MAX_WORLD_RUNS:,} runs, got "
                                                 f"{design['layouts'] * design['starts']:,}")
            self.count("runs", design["layouts"] * design["starts"], f"{key}.design")
            return WorldSpec(name, sim, (), design, float(sigma))
        seeds = t.get("seeds")
        if isinstance(seeds, int) and not isinstance(seeds, bool):
            seeds = self.int_(seeds, f"{key}.seeds", 1)
            if seeds > MAX_WORLD_RUNS:
                raise self.fail(f"{key}.seeds", f"at most {MAX_WORLD_RUNS:,} runs of one "
                                                f"world, got {seeds:,}")
            self.count("runs", seeds, f"{key}.seeds")
            seeds = list(range(seeds))
        if not isinstance(seeds, list) or not seeds:
            raise self.fail(f"{key}.seeds", "give the seeds: a list of integers, or a count")
        if len(seeds) > MAX_WORLD_RUNS:
            raise self.fail(f"{key}.seeds", f"at most {MAX_WORLD_RUNS:,} runs of one world, "
                                            f"got {len(seeds):,}")
        if not isinstance(t.get("seeds"), int):
            self.count("runs", len(seeds), f"{key}.seeds")
        seeds = [self.int_(s, f"{key}.seeds[{k}]", 0) for k, s in enumerate(seeds)]
        if len(set(seeds)) != len(seeds):
            raise self.fail(f"{key}.seeds", "a seed appears twice")
        return WorldSpec(name, sim, tuple(seeds), None, float(sigma))

    def method(self, t: Any, key: str) -> MethodSpec:
        if isinstance(t, str):
            return parse_method(t, f"{self.path}: {key}")
        t = self.keys(t, _METHOD, key)
        name = self.str_(t.get("name"), f"{key}.name")
        options = t.get("options", {})
        if not isinstance(options, dict):
            raise self.fail(f"{key}.options", "must be a table, e.g. options = { window = 40 }")
        options = dict(options)
        if "preset" in t:
            if "preset" in options:
                raise self.fail(f"{key}.preset", "given twice (here and in options)")
            options["preset"] = self.str_(t["preset"], f"{key}.preset")
        preset = options.get("preset")  # preset = "P" or options = { preset = "P" }
        label = t.get("label", f"{name}@{preset}" if isinstance(preset, str) else name)
        frac = t.get("prior_fraction", 0.0)
        if isinstance(frac, bool) or not isinstance(frac, (int, float)) or not 0 <= frac <= 1:
            raise self.fail(f"{key}.prior_fraction", f"must be in [0, 1], got {frac!r}")
        every = t.get("checkpoint_every")
        if every is not None:
            every = self.int_(every, f"{key}.checkpoint_every", 1)
        m = MethodSpec(self.str_(label, f"{key}.label"), name, options, float(frac), every)
        return checked_method(m, f"{self.path}: {key}")


def _unique_or(reader: _Reader, labels: Sequence[str], key: str) -> None:
    try:
        check_unique(labels, key)
    except SweepError as exc:
        raise SweepError(f"{shown_path(reader.path)}: {exc}") from None


__all__ = ["SweepError", "SweepSpec", "ExperimentSpec", "MethodSpec", "WorldSpec",
           "read_sweep", "parse_method", "checked_method", "named_streams", "check_unique",
           "unique_paths",
           "shipped", "resolve_path", "SHIPPED_DIR"]
