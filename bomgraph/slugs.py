"""The file and folder names ``bomgraph compare`` makes from experiment, arm and run names
(moved from :mod:`bomgraph.out_folder`, h103): each name's :func:`slug`, made unique where
two names' slugs coincide, or differ in case only (one file on a case-insensitive disk)."""

from __future__ import annotations

import hashlib
import re
from collections import Counter
from typing import Any, Hashable, Mapping, Sequence


def slug(name: str) -> str:
    """``name`` as a file or folder name: letters, digits, ``.``, ``-``, ``_``, ``@``, the
    rest ``_``; never ``.`` or ``..`` (a folder ``estimates/EXP/..`` is ``estimates``, and
    through a link on the way the folder above the one it leads to: h82)."""
    name = re.sub(r"[^A-Za-z0-9._@-]+", "_", name).strip("_")
    return name if name not in ("", ".", "..") else "_"


def _unique(stems: Mapping[Hashable, str], ident: Any) -> dict[Any, str]:
    """Each stem, with the short hash of ``ident(key)`` appended where stems coincide (case
    apart); counted once (h103: ``list.count`` for each name was quadratic)."""
    folded = Counter(v.casefold() for v in stems.values())
    return {k: (f"{v}-{hashlib.sha256(ident(k).encode()).hexdigest()[:8]}"
                if folded[v.casefold()] > 1 else v) for k, v in stems.items()}


def unique_slugs(names: Sequence[str]) -> dict[str, str]:
    """Each name's :func:`slug`; names whose slugs coincide, or differ in case only (``tri
    (x)`` and ``tri_x``, ``EKF`` and ``ekf``), get their own short hash appended, so no two
    share a file."""
    return _unique({n: slug(n) for n in dict.fromkeys(names)}, str)


def figure_names(experiments: Sequence[Any]) -> dict[Any, str]:
    """The names of compare's figures: ``EXP_error_vs_time.png`` for each experiment's name,
    and ``EXP_RUN_maps.png`` for each (experiment's name, recorded source's name). Unique:
    runs ``run 1`` and ``run_1`` drew into one file before (h103), the first overwritten."""
    exps = unique_slugs([e.name for e in experiments])
    out: dict[Any, str] = {e: f"{s}_error_vs_time.png" for e, s in exps.items()}
    maps = _unique({(e.name, s.name): f"{slug(e.name)}_{slug(s.name)}"
                    for e in experiments for s in e.sources}, "\0".join)
    return {**out, **{k: f"{v}_maps.png" for k, v in maps.items()}}


__all__ = ["figure_names", "slug", "unique_slugs"]
