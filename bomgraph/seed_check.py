"""What a method's seed is, for :func:`bomgraph.mapper.check_seed` before any run: a method's
``seed_method`` (with ``seed_options``), as ``hybrid``'s and ``hybrid-isam2``'s, names the
registered method its mapper builds to start from. A plugin's own hybrid (an option,
configuration field or factory parameter ``seed_method``) is checked as the built-in ones are
(h137: nobody checked a plugin's seed, so a typo failed every run, one at a time,
mid-sweep). Imports from bomgraph only an error.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import inspect
from typing import Any, Callable, Iterator, Mapping

from .errors import ConfigError

#: Seeds (name, registered target, :func:`canonical` options) that
#: :func:`bomgraph.mapper.check_seed` accepted: a ``dataclasses.replace`` of a hybrid's
#: configuration (the warm solve makes one at every checkpoint) does not check them again.
accepted: set[tuple[str, str | None, str]] = set()

#: The methods (and options) whose seed is being checked: a seed that is one of them again,
#: with the same options, is a circle
_CHECKING: contextvars.ContextVar[tuple[tuple[str, str], ...]] = contextvars.ContextVar(
    "bomgraph_seed_checking", default=())

_ABSENT = object()


def seed_of(name: str, options: Mapping[str, Any], config: Any, cls: type | None,
            factory: Callable[..., Any]) -> tuple[str | None, Mapping[str, Any] | None]:
    """The seed method and options of the method ``name`` (configuration class ``cls``,
    factory ``factory``) given ``options``: each the option, else ``config``'s field (the
    configuration the options made, a preset's), else the default of ``cls``'s field or of
    the factory's parameter. ``(None, None)`` for a method without a ``seed_method``, or one
    that is not a string (its own checks refuse that).

    Raises
    ------
    ConfigError
        ``seed_options`` is not a mapping.
    """
    seed = _value(options, config, cls, factory, "seed_method")
    if not isinstance(seed, str):
        return None, None
    seed_options = _value(options, config, cls, factory, "seed_options")
    if seed_options is _ABSENT or seed_options is None:
        return seed, None
    if not isinstance(seed_options, Mapping):
        raise ConfigError(f"method {name!r}: seed_options must be a mapping (a JSON object) "
                          f"of the options of {seed!r}, got {seed_options!r:.60}")
    return seed, seed_options


@contextlib.contextmanager
def seeding(name: str, options: Mapping[str, Any], seed: str,
            seed_options: Mapping[str, Any] | None) -> Iterator[None]:
    """Check the seed ``seed`` of ``name`` in the block, refusing a circle first: a seed whose
    seed, in turn, is a method being checked with the same options (by its options or its
    defaults), which the mapper would build again and again.

    Raises
    ------
    ConfigError
        The circle, naming its methods.
    """
    chain = (*_CHECKING.get(), (name, canonical(dict(options))))
    if (seed, canonical(dict(seed_options or {}))) in chain:
        path = " -> ".join([n for n, _ in chain] + [seed])
        raise ConfigError(f"method {name!r}: seed_method={seed!r} seeds itself ({path}): "
                          f"choose another seed method (e.g. stmds-smacof)")
    token = _CHECKING.set(chain)
    try:
        yield
    finally:
        _CHECKING.reset(token)


def _value(options: Mapping[str, Any], config: Any, cls: type | None,
           factory: Callable[..., Any], key: str) -> Any:
    if key in options:
        return options[key]
    if config is not None and dataclasses.is_dataclass(config):
        return getattr(config, key, _ABSENT)
    if cls is not None and dataclasses.is_dataclass(cls):
        for f in dataclasses.fields(cls):
            if f.name == key:
                if f.default is not dataclasses.MISSING:
                    return f.default
                if f.default_factory is not dataclasses.MISSING:
                    return f.default_factory()
                return _ABSENT
    try:
        params = inspect.signature(factory.__init__ if inspect.isclass(factory) else factory
                                   ).parameters
    except (TypeError, ValueError):   # no signature to read: nothing to check
        return _ABSENT
    param = params.get(key)
    if param is None or param.default is inspect.Parameter.empty:
        return _ABSENT
    return param.default


def canonical(value: Any) -> str:
    """``value`` as a string that tells apart what the option checks tell apart (types, nan,
    tuples from lists), mappings in key order."""
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{k!r}: {canonical(v)}" for k, v in sorted(
            value.items(), key=lambda kv: repr(kv[0]))) + "}"
    if isinstance(value, (list, tuple)):
        return type(value).__name__ + "(" + ", ".join(canonical(v) for v in value) + ")"
    return f"{type(value).__name__}:{value!r}"


__all__ = ["accepted", "canonical", "seed_of", "seeding"]
