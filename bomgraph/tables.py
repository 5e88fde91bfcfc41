"""One table, five formats: ``text``, ``json``, ``csv``, ``markdown``, ``latex``.

A table is a list of columns (name, header, scale, format) and rows of dicts. JSON and CSV
carry the raw values in SI units under the column names (NaN: null / empty); text, Markdown
and LaTeX show the scaled values under the headers, NaN as ``-``.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import re
from dataclasses import dataclass
from decimal import Decimal
from typing import Any, Callable, Mapping, Sequence

from .stdio import output_file

FORMATS = ("text", "json", "csv", "markdown", "latex")


@dataclass(frozen=True)
class Column:
    """``name``: the key in each row; ``header``: shown in human formats (with its unit);
    ``scale`` multiplies the value for display; ``fmt`` formats it (e.g. ``".2f"``)."""

    name: str
    header: str
    scale: float = 1.0
    fmt: str = ".4g"


def _shown(v: Any, col: Column) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    if isinstance(v, bool) or isinstance(v, str):
        return str(v)
    if isinstance(v, int) and col.scale == 1.0:
        return str(v)
    return fixed_or_exponent(float(v), col.fmt, col.scale)


#: the magnitude from which a fixed-point column shows its value in exponent form.
HUGE = 1e9


def fixed_or_exponent(value: float, fmt: str, scale: float = 1.0, huge: float = HUGE) -> str:
    """``value * scale`` formatted as ``fmt``, except a fixed-point ``fmt`` (``".2f"``) of a
    magnitude of :data:`HUGE` or more, shown in exponent form (``"6.976e+301"``: a 1e300 m map
    is not 300 digits of cm), the product taken exactly (a finite 1e307 m is 1e309 cm, beyond
    a float, not ``inf``), and a value that is not finite, shown ``"-"`` as a table's cell
    shows it (``format`` said ``"Infinity"`` for ``inf`` and ``".2f"``). ``huge``: the
    magnitude from which a fixed-point value is shown in exponent form (a narrower column's
    own)."""
    if not math.isfinite(value):
        return "-"
    x = value * scale
    fixed = fmt.endswith("f")
    if math.isfinite(x) and not (fixed and abs(x) >= huge):
        return format(x, fmt)
    if math.isfinite(x):
        return format(x, ".3e")
    return format(Decimal(value) * Decimal(scale), ".3e" if fixed else fmt)


def plural(n: int, noun: str) -> str:
    """``noun`` with an ``s`` unless ``n`` is 1 (for a count printed apart, in a column)."""
    return f"{noun}{'s' * (n != 1)}"


def counted(n: int, noun: str) -> str:
    """``n`` and ``noun``, with an ``s`` unless ``n`` is 1: ``"1 landmark"``, ``"2 poses"``
    (a summary said "1 landmarks", h154)."""
    return f"{n} {plural(n, noun)}"


#: LaTeX's ten special characters and what prints each as itself (a method name or file name
#: in a caption may hold any of them).
_LATEX_SPECIAL = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#",
                  "_": r"\_", "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}",
                  "^": r"\textasciicircum{}"}
_LATEX_RE = re.compile("|".join(re.escape(c) for c in _LATEX_SPECIAL))


def _latex_escape(s: str) -> str:
    """``s`` with each of LaTeX's special characters replaced in one pass (replacing them one
    after another escaped the braces of ``\\textbackslash{}`` again)."""
    return _LATEX_RE.sub(lambda m: _LATEX_SPECIAL[m.group()], s)


def _markdown_escape(s: str) -> str:
    """``s`` with the characters that Markdown may read as markup backslash-escaped, so a
    method or file name in a title or a cell shows as written (``*x*`` was shown as italics
    and ended the title's bold early; a ``|`` in a cell split it in two)."""
    return re.sub(r"([\\`*_{}\[\]<>|#])", r"\\\1", s)


def _json_value(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def format_table(columns: Sequence[Column], rows: Sequence[Mapping[str, Any]], fmt: str, *,
                 meta: Mapping[str, Any] | None = None, title: str = "") -> str:
    """``rows`` as ``fmt``. ``meta`` (JSON only) is merged into the top-level object, next to
    ``"rows"``; ``title`` heads the text and Markdown tables and captions the LaTeX one."""
    if fmt not in FORMATS:
        raise ValueError(f"format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    if fmt == "json":
        obj = {k: _json_value(v) for k, v in (meta or {}).items()}
        obj["rows"] = [{c.name: _json_value(r.get(c.name)) for c in columns} for r in rows]
        return json.dumps(obj, allow_nan=False)
    if fmt == "csv":
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow([c.name for c in columns])
        for r in rows:
            w.writerow(["" if _json_value(r.get(c.name)) is None else r.get(c.name)
                        for c in columns])
        return buf.getvalue().rstrip("\n")
    cells = [[_shown(r.get(c.name), c) for c in columns] for r in rows]
    heads = [c.header for c in columns]
    if fmt == "markdown":
        lines = ([f"**{_markdown_escape(title)}**", ""] if title else []) + [
            "| " + " | ".join(_markdown_escape(h) for h in heads) + " |",
            "|" + "---|" * len(heads)]
        lines += ["| " + " | ".join(_markdown_escape(c) for c in row) + " |" for row in cells]
        return "\n".join(lines)
    if fmt == "latex":
        lines = [r"\begin{table}[t]", r"\centering"]
        if title:
            lines.append(rf"\caption{{{_latex_escape(title)}}}")
        lines += [r"\begin{tabular}{" + "l" + "r" * (len(heads) - 1) + "}", r"\hline",
                  " & ".join(_latex_escape(h) for h in heads) + r" \\", r"\hline"]
        lines += [" & ".join(_latex_escape(c) for c in row) + r" \\" for row in cells]
        lines += [r"\hline", r"\end{tabular}", r"\end{table}"]
        return "\n".join(lines)
    width = [max(len(h), *(len(row[k]) for row in cells)) for k, h in enumerate(heads)]
    lines = [title] if title else []
    lines.append("  ".join(h.rjust(w) for h, w in zip(heads, width)))
    lines += ["  ".join(c.rjust(w) for c, w in zip(row, width)) for row in cells]
    return "\n".join(lines)


def write_csv(path: str | os.PathLike[str], rows: Sequence[Mapping[str, Any]],
              columns: Sequence[str] | None = None,
              ready: Callable[[str], None] | None = None) -> None:
    """``rows`` as a CSV file: ``columns`` (default: every key, in order of appearance; keys
    outside ``columns`` are left out); list values joined with ``;``. ``ready``: as
    :func:`bomgraph.stdio.output_file`'s."""
    cols: list[str] = list(columns or ())
    if columns is None:
        for r in rows:
            for k in r:
                if k not in cols:
                    cols.append(k)
    with output_file(path, ready=ready) as fh:  # atomically: a reader never sees half a table
        w = csv.DictWriter(fh, fieldnames=cols, extrasaction="ignore", lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: (";".join(map(str, v)) if isinstance(v, list) else v)
                        for k, v in r.items()})


__all__ = ["FORMATS", "Column", "counted", "format_table", "write_csv"]
