"""Where an experiment's runs come from (:mod:`bomgraph.experiments` re-exports all of it):
:class:`SimSource` (a run of the paper's design), :class:`WorldSource` and :class:`World`
(simulated worlds by seed), :class:`FileSource` (a stream file), :class:`DatasetSource` (a
recording imported on use), and :data:`SIMULATED`, this process's kept simulated streams.
Each source's ``key()`` is what the runner hashes into the cache key.
"""

from __future__ import annotations

import functools
from collections import OrderedDict
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .checks import file_name, fraction, instance, integer, items
from .errors import ConfigError, DatasetError, StreamFormatError, shown_path
from .file_digest import file_sha256, inputs_sha256, special_file
from .sim import RunSpec, SimConfig, make_priors, simulate, simulate_run, with_priors
from .stream import Stream


class SimulatedStreams:
    """The simulated streams of this process, kept for the next task of the same run: an
    experiment crosses every arm with the same runs, and each task used to simulate its run
    again (0.036 s of a paper run's 0.06-2 s; 500 times in the main job). A stream is a pure
    function of its source (seeded), so a kept one is the stream the task would simulate.

    Least recently used first out, at most ``max_steps`` steps in all (a paper stream of 301
    steps holds about 2 MB; the default keeps about 33 of them, more than the 25 runs of a
    design), so memory stays bounded whatever the sweep.
    """

    def __init__(self, max_steps: int = 10_000) -> None:
        self.max_steps = max_steps
        self._kept: OrderedDict[Any, Stream] = OrderedDict()
        self._steps = 0

    def get(self, key: Any, make: Callable[[], Stream]) -> Stream:
        """The stream of ``key`` (a hashable source), made by ``make()`` if not kept."""
        stream = self._kept.get(key)
        if stream is not None:
            self._kept.move_to_end(key)
            return stream
        stream = make()
        n = len(stream.steps)
        if n <= self.max_steps:
            while self._kept and self._steps + n > self.max_steps:
                _, old = self._kept.popitem(last=False)
                self._steps -= len(old.steps)
            self._kept[key] = stream
            self._steps += n
        return stream

    def clear(self) -> None:
        self._kept.clear()
        self._steps = 0


#: This process's kept simulated streams (:class:`SimulatedStreams`).
SIMULATED = SimulatedStreams()


@dataclass(frozen=True)
class SimSource:
    """A simulated run of a design (``prior_fraction`` > 0 adds Exp. 3 priors)."""

    spec: RunSpec
    sim: SimConfig = SimConfig()
    prior_fraction: float = 0.0
    prior_sigma_xy_m: float = 0.03

    def __post_init__(self) -> None:
        instance(self.spec, RunSpec, "SimSource: spec (paper_design(seed)[k])", ConfigError)
        instance(self.sim, SimConfig, "SimSource: sim", ConfigError)
        fraction(self.prior_fraction, "SimSource: prior_fraction", ConfigError)

    @property
    def name(self) -> str:
        return self.spec.name

    def stream(self) -> Stream:
        return SIMULATED.get(self, lambda: simulate_run(
            self.spec, self.sim, prior_fraction=self.prior_fraction,
            prior_sigma_xy_m=self.prior_sigma_xy_m))

    def key(self) -> dict[str, Any]:
        return {"spec": asdict(self.spec), "sim": asdict(self.sim),
                "prior_fraction": self.prior_fraction, "prior_sigma": self.prior_sigma_xy_m}


#: The kinds of recording a :class:`DatasetSource` imports.
DATASET_KINDS = ("mrclam", "g2o", "victoria")


@dataclass(frozen=True)
class DatasetSource:
    """A real recording, imported on use: ``kind`` is ``mrclam`` (``path`` the folder, with a
    ``robot``), ``g2o`` (``path`` the file, ``truth_path`` optional) or ``victoria``.

    Its cache key is the SHA-256 of the files the importer reads (:meth:`key`), so, as a
    stream file, a moved, renamed or copied recording reuses the cache and an edited one runs
    again; other files in its folder are not in it.
    """

    kind: str
    path: str
    robot: int | None = None
    truth_path: str | None = None
    label: str = ""

    def __post_init__(self) -> None:
        if self.kind not in DATASET_KINDS:
            raise ConfigError(f"DatasetSource: unknown dataset kind {self.kind!r}; use "
                              f"{', '.join(DATASET_KINDS)}")
        if self.kind == "mrclam" and self.robot is None:
            raise ConfigError("DatasetSource('mrclam'): robot: an MRCLAM source needs a robot "
                              "number (1-5)")
        if self.robot is not None:  # an int in the key (JSON): np.int64(1) is robot 1
            object.__setattr__(self, "robot", integer(
                self.robot, f"DatasetSource({self.kind!r}): robot", ConfigError, minimum=1))
        file_name(self.path, f"DatasetSource({self.kind!r}): path", ConfigError)
        if self.truth_path is not None:
            file_name(self.truth_path, f"DatasetSource({self.kind!r}): truth_path", ConfigError)

    @property
    def name(self) -> str:
        if self.label:
            return self.label
        base = Path(self.path).name
        return f"{base}-r{self.robot}" if self.robot is not None else base

    def inputs(self) -> dict[str, Path | None]:
        """Role -> each file the importer reads (MRCLAM: the robot's ``odometry``,
        ``measurements`` and ``groundtruth``, ``landmarks`` and ``barcodes``; g2o: ``edges``
        and ``truth``; Victoria: ``data``), None where there is none (the importer says why,
        or does without), as the importer declares them."""
        from . import datasets

        if self.kind == "mrclam":
            return datasets.mrclam_inputs(self.path, self.robot)
        if self.kind == "g2o":
            return datasets.g2o_inputs(self.path, self.truth_path)
        return datasets.victoria_inputs(self.path)

    def stream(self) -> Stream:
        """The imported recording (kept per process while its input files stay the same).

        Raises
        ------
        DatasetError
            As the importer does, and for an input that is a FIFO or a device (h113): its
            key holds what it is, not the bytes it gives, so a result read through it would
            be the cached result of other data later (and each run reads it again)."""
        inputs = self.inputs()
        for path in inputs.values():
            what = None if path is None else special_file(path)
            if what is not None:
                raise DatasetError(f"{shown_path(path)}: a {what}, not a regular file; a "
                                   f"recording's files "
                                   f"are hashed for the cache key and read by each run: copy "
                                   f"the data into a regular file")
        return _load_dataset(self.kind, self.path, self.robot, self.truth_path,
                             inputs_sha256(inputs))

    def key(self) -> dict[str, Any]:
        """The recording's kind and robot and the SHA-256 of the bytes of the files its
        importer reads (:meth:`inputs`, :func:`bomgraph.file_digest.inputs_sha256`), each
        named by its role, not its path: the same recording anywhere (copied, moved, renamed)
        has the same key; a file beside them (notes, a compare's ``--out`` folder) is not in
        it (h109: each changed the key); a file replaced by other bytes of the same size and
        modification time changes it (h104: a key of sizes and times reused the results of
        the old data)."""
        return {"kind": self.kind, "robot": self.robot, "sha256": inputs_sha256(self.inputs())}


@dataclass(frozen=True)
class FileSource:
    """A stream file (any recording or simulation written in the stream format).

    Its cache key is the SHA-256 of the file's bytes, so a moved or renamed copy reuses the
    cache and an edited file runs again. ``label`` names the run (default: the file stem).
    """

    path: str
    label: str = ""

    @property
    def name(self) -> str:
        return self.label or Path(self.path).stem

    def __post_init__(self) -> None:
        file_name(self.path, "FileSource: path", ConfigError)

    def stream(self) -> Stream:
        return _read_stream_file(str(Path(self.path).resolve()), _sha256(self.path))

    def key(self) -> dict[str, Any]:
        return {"kind": "file", "sha256": _sha256(self.path)}


def _sha256(path: str) -> str:
    """:func:`~bomgraph.file_digest.file_sha256` of a stream file, a StreamFormatError naming
    it when it cannot be read."""
    try:
        return file_sha256(path)
    except OSError as exc:
        raise StreamFormatError(f"cannot open: {exc.strerror}", path=str(path)) from None


@functools.lru_cache(maxsize=8)
def _read_stream_file(path: str, sha256: str) -> Stream:
    """The stream file, kept per process by its bytes' ``sha256`` too (as in the cache key):
    a changed file is read again."""
    from .stream_file import read_stream

    return read_stream(path)


@dataclass(frozen=True)
class WorldSource:
    """A simulated run of a world: ``simulate(sim, default_rng(seed))``, the stream
    ``bomgraph simulate --seed SEED`` writes for the same settings (priors drawn after it
    from the same generator when ``prior_fraction`` > 0)."""

    sim: SimConfig
    seed: int
    world: str = "world"
    prior_fraction: float = 0.0
    prior_sigma_xy_m: float = 0.03

    def __post_init__(self) -> None:
        instance(self.sim, SimConfig, "WorldSource: sim", ConfigError)
        integer(self.seed, f"WorldSource {self.world!r}: seed", ConfigError)
        fraction(self.prior_fraction, "WorldSource: prior_fraction", ConfigError)

    @property
    def name(self) -> str:
        return f"{self.world}-seed{self.seed}"

    def stream(self) -> Stream:
        return SIMULATED.get(self, self._simulate)

    def _simulate(self) -> Stream:
        rng = np.random.default_rng(self.seed)
        stream = simulate(self.sim, rng, meta={"seed": self.seed})
        if self.prior_fraction > 0:
            stream = with_priors(stream, make_priors(stream.truth, self.prior_fraction,
                                                     self.prior_sigma_xy_m, rng))
        return stream

    def key(self) -> dict[str, Any]:
        return {"kind": "world", "sim": asdict(self.sim), "seed": self.seed,
                "prior_fraction": self.prior_fraction, "prior_sigma": self.prior_sigma_xy_m}


@dataclass(frozen=True)
class World:
    """Simulated runs of one world: a :class:`~bomgraph.sim.SimConfig` and the seeds."""

    name: str
    sim: SimConfig
    seeds: tuple[int, ...]
    prior_sigma_xy_m: float = 0.03

    def __post_init__(self) -> None:
        where = f"World {self.name!r}"
        instance(self.sim, SimConfig, f"{where}: sim", ConfigError)
        seeds = items(self.seeds, (int, np.integer), f"{where}: seeds", ConfigError,
                      want="integer seeds >= 0")
        for k, seed in enumerate(seeds):
            integer(seed, f"{where}: seeds[{k}]", ConfigError)
        if not isinstance(self.seeds, (list, tuple)):  # an iterator is read once, here
            object.__setattr__(self, "seeds", seeds)

    def sources(self, prior_fraction: float = 0.0) -> list[WorldSource]:
        return [WorldSource(self.sim, s, self.name, prior_fraction, self.prior_sigma_xy_m)
                for s in self.seeds]


@functools.lru_cache(maxsize=16)
def _load_dataset(kind: str, path: str, robot: int | None, truth_path: str | None,
                  sha256: str) -> Stream:
    """The recording (``kind`` one of :data:`DATASET_KINDS`), kept per process by its input
    files' ``sha256`` too (as in the cache key): a changed file is read again."""
    from . import datasets

    if kind == "mrclam":
        return datasets.import_mrclam(path, robot)
    if kind == "g2o":
        return datasets.import_g2o(path, truth_path=truth_path)
    return datasets.import_victoria(path)


__all__ = ["SimulatedStreams", "SIMULATED", "SimSource", "DATASET_KINDS", "DatasetSource",
           "FileSource", "WorldSource", "World"]
