"""The seed a method builds, checked before any run: a method's ``seed_method`` option (with
``seed_options``), as ``hybrid``'s and ``hybrid-isam2``'s, names the registered method its
mapper builds to start from. A plugin's own hybrid (an option or configuration field
``seed_method``) is checked as the built-in ones are, by
:func:`bomgraph.mapper.check_method_options`: the seed is a registered method, not a bound,
not a circle of seeds, and takes ``seed_options``. h137: a plugin's seed was checked by
nobody, so a typo failed every run of the sweep, one at a time, mid-sweep. Imports from
bomgraph only the errors and the registry (on use).
"""

from __future__ import annotations

import contextvars
import dataclasses
import inspect
from typing import Any, Mapping

from .errors import BomgraphError, ConfigError

#: Seeds (name, registered target) and options :func:`check_seed` accepted: a
#: ``dataclasses.replace`` of a hybrid's configuration (the warm solve makes one at every
#: checkpoint) does not check them again.
_SEEDS_CHECKED: set[tuple[str, str | None, str]] = set()

#: The methods (and options) whose seed is being checked: a seed that is one of them again,
#: with the same options, is a circle
_CHECKING: contextvars.ContextVar[tuple[tuple[str, str], ...]] = contextvars.ContextVar(
    "bomgraph_seed_checking", default=())

_ABSENT = object()


def check_seed(owner: str, seed_method: str, seed_options: Mapping[str, Any] | None) -> None:
    """Refuse a ``seed_method`` that is not a registered method or is a bound (it needs the
    truth), or ``seed_options`` its configuration refuses, where the hybrid's configuration is
    made: before any run of ``compare`` (:func:`bomgraph.mapper.check_method_options`), not at
    every run.

    Raises
    ------
    ConfigError
        Naming ``owner``'s option and what the seed method refused.
    """
    from .mapper import check_method_options, method_info

    options = dict(seed_options or {})
    try:
        info = method_info(seed_method)
    except BomgraphError:
        info = None                         # refused by check_method_options below
    if info is not None and info.needs_truth:   # the seed runs beside the hybrid, truthless
        raise ConfigError(f"{owner}: seed_method={seed_method!r} is a bound (it needs the "
                          f"truth, as oracle does), and a seed maps from the stream alone: "
                          f"choose a method that does (e.g. stmds-smacof)")
    target = None if info is None else info.target
    key = (seed_method, target, _canonical(options))
    if key in _SEEDS_CHECKED:
        return
    try:
        check_method_options(seed_method, options)
    except BomgraphError as exc:
        raise ConfigError(f"{owner}: seed_method={seed_method!r}, seed_options={options}: "
                          f"{exc}") from None
    _SEEDS_CHECKED.add(key)


def check_method_seed(name: str, options: Mapping[str, Any], config: Any = None) -> None:
    """:func:`check_seed` for the method ``name`` given ``options``, when it takes a
    ``seed_method``: the option, else ``config``'s field (a preset's, the configuration the
    options made), else the default of its configuration class's field or of its factory's
    parameter; ``seed_options`` likewise. A method without one: nothing.

    Raises
    ------
    ConfigError
        The seed is refused, ``seed_options`` is no mapping, or the seeds go round in a
        circle (a seed whose own seed, by its options or defaults, is the method again).
    """
    seed = _value(name, options, config, "seed_method")
    if not isinstance(seed, str):   # none, or a wrong type its own checks refuse
        return
    owner = f"method {name!r}"
    seed_options = _value(name, options, config, "seed_options")
    if seed_options is _ABSENT or seed_options is None:
        seed_options = None
    elif not isinstance(seed_options, Mapping):
        raise ConfigError(f"{owner}: seed_options must be a mapping (a JSON object) of the "
                          f"options of {seed!r}, got {seed_options!r:.60}")
    chain = (*_CHECKING.get(), (name, _canonical(dict(options))))
    if (seed, _canonical(dict(seed_options or {}))) in chain:  # the same method, options:
        path = " -> ".join([n for n, _ in chain] + [seed])     # built again and again
        raise ConfigError(f"{owner}: seed_method={seed!r} seeds itself ({path}): choose "
                          f"another seed method (e.g. stmds-smacof)")
    token = _CHECKING.set(chain)
    try:
        check_seed(owner, seed, seed_options)
    finally:
        _CHECKING.reset(token)


def _value(name: str, options: Mapping[str, Any], config: Any, key: str) -> Any:
    """``key`` of the method ``name``: in ``options``, ``config``, else its default."""
    if key in options:
        return options[key]
    if config is not None and dataclasses.is_dataclass(config):
        return getattr(config, key, _ABSENT)
    from .mapper import method_config_class, method_factory

    cls = method_config_class(name)
    if cls is not None and dataclasses.is_dataclass(cls):
        for f in dataclasses.fields(cls):
            if f.name == key:
                if f.default is not dataclasses.MISSING:
                    return f.default
                if f.default_factory is not dataclasses.MISSING:
                    return f.default_factory()
                return _ABSENT
    factory = method_factory(name)
    try:
        params = inspect.signature(factory.__init__ if inspect.isclass(factory) else factory
                                   ).parameters
    except (TypeError, ValueError):   # no signature to read (a builtin): nothing to check
        return _ABSENT
    param = params.get(key)
    if param is None or param.default is inspect.Parameter.empty:
        return _ABSENT
    return param.default


def _canonical(value: Any) -> str:
    """``value`` as a string that tells apart what the option checks tell apart (types, nan,
    tuples from lists), mappings in key order."""
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{k!r}: {_canonical(v)}" for k, v in sorted(
            value.items(), key=lambda kv: repr(kv[0]))) + "}"
    if isinstance(value, (list, tuple)):
        return type(value).__name__ + "(" + ", ".join(_canonical(v) for v in value) + ")"
    return f"{type(value).__name__}:{value!r}"


__all__ = ["check_seed", "check_method_seed"]
