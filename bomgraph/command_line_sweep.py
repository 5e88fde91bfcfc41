"""The command line's sweeps: ``bomgraph compare --streams FILE... --methods
NAME[@PRESET],... --option NAME:KEY=VALUE --reference NAME[@PRESET]`` as the sweep it
stands for (:func:`command_line_spec`, the same :class:`~bomgraph.sweep.SweepSpec` a sweep
file reads to, so both run the same tasks with the same cache keys), and ``bomgraph run
--method TOKEN --option KEY=VALUE`` as one arm (:func:`run_method`). Each method is checked
as a sweep file's is (:mod:`bomgraph.sweep`); a refusal names the command line's option
while a command runs, else the Python parameter (:func:`bomgraph.checks.option_named`).
"""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path
from typing import Any, Mapping, Sequence

from .checks import no_file, option_named
from .errors import ConfigError, shown_path
from .tables import counted
from .sweep import (ExperimentSpec, MethodSpec, SweepError, SweepSpec, check_unique,
                    checked_method, named_streams, parse_method, stream_header_problem,
                    unique_paths)

_log = logging.getLogger(__name__)


def run_method(token: str, options: Mapping[str, Any]) -> tuple[str, str, dict[str, Any]]:
    """``bomgraph run --method TOKEN --option KEY=VALUE...`` as (label, method, options):
    ``NAME@PRESET`` (as ``compare --methods`` takes it) is ``NAME`` with ``preset=PRESET``,
    and ``NAME`` with a ``preset`` option is labelled ``NAME@PRESET`` too, as ``evaluate``
    names either estimate.

    Raises
    ------
    ConfigError
        The preset is given twice, or ``TOKEN`` is not ``NAME`` or ``NAME@PRESET`` (or names
        an unknown method or preset). The message names ``--method`` and ``--option`` while a
        command runs, else the parameters ``token`` and ``options`` (h111).
    """
    options = dict(options)
    if "@" not in token:
        preset = options.get("preset")
        return (f"{token}@{preset}" if isinstance(preset, str) else token), token, options
    spec = parse_method(token, option_named("--method", "token"))
    if "preset" in options:
        given = option_named("--option preset=...", "options['preset']")
        raise ConfigError(f"{option_named('--method', 'token', token)} and {given}: give the "
                          f"preset once")
    return token, spec.method, {**spec.options, **options}


def command_line_spec(streams: Sequence[str], methods: Sequence[str],
                      options: Sequence[str] = (), *, reference: str | None = None,
                      checkpoint_every: int = 10, name: str = "streams") -> SweepSpec:
    """``compare --streams FILE... --methods NAME[@PRESET],... [--option NAME:KEY=VALUE]
    [--reference NAME[@PRESET]]`` as the sweep it stands for (one experiment)."""
    from .jsonio import parse_options

    # options while a command runs, the parameters from Python (compare_experiments; h107)
    st, ms, op = (option_named(f"--{o}", p) for o, p in (
        ("streams", "streams"), ("methods", "methods"), ("option", "options")))

    if not streams:
        raise SweepError(f"{st}: give at least one stream file")
    if not methods:
        raise SweepError(f"{ms}: give at least one method (NAME or NAME@PRESET, "
                         "comma-separated); `bomgraph methods` lists them")
    arms = [parse_method(tok, option_named("--methods", "methods", tok)) for tok in methods]
    ref = parse_method(reference, option_named("--reference", "reference")) if reference else None
    extra: dict[str, dict[str, Any]] = {}
    for text in options:
        target, sep, pair = text.partition(":")
        if not sep or "=" not in pair:
            raise SweepError(f"{op} {text}: an option is NAME:KEY=VALUE (NAME: a method "
                             f"of {ms})")
        if not any(target in (a.label, a.method) for a in [*arms, *([ref] if ref else [])]):
            raise SweepError(f"{op} {text}: {target!r} is not one of {ms} "
                             f"{','.join(methods)}")
        try:
            given = parse_options([pair])
        except ConfigError as exc:
            raise SweepError(f"{op} {text}: {exc}") from None
        key = next(iter(given))
        if key in extra.get(target, {}):
            raise SweepError(f"{op} {text}: {target}:{key} is given twice (one compare "
                             f"runs one value per method; to compare values, give the "
                             f"method once per value with a label of its own in a sweep "
                             f"file)")
        extra.setdefault(target, {}).update(given)

    def with_options(m: MethodSpec) -> MethodSpec:
        added: dict[str, Any] = {}
        by = m.method  # the --option target that gives the preset (the user's spelling)
        for target in (m.method, m.label):
            added.update(extra.get(target, {}))
            by = target if "preset" in extra.get(target, {}) else by
        if not added:
            return m
        label = m.label
        if "preset" in added:  # labelled as NAME@PRESET is, never by another preset
            if "preset" in m.options:
                raise SweepError(f"{op} {by}:preset=...: {ms} {m.label} names "
                                 f"its preset already; give the preset once")
            if isinstance(added["preset"], str):
                label = f"{m.label}@{added['preset']}"
        return checked_method(dataclasses.replace(m, label=label, options={
            **m.options, **added}), f"{op} {m.label}")

    missing = [s for s in streams if not Path(s).is_file()]
    if missing:
        raise SweepError(f"{st}: {no_file(missing[0])}")
    streams, again = unique_paths(streams)  # as a sweep file's globs: one run a file
    problem = stream_header_problem(streams)
    if problem:   # its one line, no warning before it (h119)
        raise SweepError(f"{st}: {problem}")
    if again:
        _log.warning("%s: %s %s the same file as one before; each file runs once (a copy "
                     "under another name runs as a stream of its own)", st,
                     ", ".join(map(shown_path, again)), "is" if len(again) == 1 else "are")
    arms = [with_options(a) for a in arms]
    check_unique([a.label for a in arms], ms)
    exp = ExperimentSpec(name, f"{counted(len(streams), 'stream')}, "
                               f"{counted(len(arms), 'method')}",
                         tuple(arms),
                         streams=named_streams([str(Path(s).resolve()) for s in streams]),
                         reference=None if ref is None else with_options(ref),
                         checkpoint_every=checkpoint_every)
    return SweepSpec("<command line>", (exp,))


__all__ = ["command_line_spec", "run_method"]
