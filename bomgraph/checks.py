"""Checks of the objects a user hands the library (ids, point arrays, numbers).

The library's data classes and entry points (:class:`~bomgraph.stream.Step`,
:class:`~bomgraph.stream.Truth`, :class:`~bomgraph.mapper.MapEstimate`, :func:`run`,
:func:`score_estimate`, ...) validate what enters them with these, so a wrong shape or type
is refused where it enters, naming the argument, instead of failing deep inside or, worse,
being reshaped into a wrong answer. Each check is O(size) numpy (a step's is on the hot path).
"""

from __future__ import annotations

import contextlib
import contextvars
import json
import math
import numbers
import os
from collections.abc import Iterable, Mapping
from typing import Any, Callable, Iterator

import numpy as np

from .errors import shown_path

#: An error class taking one message (a :class:`~bomgraph.errors.BomgraphError` subclass).
Raise = Callable[[str], Exception]

_INT64_MAX = float(np.iinfo(np.int64).max)


#: whether refusals name the command line's options (while a command runs,
#: :func:`command_line`) or the library's parameters (h101: ``report.compare(...,
#: out_dir="x")`` from Python said "--out x: is a file", an option it was never given)
_ON_COMMAND_LINE: contextvars.ContextVar[bool] = contextvars.ContextVar(
    "bomgraph_on_command_line", default=False)


@contextlib.contextmanager
def command_line() -> Iterator[None]:
    """Refusals name the command line's options in the block (:func:`bomgraph.cli.main`'s)."""
    token = _ON_COMMAND_LINE.set(True)
    try:
        yield
    finally:
        _ON_COMMAND_LINE.reset(token)


def option_named(option: str, param: str, value: Any = None) -> str:
    """An input as a refusal names it: the command line's ``option`` (``--out PATH``) while a
    command runs, else the library's parameter ``param`` (``out_dir='PATH'``); without
    ``value``, the name alone."""
    if _ON_COMMAND_LINE.get():   # a file name (or another value) shown as every message shows
        return option if value is None else (  # one (errors.shown_path)
            f"{option} {shown_path(value) if os.fspath(value) else repr('')}")
    return param if value is None else f"{param}={os.fspath(value)!r}"


def out_named(param: str, path: str | os.PathLike[str] | None = None) -> str:
    """The output ``path`` as a refusal names it: ``--out PATH``, or ``param='PATH'``."""
    return option_named("--out", param, path)


#: the most characters of a value a message repeats (h96: a 100,000-character --option
#: value was echoed whole, twice, in one error line)
MAX_ECHO_CHARS = 80


def clip(text: str) -> str:
    """``text`` for a message: its first :data:`MAX_ECHO_CHARS` characters, then ``...`` if
    there were more."""
    return text if len(text) <= MAX_ECHO_CHARS else text[:MAX_ECHO_CHARS] + "..."


def echo(value: Any) -> str:
    """``repr(value)`` for a message, clipped (:func:`clip`). A string is cut, not its
    ``repr``: one of up to :data:`MAX_ECHO_CHARS` characters is echoed whole with both quotes
    (h97: an 80-character value lost its last character, a 79-character one its closing
    quote to a ``...`` that said it was cut), and an escape (``\\x00``) is never cut in half."""
    if not isinstance(value, str):
        return clip(repr(value))
    if len(value) <= MAX_ECHO_CHARS:
        return repr(value)
    return repr(str(value[:MAX_ECHO_CHARS]))[:-1] + "..."   # no closing quote: it goes on


def echo_name(name: str) -> str:
    """A name the user wrote (an option key) for a message: as written, clipped, or its
    :func:`echo` when it holds a newline or another unprintable character (h97: an unknown
    option ``a<newline>b`` split the one-line error in two)."""
    return clip(name) if name.isprintable() else echo(name)


def is_integer(v: Any) -> bool:
    """A Python or numpy integer (``True``/``False`` are not)."""
    return isinstance(v, (numbers.Integral, np.integer)) and not isinstance(v, (bool, np.bool_))


def id_array(value: Any, name: str, error: Raise) -> np.ndarray:
    """``value`` as a new 1-D int64 array, refusing what is not integral.

    Integer arrays and lists pass as they are; floats must be integral and fit int64 (a
    ``1.5`` would be truncated to ``1`` by a plain cast); booleans, strings, None and NaN are
    refused. Returns a copy (the caller may freeze it).
    """
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError) as exc:  # ragged nested lists
        raise error(f"{name} must be a sequence of integers ({exc})") from None
    if raw.dtype.kind in "iu":
        if raw.dtype.kind == "u" and raw.size and raw.max() > _INT64_MAX:
            raise error(f"{name} must fit int64 (got {int(raw.max())})")
        return np.array(raw, dtype=np.int64).reshape(-1)
    if raw.size == 0 and raw.dtype.kind in "fO":  # [] or an empty float array
        return np.zeros(0, dtype=np.int64)
    if raw.dtype.kind != "f":
        got = "None" if value is None else f"{raw.dtype} values"
        raise error(f"{name} must be integers, got {got}")
    if not (np.all(np.isfinite(raw)) and np.all(raw == np.round(raw))
            and np.all(np.abs(raw) <= _INT64_MAX)):
        bad = raw[~(np.isfinite(raw) & (raw == np.round(raw)))]
        raise error(f"{name} must be integers, got {bad[0] if bad.size else raw.max()!r} "
                    f"(ids are never rounded)")
    return np.array(raw, dtype=np.int64).reshape(-1)


def row_array(value: Any, width: int, name: str, error: Raise, *,
              tail: tuple[int, ...] = (), copy: bool = True) -> np.ndarray:
    """``value`` as a new float array of shape ``(n, width)`` (or ``(n, *tail)``), refusing
    any other shape rather than reshaping it: a ``(2, n)`` array is not read as ``(n, 2)``.

    An empty value (``[]``, ``np.zeros(0)``) gives ``n = 0``. Non-numeric values are refused.
    ``copy=False`` returns a float input itself (for a read-only use).
    """
    shape = tail or (width,)
    want = f"(n, {', '.join(map(str, shape))})"
    try:
        raw = np.asarray(value)
        if raw.dtype.kind not in "iuf" and not (raw.size == 0 and raw.dtype.kind == "O"):
            raise TypeError(f"{raw.dtype} values" if value is not None else "None")
        out = np.array(raw, dtype=float) if copy else np.asarray(raw, dtype=float)
    except (TypeError, ValueError) as exc:
        raise error(f"{name} must be numbers of shape {want}, got {exc}") from None
    if out.size == 0:
        return out.reshape((0, *shape))
    if out.ndim != 1 + len(shape) or out.shape[1:] != shape:
        hint = ("; transpose it (.T): points are rows" if out.ndim == 2 and
                out.shape[0] == shape[0] and len(shape) == 1 else "")
        raise error(f"{name} must have shape {want}, got {out.shape}{hint}")
    return out


def real(value: Any, name: str, error: Raise) -> float:
    """``value`` as a float, refusing strings, None, booleans and arrays of more than one
    element (so that the check after it reads a number)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Real, np.ndarray)) \
            or (isinstance(value, np.ndarray) and value.ndim):
        raise error(f"{name} must be a number, got {type(value).__name__} {value!r:.40}")
    try:
        return float(value)
    except (TypeError, ValueError, OverflowError):  # OverflowError: an int beyond a float
        raise error(f"{name} must be a number, got {value!r:.40}") from None


def finite(value: Any, name: str, error: Raise) -> float:
    """``value`` as a finite float (:func:`real`, then NaN and infinities refused)."""
    v = real(value, name, error)
    if not math.isfinite(v):
        raise error(f"{name} must be finite, got {v}")
    return v


def finite_or_none(value: Any, name: str, error: Raise) -> float | None:
    """``None`` or a finite float."""
    return None if value is None else finite(value, name, error)


def integer(value: Any, name: str, error: Raise, *, minimum: int = 0) -> int:
    """``value`` as an ``int`` >= ``minimum``, refusing floats (``2.5`` is not truncated),
    strings, booleans and None."""
    if not (is_integer(value) and value >= minimum):
        raise error(f"{name} must be an integer >= {minimum}, got {value!r:.40}")
    return int(value)


def file_name(value: Any, name: str, error: Raise) -> str:
    """``value`` (a ``str`` or an ``os.PathLike`` naming a ``str``) as a ``str``, refusing
    None, numbers, bytes and objects that are no file name."""
    try:
        path = os.fspath(value)
    except TypeError:
        path = None
    if not isinstance(path, str):
        raise error(f"{name} must be a file name (a str or a pathlib.Path), got "
                    f"{type(value).__name__} {value!r:.40}")
    return path


def no_file(path: str, what: str = "file") -> str:
    """Why ``path`` names no file, for an error line: it is a folder (the reason the command
    line's ``--streams DIR`` gave as "no such file DIR", h112), or there is nothing there (a
    pattern the shell did not expand: said so)."""
    if os.path.isdir(path):
        return (f"{path} is a folder, not a {what}; give the {what}s in it "
                f"({os.path.join(path, '*.jsonl')} in the shell)")
    if any(c in path for c in "*?["):  # '--streams "runs/*.jsonl"': the shell did not expand it
        return (f"no such {what} {path} (a pattern? the command line takes files: leave the "
                f"pattern unquoted for the shell to expand, or put it in a sweep file's streams)")
    return f"no such {what} {path}"


def _kind_names(kinds: type | tuple[type, ...]) -> str:
    return " or ".join(k.__name__ for k in (kinds if isinstance(kinds, tuple) else (kinds,)))


def instance(value: Any, kinds: type | tuple[type, ...], name: str, error: Raise) -> Any:
    """``value`` itself when it is one of ``kinds``; else refused, naming what it is."""
    if not isinstance(value, kinds):
        raise error(f"{name} must be a {_kind_names(kinds)}, got {type(value).__name__} "
                    f"{value!r:.40}")
    return value


def fraction(value: Any, name: str, error: Raise) -> float:
    """``value`` as a float in ``[0, 1]`` (NaN refused)."""
    v = real(value, name, error)
    if not 0 <= v <= 1:
        raise error(f"{name} must be in [0, 1], got {v}")
    return v


def items(value: Any, kinds: type | tuple[type, ...], name: str, error: Raise, *,
          want: str | None = None) -> tuple:
    """``value`` (a list, tuple or other iterable, not a str or a mapping) as a tuple whose
    items are all ``kinds`` (``want`` says what they are, default their class names): a lone
    item, a str (read as its characters) or a dict (read as its keys) is refused, naming the
    first wrong item."""
    want = want or _kind_names(kinds)
    if isinstance(value, (str, bytes, os.PathLike, kinds)) or isinstance(value, Mapping) \
            or not isinstance(value, Iterable):
        hint = " (a list of one: [it])" if isinstance(value, (str, os.PathLike, kinds)) else ""
        raise error(f"{name} must be a list or tuple of {want}, got {type(value).__name__} "
                    f"{value!r:.40}{hint}")
    out = tuple(value)
    for k, v in enumerate(out):
        if not isinstance(v, kinds):
            raise error(f"{name}[{k}] is {type(v).__name__} {v!r:.40}; {name} must hold "
                        f"{want}")
    return out


#: relative tolerance of a covariance's asymmetry and negative eigenvalues, against its largest
#: |entry|: the methods write round-off (at most 1.6e-16 measured: EKF, inverse-depth EKF and
#: GTSAM marginals on simulated runs); 1e-9 leaves room for ill-conditioned inversions and
#: still refuses any real sign or transposition error (the estimate file's reader and writer).
COV_RTOL = 1e-9


def covariance_problem(cov: np.ndarray) -> tuple[int, str] | None:
    """The first matrix of ``cov`` ``(n, k, k)`` that is not finite, symmetric and positive
    semi-definite (to :data:`COV_RTOL`, each matrix scaled by its largest |entry|) and what is
    wrong with it, or None when all are. A matrix all NaN is no problem: it marks a variable
    whose covariance is not defined (``MapEstimate``; ``null`` in an estimate file)."""
    finite = np.isfinite(cov).all(axis=(1, 2))
    undefined = np.isnan(cov).all(axis=(1, 2))
    c = np.where(finite[:, None, None], cov, 0.0)
    scale = np.abs(c).max(axis=(1, 2), initial=0.0)
    c = c / np.where(scale > 0, scale, 1.0)[:, None, None]
    ct = c.transpose(0, 2, 1)
    checks = ((~(finite | undefined), "not finite"),
              (np.abs(c - ct).max(axis=(1, 2), initial=0.0) > COV_RTOL, "not symmetric"),
              (np.linalg.eigvalsh((c + ct) / 2)[:, 0] < -COV_RTOL, "not positive semi-definite"))
    for bad, what in checks:
        if bad.any():
            i = int(np.argmax(bad))
            shown = json.dumps(cov[i].ravel().tolist())[:80]
            return i, (f"the covariance {shown} is {what}; a covariance must be finite, "
                       f"symmetric and positive semi-definite")
    return None


__all__ = ["MAX_ECHO_CHARS", "clip", "command_line", "echo", "echo_name", "option_named",
           "out_named",
           "is_integer", "id_array", "row_array", "real", "finite", "finite_or_none", "integer",
           "file_name", "no_file", "instance", "fraction", "items", "COV_RTOL",
           "covariance_problem"]
