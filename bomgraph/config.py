"""The one preset mechanism every method's configuration uses.

A method's configuration is a frozen dataclass that mixes in :class:`Presets` and names its
presets in one dict ``PRESETS`` of field overrides (``"paper"`` is always the defaults, which
reproduce the paper). :meth:`Presets.preset` builds a named preset with overrides, and
:func:`resolve` is how every method factory turns ``config=`` / ``preset=`` / options into a
configuration: a ready config alone, or a preset name plus options, never both.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import re
import types
import typing
from typing import Any, Callable, ClassVar, Mapping, NamedTuple, TypeVar

import numpy as np

from .checks import echo, echo_name
from .tables import plural
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
            raise ConfigError(f"{cls.__name__}: unknown {plural(len(unknown), 'option')} "
                              f"{', '.join(map(echo_name, unknown))}; "
                              f"valid options: {', '.join(sorted(fields))}")
        hints = typing.get_type_hints(cls)
        for key, value in overrides.items():
            problem = type_problem(hints.get(key), value)
            if problem:
                raise ConfigError(f"{cls.__name__}: bad option value {key}={echo(value)}: {problem}")
        values = {**cls.PRESETS[name], **overrides}
        try:
            return cls(**values)
        except TypeError as exc:  # a value of the wrong type deep in __post_init__
            raise ConfigError(f"{cls.__name__}: bad option value: {exc}") from None


#: The largest integer option (a C ``int``): iteration counts, windows and sizes are handed to
#: GTSAM's C++ as ``int``, which refuses anything larger with a ``TypeError``.
MAX_INT_OPTION = 2**31 - 1


def type_problem(annotation: Any, value: Any) -> str | None:
    """Why ``value`` does not fit the field type ``annotation`` (None when it does, or when the
    annotation is not one of the plain types checked: bool, int, float, str, tuples, unions)."""
    if annotation is None or annotation is Any:
        return None
    origin = typing.get_origin(annotation)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(annotation)
        if value is None and type(None) in args:
            return None
        problems = [type_problem(a, value) for a in args if a is not type(None)]
        return None if any(p is None for p in problems) else problems[0]
    if origin is typing.Literal:
        allowed = typing.get_args(annotation)
        return None if value in allowed else f"must be one of {', '.join(map(repr, allowed))}"
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            return "must be a list, e.g. [1, 2]"
        args = [a for a in typing.get_args(annotation) if a is not Ellipsis]
        for item in value:
            problem = type_problem(args[0] if args else None, item)
            if problem:
                return f"each item {problem}"
        return None
    if annotation is bool:
        return None if isinstance(value, (bool, np.bool_)) else "must be true or false"
    if annotation is int:
        ok = isinstance(value, numbers.Integral) and not isinstance(value, bool)
        if ok and abs(int(value)) > MAX_INT_OPTION:  # counts and sizes reach C++ (GTSAM) as int
            return f"must be an integer within +-{MAX_INT_OPTION:,} (a C int)"
        return None if ok else "must be an integer"
    if annotation is float:
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            return "must be a number"
        return "must be a number, not NaN" if math.isnan(value) else None
    if annotation is str:
        return None if isinstance(value, str) else "must be a string"
    return None


class OptionDoc(NamedTuple):
    """One option of a configuration: name, type, default and a one-line description."""

    name: str
    type: str
    default: Any
    doc: str


def type_name(annotation: Any) -> str:
    """A short readable name of a field type (``float``, ``int | None``, ``tuple[float, ...]``)."""
    if isinstance(annotation, type) and typing.get_origin(annotation) is None:
        return annotation.__name__
    return str(annotation).replace("typing.", "").replace("NoneType", "None")


def _attribute_docs(cls: type) -> dict[str, str]:
    """The first sentence of each entry of a numpydoc ``Attributes`` section; an entry naming
    several fields (``a, b : float``) gives its text to each."""
    text = (cls.__doc__ or "").expandtabs()
    match = re.search(r"^\s*Attributes\s*\n\s*-+\s*\n(.*)", text, re.S | re.M)
    informal = match is None
    if informal:  # an informal list of ``name : text`` entries: the text follows the colon
        match = re.search(r"^([ \t]*\w+(?:, \w+)* : .*)", text, re.S | re.M)
    if not match:
        return {}
    lines = match.group(1).splitlines()
    indent = min((len(ln) - len(ln.lstrip()) for ln in lines if ln.strip()), default=0)
    docs: dict[str, str] = {}
    names: list[str] = []
    body: list[str] = []

    def flush() -> None:
        sentence = _first_sentence(" ".join(body).strip())
        for n in names:
            docs[n] = sentence.rstrip(".")

    continued = False
    for ln in lines:
        if ln.strip() and len(ln) - len(ln.lstrip()) == indent:
            head = ln.split(" : ")[0] if " : " in ln else ln.strip().rstrip(":").strip()
            if not continued:
                flush()
                names, body = [], []
            names += [n.strip() for n in head.split(",") if n.strip()]
            continued = ln.rstrip().endswith(",")
            if informal and " : " in ln:
                body.append(ln.split(" : ", 1)[1].strip())
        elif ln.strip():
            body.append(ln.strip())
    flush()
    return docs


#: Abbreviations whose full stop does not end a sentence ("std. dev. (m) of ...").
_ABBREVIATIONS = re.compile(r"\b(?:std|dev|e\.g|i\.e|cf|approx|eq|eqs|fig|vs)\.$", re.I)


def _first_sentence(text: str) -> str:
    """``text`` up to its first full stop followed by a capital or ``(``, skipping the full
    stops of :data:`_ABBREVIATIONS`."""
    for m in re.finditer(r"(?<=\.)\s+(?=[A-Z(])", text):
        if not _ABBREVIATIONS.search(text[:m.start()]):
            return text[:m.start()]
    return text


def describe_options(config_cls: type) -> list[OptionDoc]:
    """Every option of a configuration dataclass, in field order: its type (from the
    annotation), default, and one line (``field(metadata={"doc": ...})``, or else the first
    sentence of its entry in the class docstring's ``Attributes`` section)."""
    hints = typing.get_type_hints(config_cls)
    docs: dict[str, str] = {}
    for klass in reversed(config_cls.__mro__):  # a subclass's entry wins over its base's
        docs.update(_attribute_docs(klass))
    out = []
    for f in dataclasses.fields(config_cls):
        default = (f.default if f.default is not dataclasses.MISSING else
                   f.default_factory() if f.default_factory is not dataclasses.MISSING
                   else None)
        doc = (f.metadata.get("doc") or docs.get(f.name, "")).replace("``", "`")
        out.append(OptionDoc(f.name, type_name(hints.get(f.name, f.type)), default, doc))
    return out


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
            given = (["preset"] if preset is not None else []) + sorted(options)
            raise ConfigError(f"give either config= or preset= and options, not both "
                              f"(got config= with {', '.join(given)})")
        if not isinstance(config, cls):
            raise ConfigError(f"config= must be a {cls.__name__}, got {type(config).__name__}")
        return config
    return cls.preset(preset or "paper", **options)


def check_plain_options(name: str, target: Callable[..., Any],
                         params: Mapping[str, Any], cls: type | None,
                         opts: Mapping[str, Any]) -> None:
    """:func:`bomgraph.mapper.check_method_options` for a method without presets: names against the
    factory's parameters and ``cls``'s fields, values against their annotations."""
    import inspect

    def hints_of(obj: Any) -> dict[str, Any]:
        try:
            return typing.get_type_hints(obj)
        except Exception:  # unresolvable annotations in a plugin: nothing to check against
            return {}

    hints = {k: v for k, v in hints_of(target).items() if k in params}
    known = {k for k in params if k not in ("self", "header", "truth")
             and params[k].kind not in (inspect.Parameter.VAR_KEYWORD,
                                        inspect.Parameter.VAR_POSITIONAL)}
    if cls is not None and dataclasses.is_dataclass(cls):
        fields = {f.name for f in dataclasses.fields(cls)}
        hints.update({k: v for k, v in hints_of(cls).items() if k in fields})
        known |= fields
    takes_any = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())
    for key, value in opts.items():
        if key not in known and not takes_any:
            what = ("it has no presets" if key == "preset" else
                    f"its options: {', '.join(sorted(known))}" if known else "it takes none")
            raise ConfigError(f"method {name!r}: unknown option {key!r} ({what})")
        problem = type_problem(hints.get(key), value)
        if problem:
            raise ConfigError(f"method {name!r}: bad option value {key}={value!r}: {problem}")


__all__ = ["Presets", "requirement", "resolve", "OptionDoc", "describe_options", "type_problem",
           "type_name", "check_plain_options"]
