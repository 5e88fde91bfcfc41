"""The one preset mechanism every method's configuration uses.

A method's configuration is a frozen dataclass that mixes in :class:`Presets` and names its
presets in one dict ``PRESETS`` of field overrides (``"paper"`` is always the defaults, which
reproduce the paper). :meth:`Presets.preset` builds a named preset with overrides, and
:func:`resolve` is how every method factory turns ``config=`` / ``preset=`` / options into a
configuration: a ready config alone, or a preset name plus options, never both.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, ClassVar, Mapping, TypeVar

from .errors import ConfigError

C = TypeVar("C", bound="Presets")


class Presets:
    """Mixin for frozen configuration dataclasses with named presets."""

    #: preset name -> field overrides; ``"paper"`` (the defaults) is always present.
    PRESETS: ClassVar[Mapping[str, Mapping[str, Any]]] = {"paper": {}}

    @classmethod
    def preset_names(cls) -> tuple[str, ...]:
        return tuple(cls.PRESETS)

    @classmethod
    def preset(cls: type[C], name: str = "paper", **overrides: Any) -> C:
        """The preset ``name`` with ``overrides`` applied (unknown names are refused)."""
        if name not in cls.PRESETS:
            raise ConfigError(f"unknown {cls.__name__} preset {name!r}; choose one of "
                              f"{', '.join(cls.PRESETS)}")
        fields = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
        unknown = sorted(set(overrides) - fields)
        if unknown:
            raise ConfigError(f"{cls.__name__}: unknown option(s) {', '.join(unknown)}; "
                              f"valid options: {', '.join(sorted(fields))}")
        values = {**cls.PRESETS[name], **overrides}
        try:
            return cls(**values)
        except TypeError as exc:  # a value of the wrong type deep in __post_init__
            raise ConfigError(f"{cls.__name__}: bad option value: {exc}") from None


def requirement(owner: str) -> Callable[[bool, str], None]:
    """The ``need(ok, message)`` check of a config's ``__post_init__``: it raises
    ``ConfigError("<owner>: <message>")`` when ``ok`` is false."""

    def need(ok: bool, message: str) -> None:
        if not ok:
            raise ConfigError(f"{owner}: {message}")

    return need


def resolve(cls: type[C], config: C | None = None, preset: str | None = None,
            options: Mapping[str, Any] | None = None) -> C:
    """The configuration a method factory runs with.

    ``config`` (an instance of ``cls``) is taken as it is and refuses any ``preset`` or
    option beside it; otherwise ``cls.preset(preset or "paper", **options)``.
    """
    options = dict(options or {})
    if config is not None:
        if preset is not None or options:
            raise ConfigError(f"give either config= or preset= and options, not both "
                              f"(got config= with {['preset'] if preset else []}"
                              f"{sorted(options)})")
        if not isinstance(config, cls):
            raise ConfigError(f"config= must be a {cls.__name__}, got {type(config).__name__}")
        return config
    return cls.preset(preset or "paper", **options)


__all__ = ["Presets", "requirement", "resolve"]
