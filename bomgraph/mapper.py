"""The Mapper protocol, the MapEstimate it returns, the runner, and the registry of methods.

Every method (BOM-STMDS, the baselines) is a Mapper: built from a
:class:`~bomgraph.stream.StreamHeader` (never the truth), fed one :class:`~bomgraph.stream.Step`
at a time, asked for a :class:`MapEstimate` at checkpoints (the paper: every 10 steps).
:func:`run` drives a mapper over a stream and records estimates and wall times. Methods are
found by name through a registry of ``"module:attribute"`` strings imported only on use, so
``bomgraph`` names the ``baselines`` methods without importing them.
"""

from __future__ import annotations

import dataclasses
import inspect
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Mapping, Protocol, runtime_checkable

import numpy as np

from .checks import is_integer
from .errors import BomgraphError, ConfigError, MethodProtocolError, UnknownMethodError
from .map_estimate import MapEstimate
from .stream import Step, StreamHeader, Truth


@runtime_checkable
class Mapper(Protocol):
    """A bearing-only mapper. Construct it with the header (and options), then feed steps.

    ``step`` is called once per step in order ``t = 0, 1, 2, ...``; ``estimate`` may be called
    at any time and returns the current map (possibly empty), never raising for lack of data.

    A mapper may also have a ``finish()`` method (not part of the protocol): :func:`run`
    calls it once after the last step, before the final estimate, so the method can spend on
    its final map what it does not spend on every checkpoint (the LM mappers solve the whole
    graph once after windowed solves on a long recording). No step follows it. It takes no
    arguments; a ``finish`` that needs some is refused before the first step.
    """

    def step(self, step: Step) -> None: ...

    def estimate(self) -> MapEstimate: ...


# --------------------------------------------------------------------------------------------
# Running
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Checkpoint:
    """The estimate after step ``t`` and the wall time ``estimate()`` took (at the final
    checkpoint, with the mapper's ``finish()`` before it)."""

    t: int
    estimate: MapEstimate
    estimate_s: float


@dataclass(frozen=True, eq=False)
class RunResult:
    """The outcome of :func:`run`.

    Attributes
    ----------
    method : str
    checkpoints : tuple of Checkpoint
        In increasing ``t``; the last one is taken after the final step.
    step_s : ndarray of shape (T,)
        Wall time of each ``mapper.step`` call.
    total_s : float
        Wall time of the whole run (steps and estimates).
    """

    method: str
    checkpoints: tuple[Checkpoint, ...]
    step_s: np.ndarray
    total_s: float

    @property
    def final(self) -> MapEstimate:
        if not self.checkpoints:
            raise ConfigError(f"RunResult {self.method!r} has no checkpoint, so no final map")
        return self.checkpoints[-1].estimate

    def at(self, t: int) -> MapEstimate:
        """The estimate at checkpoint ``t`` (KeyError-free: a ConfigError names the choices)."""
        for c in self.checkpoints:
            if c.t == t:
                return c.estimate
        raise ConfigError(f"no checkpoint at t = {t}; checkpoints are "
                          f"{[c.t for c in self.checkpoints]}")

    def timing(self) -> dict[str, float]:
        est = np.array([c.estimate_s for c in self.checkpoints])
        return {"total": float(self.total_s), "steps": float(self.step_s.sum()),
                "step_median": float(np.median(self.step_s)) if self.step_s.size else 0.0,
                "estimates": float(est.sum()),
                "estimate_median": float(np.median(est)) if est.size else 0.0}


def checkpoint_times(n_steps: int, every: int) -> list[int]:
    """Steps after which the map is estimated: ``every, 2*every, ...`` and the last step."""
    if not (is_integer(every) and every >= 1):
        raise ConfigError(f"checkpoint_every must be an integer >= 1, got {every!r:.40}")
    last = n_steps - 1
    ts = list(range(every, last + 1, every))
    if not ts or ts[-1] != last:
        ts.append(last)
    return ts


_END = object()

#: How :func:`run` marks an exception raised inside a method (its ``step``, ``finish`` or
#: ``estimate``): a note ``"raised in Name.step() at t = 5"`` (``BaseException.add_note``), the
#: exception itself unchanged; :func:`method_failure_note` reads it back.
_NOTE_PREFIX = "raised in "


def _note_method_failure(exc: BaseException, mapper: Any, call: str, t: int) -> None:
    if method_failure_note(exc) is None:
        exc.add_note(f"{_NOTE_PREFIX}{type(mapper).__name__}.{call} at t = {t}")


def method_failure_note(exc: BaseException) -> str | None:
    """Where inside a method :func:`run` saw ``exc`` raised (``"raised in Name.step() at t =
    5"``), or None if it was not raised by a method's own code."""
    for note in getattr(exc, "__notes__", ()):
        if isinstance(note, str) and note.startswith(_NOTE_PREFIX):
            return note
    return None


def _estimate_at(mapper: Mapper, t: int, finish: Callable[[], None] | None,
                 checkpoints: list[Checkpoint],
                 on_checkpoint: Callable[[Checkpoint], None] | None, keep: bool) -> None:
    """Take the checkpoint after step ``t``: ``finish()`` first if given (the last step), its
    time counted in the estimate's."""
    t0 = time.perf_counter()
    call = "finish()"
    try:
        if finish is not None:
            finish()
        call = "estimate()"
        est = mapper.estimate()
    except Exception as exc:
        _note_method_failure(exc, mapper, call, t)
        raise
    if not isinstance(est, MapEstimate):
        raise MethodProtocolError(
            f"{type(mapper).__name__}.estimate() returned {type(est).__name__} after step {t}; "
            f"a Mapper's estimate() must return a bomgraph.mapper.MapEstimate(landmark_ids "
            f"(n,), landmarks_xy (n, 2), ...) (MapEstimate.empty() when it has no map yet)")
    c = Checkpoint(t, est, time.perf_counter() - t0)
    if on_checkpoint is not None:
        on_checkpoint(c)
    if not keep:
        checkpoints.clear()
    checkpoints.append(c)


def _finish_hook(mapper: Mapper) -> Callable[[], Any] | None:
    """The mapper's ``finish`` if it has one (:class:`Mapper`), checked to take no arguments."""
    finish = getattr(mapper, "finish", None)
    if not callable(finish):
        return None
    try:
        signature = inspect.signature(finish)
    except (TypeError, ValueError):   # no signature to read (a builtin): called as it is
        return finish
    try:
        signature.bind()
    except TypeError:
        raise ConfigError(
            f"{type(mapper).__name__}.finish({', '.join(signature.parameters)}) takes "
            f"arguments, but run() calls finish() with none, once after the last step (the "
            f"Mapper's end-of-stream hook); give it defaults or rename the method") from None
    return finish


def _check_run_arguments(mapper: Any, steps: Any, checkpoint_every: Any, method: Any,
                         on_checkpoint: Any) -> None:
    """Refuse, before the first step, arguments :func:`run` cannot use (naming them)."""
    if isinstance(mapper, type) or not (callable(getattr(mapper, "step", None))
                                        and callable(getattr(mapper, "estimate", None))):
        what = (f"the class {mapper.__name__} (build it first)" if isinstance(mapper, type)
                else f"a {type(mapper).__name__}")
        raise MethodProtocolError(f"run(): mapper is {what}, not a Mapper: it needs step(step) "
                                  f"and estimate() methods (create_mapper(name, header) "
                                  f"builds one)")
    if not (is_integer(checkpoint_every) and checkpoint_every >= 1):
        raise ConfigError(f"checkpoint_every must be an integer >= 1, got "
                          f"{checkpoint_every!r:.40}")
    if method is not None and not isinstance(method, str):
        raise ConfigError(f"run(): method must be the method's name (a str) or None, got "
                          f"{type(method).__name__} {method!r:.40}")
    if on_checkpoint is not None and not callable(on_checkpoint):
        raise ConfigError(f"run(): on_checkpoint must be callable or None, got "
                          f"{type(on_checkpoint).__name__}")
    if isinstance(steps, (Step, str, bytes)) or not isinstance(steps, Iterable):
        hint = (" (pass stream.steps)" if hasattr(steps, "steps") else
                " (pass [step])" if isinstance(steps, Step) else "")
        raise ConfigError(f"run(): steps must be an iterable of Step, got "
                          f"{type(steps).__name__}{hint}")


def _step_problem(st: Any, expected_t: int) -> ConfigError:
    """Why ``st`` cannot be the step ``expected_t`` of a run."""
    if not isinstance(st, Step):
        return ConfigError(f"run(): step {expected_t} is a {type(st).__name__}, not a "
                           f"bomgraph.stream.Step")
    if st.t != expected_t:
        return ConfigError(f"run(): steps must come in order t = 0, 1, 2, ...; expected "
                           f"t = {expected_t}, got t = {st.t} (a mapper cannot skip or "
                           f"replay steps; start a new mapper for another stream)")
    return ConfigError(f"run(): step {st.t}: odom must be None at t = 0 and given after")


def run(mapper: Mapper, steps: Iterable[Step], *, checkpoint_every: int = 10,
        method: str | None = None,
        on_checkpoint: Callable[[Checkpoint], None] | None = None,
        keep_checkpoints: bool = True) -> RunResult:
    """Feed ``steps`` to ``mapper``; estimate the map every ``checkpoint_every`` steps and last.

    The steps are read one ahead, so the last one is known as such: after it the mapper's
    ``finish()`` (if it has one, :class:`Mapper`) runs before the final estimate, its time
    counted in that checkpoint's ``estimate_s``.

    Parameters
    ----------
    mapper : Mapper
    steps : iterable of Step
        May be a lazy :class:`~bomgraph.stream_file.StreamReader`.
    checkpoint_every : int
        The paper maps every 10 steps (t = 10, 20, ...); the final step is always a checkpoint.
    method : str, optional
        Name recorded in the result (defaults to the mapper's class name).
    on_checkpoint : callable, optional
        Called with each :class:`Checkpoint` as soon as it is taken (e.g. to write it out).
    keep_checkpoints : bool
        False keeps only the latest checkpoint in the result (memory bounded by one map;
        pair it with ``on_checkpoint``). The estimates are the same either way.
    """
    _check_run_arguments(mapper, steps, checkpoint_every, method, on_checkpoint)
    clock = time.perf_counter
    start = clock()
    step_s: list[float] = []
    checkpoints: list[Checkpoint] = []
    finish = _finish_hook(mapper)
    it = iter(steps)
    nxt = next(it, _END)
    if nxt is _END:
        raise ConfigError("run(): the stream has no steps")
    expected_t = 0
    while nxt is not _END:
        st = nxt
        if not isinstance(st, Step) or st.t != expected_t or (st.odom is None) != (st.t == 0):
            raise _step_problem(st, expected_t)
        expected_t += 1
        t0 = clock()
        try:
            mapper.step(st)
        except Exception as exc:
            _note_method_failure(exc, mapper, "step()", st.t)
            raise
        step_s.append(clock() - t0)
        due = st.t > 0 and st.t % checkpoint_every == 0
        try:     # one step ahead: the last step is known as such before its estimate
            nxt = next(it, _END)
        except Exception:
            if due:   # the checkpoint of a step read before a bad one is not lost
                _estimate_at(mapper, st.t, None, checkpoints, on_checkpoint, keep_checkpoints)
            raise
        if nxt is _END:
            _estimate_at(mapper, st.t, finish, checkpoints, on_checkpoint, keep_checkpoints)
        elif due:
            _estimate_at(mapper, st.t, None, checkpoints, on_checkpoint, keep_checkpoints)
    return RunResult(method or type(mapper).__name__, tuple(checkpoints),
                     np.array(step_s), clock() - start)


# --------------------------------------------------------------------------------------------
# Registry
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class MethodInfo:
    """A registered method: its name, where its factory lives, and what it is.

    ``origin`` is ``"builtin"`` (bomgraph's and baselines' methods), ``"plugin"`` (an entry
    point of the group ``bomgraph.methods`` of an installed distribution, named with its
    version: :mod:`bomgraph.plugins`) or ``"runtime"`` (:func:`register_method` in the running
    process: worker processes cannot see it).
    """

    name: str
    target: str
    description: str
    needs_truth: bool = False
    origin: str = "runtime"
    distribution: str | None = None
    version: str | None = None


_REGISTRY: dict[str, MethodInfo] = {}


def register_method(name: str, target: str, description: str = "", *,
                    needs_truth: bool = False, replace: bool = False,
                    _origin: str = "runtime") -> None:
    """Register ``"package.module:Factory"`` under ``name``; the module is imported on use.

    The factory is called as ``Factory(header, **options)`` (and ``truth=`` when
    ``needs_truth`` or, as for a plugin, the factory says ``needs_truth = True``) and must
    return a :class:`Mapper`; without a ``description`` the factory's ``description``
    attribute, else its docstring's first line, is shown. A method registered this way exists
    in this process only: serial runs use it, worker processes (a local pool, Dask) do not
    see it and :func:`bomgraph.bench.execute` refuses it there; declare it as an entry point
    of the group ``bomgraph.methods`` instead (:mod:`bomgraph.plugins`).

    A name already taken (a built-in method, an installed plugin, an earlier registration
    with another target or ``needs_truth``) is refused unless ``replace`` is True; the same
    target again (a notebook cell run twice, its description edited) is registered anew.
    """
    from .plugins import warn_name

    if not (isinstance(name, str) and name.strip()):
        raise ConfigError(f"register_method: name must be a non-empty string, got {name!r}")
    warn_name(name, "register_method")
    if not isinstance(target, str) or ":" not in target:
        raise ConfigError(f"method target must be 'module:attribute', got {target!r}")
    info = MethodInfo(name, target, description, needs_truth, _origin)
    if not replace and _origin == "runtime":
        taken = _REGISTRY.get(name) or _plugin_infos().get(name)
        if taken is not None and (taken.origin, taken.target, taken.needs_truth) != (
                "runtime", target, needs_truth):
            what = (f"{taken.target}, needs_truth={taken.needs_truth}"
                    if (taken.origin, taken.target) == ("runtime", target) else taken.target)
            raise ConfigError(f"register_method: {name!r} is taken ({taken.origin} method "
                              f"{what}); choose another name, or pass replace=True to "
                              f"replace it in this process")
    _REGISTRY[name] = info


for _name, _target, _desc, _truth in [
    ("triangulate", "baselines.triangulate:TriangulateMapper",
     "dead reckoning + least-squares ray intersection (the naive baseline)", False),
    ("stmds-cs", "bomgraph.stmds.mapper:make_stmds_cs",
     "BOM-STMDS Method 1: DMC-SPL + classical scaling", False),
    ("stmds-smacof", "bomgraph.stmds.mapper:make_stmds_smacof",
     "BOM-STMDS Method 2: classical scaling to t=40, weighted SMACOF from t=50", False),
    ("stmds-cs-loc", "bomgraph.stmds.mapper:make_stmds_cs_loc",
     "BOM-STMDS Method 1 with robot localisation (last p positions)", False),
    ("stmds-smacof-loc", "bomgraph.stmds.mapper:make_stmds_smacof_loc",
     "BOM-STMDS Method 2 with robot localisation (last p positions)", False),
    ("ekf", "baselines.ekf.mappers:EkfMapper",
     "bearing-only EKF-SLAM (filterpy), delayed constrained initialisation", False),
    ("ekf-invdepth", "baselines.ekf.mappers:InverseDepthEkfMapper",
     "bearing-only EKF-SLAM (filterpy), undelayed inverse-depth initialisation", False),
    ("gtsam-batch", "baselines.factor_graph:BatchMapper",
     "GTSAM bearing factor graph, Levenberg-Marquardt every 10 steps (its own schedule)", False),
    ("gtsam-isam2", "baselines.isam2:Isam2Mapper",
     "GTSAM bearing factor graph, incremental iSAM2", False),
    ("hybrid", "baselines.hybrid:HybridMapper",
     "GTSAM seeded with the BOM-STMDS map (alignment + resection)", False),
    ("hybrid-isam2", "baselines.hybrid_isam2:HybridIsam2Mapper",
     "incremental iSAM2 whose new landmarks enter at their BOM-STMDS positions", False),
    ("oracle", "baselines.factor_graph:OracleMapper",
     "LM started from the ground truth: the accuracy bound (MLE)", True),
]:
    register_method(_name, _target, _desc, needs_truth=_truth, _origin="builtin")


def _plugin_infos() -> dict[str, MethodInfo]:
    """The installed plugins not shadowed by a registered method of the same name."""
    from . import plugins

    return {e.name: MethodInfo(e.name, e.target, "", False, "plugin", e.distribution, e.version)
            for e in plugins.discover().values() if e.name not in _REGISTRY}


def available_methods() -> list[MethodInfo]:
    """Every registered method in registration order, then the installed plugins."""
    return list(_REGISTRY.values()) + list(_plugin_infos().values())


def method_info(name: str) -> MethodInfo:
    """The method called ``name``: a registered one, else an installed plugin (a plugin's or
    a :func:`register_method` one's is a bound, given ``truth=`` as ``oracle``, if its
    factory has ``needs_truth = True``)."""
    found = _REGISTRY.get(name) or _plugin_infos().get(name)
    if found is None:
        known = ", ".join(m.name for m in available_methods())
        raise UnknownMethodError(f"unknown method {name!r}; known methods: {known} (your own "
                                 f"method: install a package declaring it in the entry-point "
                                 f"group 'bomgraph.methods')")
    if found.origin == "builtin" or found.needs_truth:
        return found
    from .plugins import load

    try:  # one that cannot be loaded says so where it is run
        bound = getattr(load(found.target, name), "needs_truth", False) is True
    except BomgraphError:
        return found
    return dataclasses.replace(found, needs_truth=True) if bound else found


def method_factory(name: str) -> Callable[..., Mapper]:
    """Import and return the factory registered under ``name``."""
    from .plugins import load

    info = method_info(name)  # a built-in's code is keyed whole (code_fingerprint): no record
    return load(info.target, name, record=info.origin != "builtin")  # type: ignore[return-value]


def method_description(name: str) -> str:
    """What the method is: its registered description, else (a plugin) its factory's
    ``description`` attribute or the first line of its docstring."""
    info = method_info(name)
    if info.description:
        return info.description
    factory = method_factory(name)
    text = getattr(factory, "description", None) or (factory.__doc__ or "").strip()
    return text.splitlines()[0] if text else "(no description)"


def method_config_class(name: str) -> type | None:
    """The configuration dataclass of the method registered under ``name``: the ``config``
    parameter's annotation of its factory, or the factory's ``config_class`` attribute
    (None for a plugin that declares neither)."""
    import inspect
    import typing

    factory = method_factory(name)
    declared = getattr(factory, "config_class", None)
    if declared is not None:
        return declared
    try:
        hint = typing.get_type_hints(factory.__init__ if inspect.isclass(factory)
                                     else factory).get("config")
    except Exception:  # unresolvable annotations in a plugin: no options to show
        return None
    for cand in (hint, *typing.get_args(hint)):
        if isinstance(cand, type) and dataclasses.is_dataclass(cand):
            return cand
    return None


def check_method_options(name: str, options: Mapping[str, Any]) -> None:
    """Refuse, before any run, the options of ``name`` that its configuration class refuses
    (an unknown name, a wrong type, a value out of range), as the factory would at every run.

    Options that are parameters of the factory itself are checked as the factories check
    them (:func:`~bomgraph.method_limits.check_factory_options`: ``start_pose``, a mapper such as ``seed_mapper``);
    checks that need the stream's header are left to the factory. A method whose configuration has no presets (a plugin with a plain dataclass as
    ``config_class``, or none) has its option names checked against the factory's parameters
    and the dataclass's fields, and their values against the type annotations (bool, int,
    float, str, tuples, unions, literals), so a typo or ``NAME@PRESET`` of a plugin without
    presets is refused in one line instead of failing every run.

    Raises
    ------
    ConfigError
        Also for a ``seed_method`` (a plugin's too) that :func:`check_seed` refuses.
    """
    import inspect

    from .config import Presets, check_plain_options
    from .method_limits import check_factory_options

    cls = method_config_class(name)
    opts = dict(options)
    factory = method_factory(name)
    target = factory.__init__ if inspect.isclass(factory) else factory
    params = inspect.signature(target).parameters
    check_factory_options(name, target, params, opts, Mapper)
    if "config" in opts:
        return _check_method_seed(name, options, opts["config"])
    own = {k for k, p in params.items() if p.kind is not inspect.Parameter.VAR_KEYWORD}
    config = None
    if cls is not None and issubclass(cls, Presets):
        preset = opts.pop("preset", None)
        config = cls.preset(preset or "paper", **{k: v for k, v in opts.items() if k not in own})
    else:
        check_plain_options(name, target, params, cls, opts)
    _check_method_seed(name, options, config)


def _check_method_seed(name: str, opts: Mapping[str, Any], config: Any) -> None:
    """:func:`check_seed` for the ``seed_method`` of ``name`` (a plugin's too, h137: a wrong
    one failed every run mid-sweep), a circle of seeds refused (:mod:`bomgraph.seed_check`):
    ``opts`` whole, ``preset`` too (h142: without it, presets seeding each other recursed)."""
    from .seed_check import seed_of, seeding

    seed, seed_options = seed_of(name, opts, config, method_config_class(name),
                                 method_factory(name))
    if seed is not None:
        with seeding(name, opts, seed, seed_options):
            check_seed(f"method {name!r}", seed, seed_options)


def check_seed(owner: str, seed_method: str, seed_options: Mapping[str, Any] | None) -> None:
    """Refuse, as :class:`ConfigError` naming ``owner``, a seed (a hybrid's ``seed_method``,
    built beside it) that is not a registered method or is a bound (it needs the truth), or
    ``seed_options`` its configuration refuses: before any run (:func:`check_method_options`)."""
    from .seed_check import accepted, canonical

    options = dict(seed_options or {})
    try:
        info = method_info(seed_method)
    except BomgraphError:
        info = None                         # refused by check_method_options below
    if info is not None and info.needs_truth:   # the seed runs beside the hybrid, truthless
        raise ConfigError(f"{owner}: seed_method={seed_method!r} is a bound (it needs the "
                          f"truth, as oracle does), and a seed maps from the stream alone: "
                          f"choose a method that does (e.g. stmds-smacof)")
    key = (seed_method, None if info is None else info.target, canonical(options))
    if key in accepted:  # a dataclasses.replace of a hybrid's config: checked already
        return
    try:
        check_method_options(seed_method, options)
    except BomgraphError as exc:
        raise ConfigError(f"{owner}: seed_method={seed_method!r}, seed_options={options}: "
                          f"{exc}") from None
    accepted.add(key)


def factory_options(name: str) -> list[Any]:
    """The keyword parameters of the factory of ``name`` (a method without a configuration
    class, e.g. ``def __init__(self, header, *, depth_m: float = 1.0)``), as
    :class:`bomgraph.config.OptionDoc` with their annotations and defaults."""
    import inspect
    import typing

    from .config import OptionDoc, type_name

    factory = method_factory(name)
    target = factory.__init__ if inspect.isclass(factory) else factory
    try:
        hints = typing.get_type_hints(target)
    except Exception:  # unresolvable annotations in a plugin: names and defaults only
        hints = {}
    return [OptionDoc(k, type_name(hints[k]) if k in hints else "",
                      None if p.default is inspect.Parameter.empty else p.default, "")
            for k, p in inspect.signature(target).parameters.items()
            if k not in ("self", "header", "truth")
            and p.kind in (inspect.Parameter.KEYWORD_ONLY,
                           inspect.Parameter.POSITIONAL_OR_KEYWORD)]


def create_mapper(name: str, header: StreamHeader, *, truth: Truth | None = None,
                  **options: Any) -> Mapper:
    """Build the mapper registered under ``name`` for a stream with ``header``.

    ``truth`` is passed only to methods that declare ``needs_truth`` (the oracle bound), and
    such a method refuses to run without it.
    """
    info = method_info(name)
    if not isinstance(header, StreamHeader):
        raise ConfigError(f"create_mapper({name!r}): header must be a StreamHeader (stream."
                          f"header), got {type(header).__name__}")
    if truth is not None and not isinstance(truth, Truth):
        raise ConfigError(f"create_mapper({name!r}): truth must be a Truth (stream.truth) or "
                          f"None, got {type(truth).__name__}")
    if info.needs_truth and truth is None:
        raise ConfigError(f"method {name!r} reads the ground truth (a benchmark bound): give "
                          f"it as create_mapper({name!r}, stream.header, truth=stream.truth) "
                          f"(a stream without truth cannot run it)")
    if info.origin != "builtin":  # a plugin's own options: refused here in one line
        check_method_options(name, options)
    factory = method_factory(name)
    try:
        if info.needs_truth:
            mapper = factory(header, truth=truth, **options)
        else:
            mapper = factory(header, **options)
    except TypeError as exc:  # an unknown option name or an option of the wrong type
        try:
            inspect.signature(factory).bind(header, **(
                {"truth": truth} if info.needs_truth else {}), **options)
        except (TypeError, ValueError):  # the call itself does not fit: the options are wrong
            raise ConfigError(f"method {name!r}: bad options {sorted(options)}: {exc}") from None
        raise MethodProtocolError(
            f"method {name!r}: its factory {info.target} raised TypeError while building it "
            f"with options {sorted(options)}: {exc} (the options fit its signature, so look in "
            f"the factory)") from exc
    if isinstance(mapper, type) or not (callable(getattr(mapper, "step", None))
                                        and callable(getattr(mapper, "estimate", None))):
        raise MethodProtocolError(f"method {name!r}: its factory {info.target} returned "
                                  f"{type(mapper).__name__}, not a Mapper (an object with "
                                  f"step(step) and estimate() methods)")
    return mapper


__all__ = ["MapEstimate", "Mapper", "Checkpoint", "RunResult", "run", "checkpoint_times",
           "MethodInfo", "register_method", "available_methods", "method_info", "method_factory",
           "method_description", "method_config_class", "check_method_options", "check_seed",
           "factory_options", "create_mapper"]
