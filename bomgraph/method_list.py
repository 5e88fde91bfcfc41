"""What ``bomgraph methods`` shows: each registered method on a line (name, description, where
it comes from), its presets on a line each as field overrides (:func:`format_method_list`), and
the same as data for ``--json`` (:func:`method_listing`)."""

from __future__ import annotations

from typing import Any, Mapping, Sequence

from .errors import BomgraphError
from .mapper import MethodInfo, method_config_class, method_description, method_info


def preset_summary(overrides: Mapping[str, Any], width: int = 100) -> str:
    """A preset's field overrides on one line (cut at ``width`` characters)."""
    text = ", ".join(f"{k}={v!r}" for k, v in overrides.items()) or "the defaults"
    return text if len(text) <= width else text[:width - 3] + "..."


def method_listing(info: MethodInfo) -> dict[str, Any]:
    """What ``bomgraph methods`` shows of one method (name, description, origin, its
    distribution and version, presets as field overrides); a plugin that cannot be loaded is
    listed with the reason in its description, not raised."""
    row: dict[str, Any] = {"name": info.name, "needs_truth": info.needs_truth,
                           "origin": info.origin, "distribution": info.distribution,
                           "version": info.version, "presets": {}}
    try:
        row["needs_truth"] = method_info(info.name).needs_truth   # a plugin's factory says
        row["description"] = method_description(info.name)
        cls = method_config_class(info.name)
        row["presets"] = {k: dict(v) for k, v in getattr(cls, "PRESETS", {}).items()}
    except BomgraphError as exc:
        row["description"] = f"(cannot be loaded: {exc})"
    return row


def format_method_list(rows: Sequence[Mapping[str, Any]]) -> str:
    """:func:`method_listing` rows as the text of ``bomgraph methods``: a line per method
    (name, description, where it comes from), then a line per preset (``@NAME`` and its
    field overrides)."""
    lines = []
    # one column for every preset name (the longest, @real-seed-robust, is 17 characters)
    width = max([15] + [len(n) for r in rows for n in r["presets"]])
    for r in rows:
        flag = "  (benchmark only: reads the truth)" if r["needs_truth"] else ""
        if r["origin"] == "plugin":
            flag += f"  (plugin: {r['distribution'] or '?'} {r['version'] or ''})".rstrip()
        elif r["origin"] == "runtime":
            flag += "  (registered at run time: this process only)"
        lines.append(f"{r['name']:18s} {r['description']}{flag}")
        lines += [f"  @{name:{width}s} {preset_summary(o)}" for name, o in r["presets"].items()]
    return "\n".join(lines)


def no_presets_line(name: str) -> str:
    """What ``bomgraph methods NAME`` says of a method that declares no presets: whether
    ``NAME@PRESET`` is refused, passed on to a factory that takes any option, or is an option
    ``preset`` of the factory's (or of its configuration's) own."""
    import dataclasses

    from .config import describe_options
    from .mapper import check_method_options, factory_options

    cls = method_config_class(name)
    docs = describe_options(cls) if cls is not None and dataclasses.is_dataclass(cls) else []
    own = next((o for o in [*docs, *factory_options(name)] if o.name == "preset"), None)
    if own is not None:  # its values may refuse the word PRESET: lit@fast of Literal["fast"]
        return f"presets: none declared (NAME@PRESET gives its option preset: {own.type})"
    try:
        check_method_options(name, {"preset": "PRESET"})
    except BomgraphError:
        return "presets: none (NAME@PRESET is refused)"
    return "presets: none declared (NAME@PRESET is passed on to the factory as preset=PRESET)"


def takes_any_option(name: str) -> bool:
    """Whether the factory of ``name``, a method without a configuration class, takes
    ``**options`` (the README's ``Factory(header, **options)``): then it is handed any option,
    checked only when it runs."""
    import inspect

    from .mapper import method_config_class, method_factory

    if method_config_class(name) is not None:
        return False
    factory = method_factory(name)
    try:
        params = inspect.signature(factory.__init__ if inspect.isclass(factory)
                                   else factory).parameters.values()
    except (TypeError, ValueError):  # no signature to read (a builtin)
        return False
    return any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params)


def options_heading(name: str, config_name: str | None, n_options: int) -> str:
    """The line over ``bomgraph methods NAME``'s options. A method without a configuration
    class whose factory takes ``**options`` (:func:`takes_any_option`) is handed any option
    unchecked before it runs: said so, where the line said "options: none" of one that took
    any (h152)."""
    if config_name is not None:
        return f"options ({config_name}; --option KEY=VALUE):"
    if takes_any_option(name):
        if not n_options:
            return ("options: any (the factory takes **options: --option KEY=VALUE, "
                    "checked only when it runs)")
        return ("options (the factory's keyword parameters, and any other through its "
                "**options, checked only when it runs; --option KEY=VALUE):")
    if n_options:
        return "options (the factory's keyword parameters; --option KEY=VALUE):"
    return "options: none"


__all__ = ["preset_summary", "method_listing", "format_method_list", "no_presets_line",
           "options_heading", "takes_any_option"]
