"""Strict JSON helpers shared by the stream, the estimate file, the cache and the CLI.

- :func:`jsonable`: the one sanitiser that turns numpy values, tuples and non-finite floats
  into plain JSON values (non-finite floats become ``null``: strict JSON has no NaN).
- :func:`parse_option_value` / :func:`parse_options`: the one parser of ``key=value`` method
  options (from ``--option`` and from scripts). Values are JSON where they parse as JSON;
  ``inf``, ``+inf``, ``-inf``, ``Infinity`` and ``-Infinity`` are infinities; anything else is
  a string. NaN is refused: no option means "not a number".
"""

from __future__ import annotations

import json
import math
from typing import Any, Mapping, Sequence

import numpy as np

from .errors import ConfigError

_INFINITIES = {"inf": math.inf, "+inf": math.inf, "infinity": math.inf, "+infinity": math.inf,
               "-inf": -math.inf, "-infinity": -math.inf}


def jsonable(value: Any, *, max_items: int | None = None) -> Any:
    """``value`` as plain JSON data.

    Numpy scalars become Python numbers, arrays/tuples/lists become lists, mappings become
    dicts with string keys, non-finite floats become ``None``. A sequence longer than
    ``max_items`` (when given) and any other object become ``None``.
    """
    if value is None or isinstance(value, str):
        return value
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return v if math.isfinite(v) else None
    if isinstance(value, Mapping):
        return {str(k): jsonable(v, max_items=max_items) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        if max_items is not None and len(value) > max_items:
            return None
        return [jsonable(v, max_items=max_items) for v in value]
    return None


def parse_option_value(text: str) -> Any:
    """One option value from text: JSON if it parses, an infinity, or else the string."""
    low = text.strip().lower()
    if low in _INFINITIES:
        return _INFINITIES[low]
    if low in ("nan", "+nan", "-nan"):
        raise ConfigError(f"option value {text!r}: NaN is not a valid option value")
    try:
        return json.loads(text, parse_constant=_refuse_constant)
    except json.JSONDecodeError:
        return text


def _refuse_constant(name: str) -> float:
    if name == "NaN":
        raise ConfigError("NaN is not a valid option value")
    return math.inf if name == "Infinity" else -math.inf


def parse_options(pairs: Sequence[str]) -> dict[str, Any]:
    """``["key=value", ...]`` as a dict, values by :func:`parse_option_value`."""
    out: dict[str, Any] = {}
    for p in pairs:
        if "=" not in p:
            raise ConfigError(f"an option is key=value, got {p!r}")
        k, v = p.split("=", 1)
        if not k:
            raise ConfigError(f"an option needs a name before '=', got {p!r}")
        out[k] = parse_option_value(v)
    return out


__all__ = ["jsonable", "parse_option_value", "parse_options"]
