"""Strict JSON helpers shared by the stream, the estimate file, the cache and the CLI.

- :func:`jsonable`: the one sanitiser that turns numpy values, tuples and non-finite floats
  into plain JSON values (non-finite floats become ``null``: strict JSON has no NaN; with
  ``strict=True`` they, and objects JSON cannot hold, are refused instead).
- Strict reading: :func:`loads_strict` parses one JSON text refusing duplicate keys
  (:class:`DuplicateKeyError`); :func:`find_nonfinite` names the first NaN/Infinity in parsed
  data; :func:`is_int`, :func:`is_id`, :func:`is_num` test JSON values without accepting
  booleans as numbers; :func:`decode_utf8` turns a raw line into text.
- :func:`line_of_key` finds the line of a JSON text on which a path (``a.b[2]``) lies, for
  messages about a multi-line JSON document; :func:`path_of` spells where a container is.
- :func:`parse_option_value` / :func:`parse_options`: the one parser of ``key=value`` method
  options (from ``--option`` and from scripts). Values are JSON where they parse as JSON;
  ``inf``, ``+inf``, ``-inf``, ``Infinity`` and ``-Infinity`` are infinities; anything else is
  a string. NaN is refused: no option means "not a number". A record of options
  (:func:`options_to_json`, :func:`options_from_json`) writes an infinity as the string
  ``"Infinity"`` or ``"-Infinity"`` (strict JSON has none), so it reads back as given.
"""

from __future__ import annotations

import json
import math
import os
import re
import sys
from json.decoder import scanstring
from typing import Any, Iterator, Mapping, Sequence

import numpy as np

from .checks import option_named
from .errors import ConfigError

_INFINITIES = {"inf": math.inf, "+inf": math.inf, "infinity": math.inf, "+infinity": math.inf,
               "-inf": -math.inf, "-infinity": -math.inf}


def jsonable(value: Any, *, max_items: int | None = None, strict: bool = False) -> Any:
    """``value`` as plain JSON data.

    Numpy scalars become Python numbers, arrays/tuples/lists become lists, sets sorted lists
    (by value, or by ``repr`` where the values do not compare) and paths strings (not with
    ``strict``: they would not read back as they were), mappings dicts with string keys,
    non-finite floats ``None``. A sequence longer than ``max_items`` (when given) and any other
    object become ``None``.

    With ``strict=True`` a non-finite float raises ``ValueError`` and an object JSON cannot
    hold raises ``TypeError`` (for data that must survive a file unchanged, e.g. stream meta).
    """
    if value is None:
        return value
    if isinstance(value, str):
        return str(value)
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        if math.isfinite(v):
            return v
        if strict:
            raise ValueError(f"non-finite number {v} is not allowed")
        return None
    if isinstance(value, Mapping):
        return {str(k): jsonable(v, max_items=max_items, strict=strict)
                for k, v in value.items()}
    if not strict and isinstance(value, (set, frozenset)):
        try:
            value = sorted(value)
        except TypeError:                       # values that do not compare (1 and "a")
            value = sorted(value, key=repr)
    if not strict and isinstance(value, os.PathLike):
        return os.fspath(value)
    if isinstance(value, (list, tuple, np.ndarray)):
        if max_items is not None and len(value) > max_items:
            return None
        return [jsonable(v, max_items=max_items, strict=strict) for v in value]
    if strict:
        raise TypeError(f"Object of type {type(value).__name__} is not JSON serializable")
    return None


# --------------------------------------------------------------------------------------------
# Strict reading
# --------------------------------------------------------------------------------------------

MAX_ID = int(np.iinfo(np.int64).max)
"""The largest landmark id or step index a file may carry (fits int64)."""


def is_int(v: Any) -> bool:
    """A JSON integer (``True``/``False`` are not integers here)."""
    return isinstance(v, int) and not isinstance(v, bool)


def version_problem(version: Any, known: Sequence[int]) -> str | None:
    """What is wrong with a header's ``version`` (None: it is one of ``known``): a value that
    is not a JSON integer is told which integer to write (``"1"`` was refused as an "unknown
    version" by a reader that "knows version 1"), an integer outside ``known`` is unknown."""
    if is_int(version) and version in known:
        return None
    if not is_int(version):
        got = json.dumps(version)[:20]
        return (f"must be the integer {' or '.join(map(str, known))}, not "
                f"{'the string ' if isinstance(version, str) else ''}{got}")
    knows = (f"versions {', '.join(map(str, known[:-1]))} and {known[-1]}" if len(known) > 1
             else f"version {known[0]}")
    got = str(version) if len(str(version)) <= 20 else f"{str(version)[:20]}..."
    return f"unknown version {got}; this reader knows {knows}"


def is_id(v: Any) -> bool:
    """A landmark id or step index: a JSON integer in ``[0, MAX_ID]``."""
    return is_int(v) and 0 <= v <= MAX_ID


def is_num(v: Any) -> bool:
    """A JSON number that fits a float (booleans and huge integers do not)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    if isinstance(v, int):
        try:
            return math.isfinite(float(v))
        except OverflowError:
            return False
    return True


class DuplicateKeyError(Exception):
    """A key appears twice in one JSON object; ``args[0]`` is the key."""


def no_duplicate_keys(pairs: list[tuple[str, Any]]) -> dict:
    """``object_pairs_hook`` for :mod:`json` that refuses a repeated key."""
    out: dict = {}
    for k, v in pairs:
        if k in out:
            raise DuplicateKeyError(k)
        out[k] = v
    return out


def loads_strict(text: str) -> Any:
    """``json.loads`` that raises :class:`DuplicateKeyError` on a repeated key.

    ``NaN``/``Infinity`` parse as floats so that :func:`find_nonfinite` can name where they
    are (the caller refuses them with the key).
    """
    return json.loads(text, parse_constant=float, object_pairs_hook=no_duplicate_keys)


def find_nonfinite(obj: Any, where: str = "") -> str | None:
    """The path (``a.b[2]``) of the first non-finite float in parsed JSON data, or None.

    Walks the data depth first with an explicit stack of iterators, so any nesting depth the
    JSON parser accepted is checked without recursion, and memory stays that of the depth: a
    path is spelled only for the value it names (spelling one per element took about 130
    bytes each, 4 GB for a 60 MiB line of numbers)."""
    if isinstance(obj, float):
        return None if math.isfinite(obj) else where
    if not isinstance(obj, (dict, list)):
        return None
    # a frame: the (key, value) pairs of one container and its link to the root, a link being
    # (parent link, key, whether the key is a dict's) or None at the root
    stack: list[tuple[Iterator[tuple[Any, Any]], Any]] = [(_items(obj), None)]
    while stack:
        items, link = stack[-1]
        in_dict = isinstance(items, _DICT_ITEMS)
        for key, value in items:
            if isinstance(value, float):
                if not math.isfinite(value):
                    return _spell(where, (link, key, in_dict))
            elif isinstance(value, (dict, list)):
                stack.append((_items(value), (link, key, in_dict)))
                break
        else:
            stack.pop()
    return None


_DICT_ITEMS = type(iter({}.items()))


def _items(node: dict | list) -> Iterator[tuple[Any, Any]]:
    """``(key, value)`` of a dict or ``(index, value)`` of a list, as an iterator."""
    return iter(node.items()) if isinstance(node, dict) else enumerate(node)


def _spell(where: str, link: Any) -> str:
    """The path ``a.b[2]`` of the value a link chain ``(parent link, key, in dict)`` ends at."""
    keys: list[tuple[Any, bool]] = []
    while link is not None:
        link, key, in_dict = link
        keys.append((key, in_dict))
    at, root = where, not where   # the root's keys are spelled bare, even the key ""
    for key, in_dict in reversed(keys):
        at = (str(key) if root else f"{at}.{key}") if in_dict else f"{at}[{key}]"
        root = False
    return at


def path_of(root: Any, target: dict | list) -> str | None:
    """The path (``a.b[2]``; ``""`` for the root) of the container ``target``, found by
    identity in parsed JSON data ``root``, or None. Iterative, as :func:`find_nonfinite`."""
    if root is target:
        return ""
    if not isinstance(root, (dict, list)):
        return None
    stack: list[tuple[Iterator[tuple[Any, Any]], Any]] = [(_items(root), None)]
    while stack:
        items, link = stack[-1]
        in_dict = isinstance(items, _DICT_ITEMS)
        for key, value in items:
            if isinstance(value, (dict, list)):
                if value is target:
                    return _spell("", (link, key, in_dict))
                stack.append((_items(value), (link, key, in_dict)))
                break
        else:
            stack.pop()
    return None




def line_of_key(text: str, key: str | None) -> int:
    """The line (from 1) of ``text``, one JSON value, on which the value that ``key`` names
    begins: ``key`` is a path as :func:`find_nonfinite` spells it (``a.b[2]``; a key holding
    ``.`` or ``[`` is matched whole); a path ending in an object's key gives the line of that
    key (of its last occurrence, if it is repeated). Only the path is walked, the values
    beside it are stepped over; where the path leaves the data the line is that of the last
    value reached, so line 1 for a ``key`` of None.

    Linear in the text and vectorised (:class:`_Structure`: the brackets, braces and commas
    outside strings and their depths, found once), so a file of millions of values is walked
    in a fraction of a second; only the keys of the objects on the path that could be the
    one named are decoded. ``text`` is expected to be valid JSON (the estimate reader calls
    this only after parsing it); beyond where it is not, the line is a best guess."""
    end = len(text)
    while end and text[end - 1] in " \t\r\n":
        end -= 1
    if text.find("\n", 0, end) < 0:
        return 1                          # one line (as bomgraph wrote version 1): no walk
    data = text.encode("utf-8", "surrogatepass")
    doc = _Structure(data)
    pos = _WSB.match(data).end()
    rest = key or ""
    top_empty = key == ""                 # the top-level key "" (the root is never named "")
    at_root = True                        # a root key is not after a "." (".x" is key ".x")
    try:   # the text is parsed JSON when the estimate reader asks; if not, a best guess
        while rest or top_empty:
            top_empty = False
            if data.startswith(b"[", pos) and (m := _INDEX.match(rest)):
                k = int(m[1])
                commas = doc.separators(pos)
                if k > len(commas):
                    break
                pos = _WSB.match(data, (pos if k == 0 else int(commas[k - 1])) + 1).end()
                rest, at_root = rest[m.end():], False
                continue
            if not data.startswith(b"{", pos):
                break
            if not at_root:
                rest = rest.removeprefix(".")
            at_root = False
            found = doc.last_longest_key(pos, rest)
            if found is None:
                break
            name, at, value = found
            rest = rest[len(name):]
            pos = value if rest else at
    except (ValueError, IndexError):   # not JSON here (a string's quotes unpaired,
        pass                           # a raw control character): the line reached
    return data.count(b"\n", 0, pos) + 1


_WSB = re.compile(rb"[ \t\n\r]*")
_PATH_CUT = re.compile(rb"[.\[]")
_INDEX = re.compile(r"\[(\d+)\]")
_OPEN, _CLOSE, _COMMA, _QUOTE, _BACKSLASH = b"[{", b"]}", ord(","), ord('"'), ord("\\")


class _Structure:
    """The skeleton of a JSON text (UTF-8 bytes) for :func:`line_of_key`: the positions of
    its brackets, braces and commas outside strings with the nesting depth after each, and
    of its strings' unescaped quotes."""

    def __init__(self, data: bytes) -> None:
        self.data = data
        a = np.frombuffer(data, np.uint8)
        quotes = np.flatnonzero(a == _QUOTE)
        after_bs = quotes[(quotes > 0) & (a[quotes - 1] == _BACKSLASH)]
        escaped = [q for q in after_bs.tolist() if _backslashes_before(data, q) % 2]
        self.quotes = np.setdiff1d(quotes, escaped, assume_unique=True) if escaped else quotes
        self.backslashes = np.flatnonzero(a == _BACKSLASH)
        step = np.zeros(256, np.int8)
        step[list(_OPEN)], step[list(_CLOSE)] = 1, -1
        mark = step != 0
        mark[_COMMA] = True
        where = np.flatnonzero(mark[a])
        where = where[np.searchsorted(self.quotes, where) % 2 == 0]   # outside strings
        self.where = where
        self.is_comma = a[where] == _COMMA
        self.depth = np.cumsum(step[a[where]], dtype=np.int32)   # inside, after each mark

    def _inside(self, pos: int) -> tuple[int, int, int]:
        """For the container opened at ``pos``: the index of its opening mark, of its
        closing one (the end of the marks if it is not closed), and its depth."""
        i = int(np.searchsorted(self.where, pos))
        d = int(self.depth[i])
        lo, width, n = i + 1, 64, len(self.where)
        while lo < n:   # in growing windows: a path's containers are walked in their length
            hi = min(n, lo + width)               # (not to the end of the text at each level)
            below = np.flatnonzero(self.depth[lo:hi] < d)
            if below.size:
                return i, lo + int(below[0]), d
            lo, width = hi, width * 4
        return i, n, d

    def separators(self, pos: int) -> np.ndarray:
        """The positions of the commas between the values of the container opened at
        ``pos``."""
        i, j, d = self._inside(pos)
        sel = self.is_comma[i + 1:j] & (self.depth[i + 1:j] == d)
        return self.where[i + 1:j][sel]

    def last_longest_key(self, pos: int, rest: str) -> tuple[str, int, int] | None:
        """Of the object opened at ``pos``, the key that begins ``rest`` as a path (``rest``
        itself, or followed by ``.`` or ``[``), the longest, the last if repeated: ``(key,
        where the key is, where its value is)``, or None. Only keys of a length one of those
        could have, or written with escapes, are decoded."""
        i, j, _ = self._inside(pos)
        close = int(self.where[j]) if j < len(self.where) else len(self.data)
        # each key is the first string after the '{' or a comma of the object
        k = np.searchsorted(self.quotes, np.concatenate([[pos], self.separators(pos)]),
                            side="right")
        k = k[k + 1 < len(self.quotes)]
        starts, ends = self.quotes[k], self.quotes[k + 1]
        starts, ends = starts[starts < close], ends[starts < close]
        # the byte lengths of rest and of its prefixes before a "." or "[", up to the longest
        # key here (not every prefix: a path n keys deep has n of them, each as long)
        longest = int((ends - starts).max()) - 1 if len(starts) else 0
        head = rest[:longest + 1].encode("utf-8", "surrogatepass")
        sizes = [m.start() for m in _PATH_CUT.finditer(head)] + [len(head)]
        escaped = (np.searchsorted(self.backslashes, ends)
                   > np.searchsorted(self.backslashes, starts))
        best: tuple[str, int, int] | None = None
        for at, end in zip(*(v[np.isin(ends - starts - 1, sizes) | escaped].tolist()
                             for v in (starts, ends))):
            name = scanstring(self.data[at:end + 1].decode("utf-8", "surrogatepass"), 1)[0]
            if rest.startswith(name) and rest[len(name):len(name) + 1] in ("", ".", "[") \
                    and (best is None or len(name) >= len(best[0])):
                colon = _WSB.match(self.data, end + 1).end()
                best = (name, at, _WSB.match(self.data, colon + 1).end())
        return best


def _backslashes_before(data: bytes, pos: int) -> int:
    n = 0
    while pos - n - 1 >= 0 and data[pos - n - 1] == 0x5C:
        n += 1
    return n


#: nesting deeper than this is where a JSON text is said to be too deep (:mod:`json`
#: gives up near the interpreter's recursion limit, 1000 by default)
_DEEP = 500
_STRING_OR_BRACKET = r'"(?:[^"\\]|\\.)*"|[\[\]{}]'
_TOKEN = re.compile(_STRING_OR_BRACKET + (r"|(?<![\d.eE+\-])-?\d{%d,}(?![\d.eE])"
                                          % (sys.get_int_max_str_digits() + 1)
                                          if sys.get_int_max_str_digits() else ""))


def unparsable_at(text: str) -> tuple[int | None, str | None]:
    """Where valid JSON that :mod:`json` cannot parse first defeats it: the line of the first
    nesting deeper than :data:`_DEEP` or of the first integer longer than Python converts,
    and what it is; ``(None, None)`` if neither is found."""
    depth = 0
    for m in _TOKEN.finditer(text):
        tok = m[0]
        if tok in ("[", "{"):
            depth += 1
            if depth > _DEEP:
                return text.count("\n", 0, m.start()) + 1, f"nested more than {_DEEP} deep"
        elif tok in ("]", "}"):
            depth -= 1
        elif tok[0] != '"':
            return (text.count("\n", 0, m.start()) + 1,
                    f"an integer of {len(tok.lstrip('-'))} digits; Python converts at most "
                    f"{sys.get_int_max_str_digits()}")
    return None, None


#: what a file that starts with a UTF-8 byte-order mark (Windows Notepad's "UTF-8") is told
BOM_ADVICE = "the file starts with a UTF-8 byte-order mark (BOM): save it as UTF-8 without one"


def decoder_problem(exc: json.JSONDecodeError) -> str:
    """The decoder's message and column: ``Expecting ',' delimiter at column 61``; of a
    byte-order mark, what to do (it said "decode using utf-8-sig", advice to a programmer)."""
    return BOM_ADVICE if exc.msg.startswith("Unexpected UTF-8 BOM") else (
        f"{exc.msg.removesuffix(' at')} at column {exc.colno}")


#: a number the decoder may have stopped inside (``-``, ``1.``, ``1e``, ``-2.5e+``), and the
#: start of a literal (``tru``)
_NUMBER_START = re.compile(r'-?(?:(?:0|[1-9][0-9]*)(?:\.[0-9]*)?(?:[eE][+-]?[0-9]*)?)?')
_VALUE_START = re.compile(rf'\s*(?:{_NUMBER_START.pattern}|t(?:ru?)?|f(?:a(?:ls?)?)?|n(?:ul?)?)')


def _stops_mid_value(exc: json.JSONDecodeError, text: str) -> bool:
    """The decoder ran out of ``text`` (no newline) inside a value: a prefix of a valid line,
    as a file cut short ends. Not where a stray character follows a complete value (``1 2``,
    ``1.2.3``, ``"x"1``, h119: those were called cut short), but inside a ``\\u`` escape too
    (h119: ``"ab\\u00`` was not)."""
    rest = text[exc.pos:]
    if exc.msg.startswith("Unterminated string") or not rest.strip():
        return True
    if exc.msg.startswith("Invalid \\uXXXX escape"):
        return re.fullmatch(r"u[0-9a-fA-F]{0,4}", rest) is not None  # 4: at the end
    if exc.msg.startswith("Expecting value"):
        return _VALUE_START.fullmatch(rest) is not None
    start = exc.pos   # a delimiter expected: the number before it, with what follows it
    while start > 0 and text[start - 1] in "0123456789.eE+-":
        start -= 1
    return start < exc.pos and _NUMBER_START.fullmatch(text, start) is not None


def line_not_json(exc: BaseException, text: str, line: int = 1) -> str:
    """Why line ``line`` of a JSON Lines file (``text``, with its newline) does not parse:
    ``not valid JSON (Expecting ',' delimiter at column 61)``, and where the line has no
    newline (the file ends in it) and the decoder ran out of it mid-value, that the file looks
    cut short (h112: a truncated last line said only ``(Unterminated string starting at)``;
    h116: not of a complete line with a stray character or a trailing comma). A byte-order
    mark after line 1 (files joined, one saved with a BOM) is called the line's, not the
    file's."""
    if isinstance(exc, json.JSONDecodeError):
        why = decoder_problem(exc)
        if line > 1 and exc.msg.startswith("Unexpected UTF-8 BOM"):
            why = ("the line starts with a UTF-8 byte-order mark (BOM): remove it (a file "
                   "saved with one, joined to this one?)")
        ran_out = _stops_mid_value(exc, text)
    else:
        why = ("too deeply nested" if isinstance(exc, RecursionError)
               else unparsable_at(text)[1] or str(exc) or type(exc).__name__)
        ran_out = False
    cut = ("; the file ends in this line, without a newline: cut short? complete the line or "
           "remove it" if ran_out and not text.endswith("\n") else "")
    return f"not valid JSON ({why}){cut}"


def decode_utf8(raw: bytes) -> str:
    """One raw line as text; ``UnicodeDecodeError`` says at which byte it is not UTF-8."""
    return raw.decode("utf-8")


def parse_option_value(text: str) -> Any:
    """One option value from text: JSON if it parses, an infinity, or else the string."""
    low = text.strip().lower()
    if low in _INFINITIES:
        return _INFINITIES[low]
    if low in ("nan", "+nan", "-nan"):
        raise ConfigError(f"option value {text!r}: NaN is not a valid option value")
    try:
        return json.loads(text, parse_constant=_refuse_constant)
    except ConfigError:
        raise
    except (ValueError, RecursionError):   # not JSON, or JSON Python will not parse (an
        return text                        # integer of 5000 digits, nesting 3000 deep)


def _refuse_constant(name: str) -> float:
    if name == "NaN":
        raise ConfigError("NaN is not a valid option value")
    return math.inf if name == "Infinity" else -math.inf


#: How a record (an estimate file's ``options``, results.json's arms) writes an infinite option
#: value: strict JSON has no infinity, and these are the texts ``--option`` reads as one.
OPTION_INFINITIES = {"Infinity": math.inf, "-Infinity": -math.inf}


def options_to_json(value: Any) -> Any:
    """Method options (a mapping, or one value) as they are recorded: each infinity, at any
    depth, as the string ``"Infinity"`` or ``"-Infinity"`` (:data:`OPTION_INFINITIES`), read
    back by :func:`options_from_json`; everything else as given (tuples as lists). A string
    option spelled so would read back as the infinity, so it is refused (ConfigError)."""
    if isinstance(value, Mapping):
        return {k: options_to_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [options_to_json(v) for v in value]
    if isinstance(value, str) and value in OPTION_INFINITIES:
        number = option_named("--option KEY=inf", "float('inf')")
        raise ConfigError(f"option value {value!r}: a record writes an infinity so (it would "
                          f"read back as {OPTION_INFINITIES[value]}); give the number "
                          f"({number}) or another string")
    if isinstance(value, (float, np.floating)) and math.isinf(value):
        return "Infinity" if value > 0 else "-Infinity"
    return value


def options_from_json(value: Any) -> Any:
    """Recorded options (:func:`options_to_json`) as given: ``"Infinity"`` and
    ``"-Infinity"``, at any depth, are the infinities again."""
    if isinstance(value, dict):
        return {k: options_from_json(v) for k, v in value.items()}
    if isinstance(value, list):
        return [options_from_json(v) for v in value]
    if isinstance(value, str) and value in OPTION_INFINITIES:
        return OPTION_INFINITIES[value]
    return value


def parse_options(pairs: Sequence[str]) -> dict[str, Any]:
    """``["key=value", ...]`` as a dict, values by :func:`parse_option_value`."""
    out: dict[str, Any] = {}
    for p in pairs:
        if "=" not in p:
            raise ConfigError(f"an option is key=value, got {p!r}")
        k, v = p.split("=", 1)
        if not k:
            raise ConfigError(f"an option needs a name before '=', got {p!r}")
        if k in out:
            raise ConfigError(f"option {k} is given twice; give it once")
        try:
            out[k] = parse_option_value(v)
        except ConfigError as exc:
            raise ConfigError(f"option {k}: {exc}") from None
    return out


__all__ = ["jsonable", "parse_option_value", "parse_options", "options_to_json",
           "options_from_json", "OPTION_INFINITIES", "MAX_ID", "is_int", "is_id",
           "is_num", "version_problem", "DuplicateKeyError", "no_duplicate_keys", "loads_strict",
           "find_nonfinite", "path_of", "line_of_key", "unparsable_at", "decoder_problem",
           "BOM_ADVICE", "line_not_json"]
