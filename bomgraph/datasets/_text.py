"""Strict line parsing shared by the dataset importers.

Real recordings arrive as whitespace-separated text (MRCLAM ``.dat``, g2o, GTSAM's Victoria
Park file). These helpers read them with one rule: a line that cannot be read is a
:class:`~bomgraph.errors.DatasetError` naming the file, the line number and the field, with
what to fix. Nothing is skipped except comment lines (starting with the comment character) and
whitespace-only lines, which carry no data.

Files ending in ``.gz`` are decompressed transparently; CRLF line endings, tabs and trailing
blanks are accepted (a public MRCLAM copy uses them).
"""

from __future__ import annotations

import array
import gzip
import math
import os
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Iterator, Literal, Sequence

import numpy as np

from ..errors import DatasetError, shown_path
from ..jsonio import BOM_ADVICE, MAX_ID
from ..plausibility import MAX_BEARING_SIGMA_RAD, MIN_BEARING_SIGMA_RAD
from ..stdio import MAX_LINE_BYTES, line_too_long, open_input

FieldKind = Literal["int", "float"]
_CHUNK = 2**20


def dataset_error(path: str | os.PathLike[str], line: int | None, field: str | None,
                  message: str) -> DatasetError:
    """A :class:`DatasetError` whose message starts with ``file, line N: field 'f':``."""
    where = shown_path(path)
    if line is not None:
        where += f", line {line}"
    if field is not None:
        where += f": field '{field}'"
    return DatasetError(f"{where}: {message}")


def checked_bearing_sigma(bearing_sigma_rad: float) -> float:
    """A caller-given bearing sigma, refused unless finite and in [1e-9, pi/sqrt(3)] rad
    (above, the spread of a bearing uniform on the circle; below, no sensor:
    :mod:`bomgraph.plausibility`)."""
    if not (math.isfinite(bearing_sigma_rad) and MIN_BEARING_SIGMA_RAD <= bearing_sigma_rad
            <= MAX_BEARING_SIGMA_RAD):
        raise DatasetError(f"bearing sigma must be a finite number in [{MIN_BEARING_SIGMA_RAD:g}, "
                           f"pi/sqrt(3) = {MAX_BEARING_SIGMA_RAD:.3g}] rad, got "
                           f"{bearing_sigma_rad!r} (radians: 3 degrees is 0.0524)")
    return float(bearing_sigma_rad)


def find_file(directory: str | os.PathLike[str], name: str) -> Path:
    """``directory/name`` or, failing that, ``directory/name.gz``.

    Raises
    ------
    DatasetError
        When neither exists (the message lists what was tried), or the one there is a
        directory or a broken or looping link (the message says which).
    """
    found = file_read(directory, name)
    if found is not None:
        return found
    d = Path(directory)
    for candidate in (d / name, d / (name + ".gz")):  # there, but not a file: say what it is
        if candidate.is_dir():
            raise DatasetError(f"{shown_path(candidate)}: is a directory, not a data file; put the "
                               f"dataset's {name} there")
        if candidate.is_symlink():
            raise DatasetError(f"{shown_path(candidate)}: is a broken or looping link (to "
                               f"{os.readlink(candidate)}); point it at the data file")
    raise DatasetError(f"{shown_path(d)}: neither {name} nor {name}.gz exists; check the dataset "
                       f"directory (each MRCLAM folder holds Barcodes.dat, "
                       f"Landmark_Groundtruth.dat and RobotN_*.dat)")


def file_read(directory: str | os.PathLike[str], name: str) -> Path | None:
    """The file :func:`find_file` reads for ``name``: ``directory/name`` or, failing that,
    ``directory/name.gz``, whichever first exists and is not a directory (a device or FIFO is
    read, bounded); None when neither is, or it cannot be told (no search permission on the
    folder): :func:`find_file` then says why. It never raises (a cache key lists it)."""
    d = Path(directory)
    for candidate in (d / name, d / (name + ".gz")):
        if os.path.exists(candidate) and not os.path.isdir(candidate):  # never raise
            return candidate
    return None


def has_file(directory: str | os.PathLike[str], name: str) -> bool:
    """Whether ``directory/name`` or ``directory/name.gz`` is there, even as something that
    is not a data file (a directory, a broken link), which :func:`find_file` then names."""
    d = Path(directory)
    return any(os.path.lexists(p) for p in (d / name, d / (name + ".gz")))


#: the first two bytes of every gzip file (RFC 1952).
GZIP_MAGIC = b"\x1f\x8b"


#: the largest dataset file read, decompressed. The largest real recording file is 3.4 MB
#: (MRCLAM dataset 6, Robot4_Groundtruth.dat; ``shared/data/*/SOURCE.md``), so 256 MiB is
#: 75x that. The text is read a block at a time, but the rows parsed from it are held, so the
#: cap bounds them too (the general input cap, 4 GiB, would let a 4 MiB .gz ask for it all).
MAX_DATASET_BYTES = 256 * 2**20
#: the largest Victoria Park file read, decompressed. Its importer holds every record as
#: Python objects and then a Step per pose: about 25 bytes of memory a byte of text (h91: 5 MB
#: more text took 125 MB more), so a file at MAX_DATASET_BYTES asked for 6 GiB (h91's fuzz: a
#: MemoryError traceback under 1.5 GiB of address space). 16 MiB, about 400 MB at the peak, is
#: 23x the Victoria Park file (0.7 MB). A g2o file is bounded by the text of the records it
#: holds as objects instead (:data:`bomgraph.datasets.g2o.MAX_G2O_HELD_BYTES`, h96): its
#: bearings are held 8 bytes a value, and a simulated run's export is 1.5 KB a step.
MAX_RECORD_FILE_BYTES = 16 * 2**20


@dataclass(frozen=True)
class Line:
    """One data line: its 1-based number in the file and its whitespace-separated tokens."""

    number: int
    tokens: list[str]


def read_lines(path: str | os.PathLike[str], *, comment: str | None = "#",
               max_bytes: int | None = None,
               max_line_chars: int | None = None) -> Iterator[Line]:
    """The non-comment, non-blank lines of a dataset file with their 1-based line numbers,
    read a block of lines at a time (gzip-decompressed if the name ends in ``.gz``): memory
    is one block (about 1 MiB) and one line, whatever the file's size.

    ``max_line_chars`` bounds a data line before it is split into tokens: a token is a
    Python string, about 20 bytes of memory a byte of text (h97: one 60 MB line of ``12 ``
    in a g2o file peaked at 1.7 GB), so a line longer than that is refused naming its line.

    Raises
    ------
    DatasetError
        When the file is missing, unreadable, not gzip despite its name, corrupt gzip, larger
        than ``max_bytes`` decompressed (default :data:`MAX_DATASET_BYTES`; a file larger
        than that on disk is refused before it is read), or not ASCII/UTF-8.
    """
    p = Path(path)
    max_bytes = MAX_DATASET_BYTES if max_bytes is None else max_bytes
    try:
        fh = open_input(p)
    except FileNotFoundError:
        raise DatasetError(f"{shown_path(p)}: file not found; check the path") from None
    except OSError as exc:
        raise DatasetError(f"{shown_path(p)}: cannot read ({exc.strerror or exc})") from None
    with fh:
        try:
            is_gzip = fh.peek(2)[:2] == GZIP_MAGIC
        except OSError as exc:
            raise DatasetError(f"{shown_path(p)}: cannot read ({exc.strerror or exc})") from None
        if p.suffix == ".gz" and not is_gzip:
            raise DatasetError(f"{shown_path(p)}: named .gz but not gzip data; drop the .gz suffix")
        if not is_gzip and os.fstat(fh.fileno()).st_size > max_bytes:
            raise _too_large(p, max_bytes)
        src: IO[bytes] = gzip.GzipFile(fileobj=fh) if p.suffix == ".gz" else fh
        number, offset = 0, 0
        try:
            for block in _line_blocks(src, p, max_bytes):
                if offset == 0 and block.startswith(b"\xef\xbb\xbf"):  # was: record '\ufeff#'
                    raise dataset_error(p, 1, None, BOM_ADVICE)
                try:
                    text = block.decode("utf-8")
                except UnicodeDecodeError as exc:
                    hint = ("it is gzip data: name it with a .gz suffix" if is_gzip else
                            "the file is corrupt or not a text dataset")
                    line = number + block[:exc.start].count(b"\n") + 1
                    raise dataset_error(p, line, None, f"not UTF-8 text (byte "
                                        f"{offset + exc.start}); {hint}") from None
                offset += len(block)
                for part in text.splitlines():  # as str.splitlines of the whole text
                    number += 1
                    stripped = part.strip()
                    if stripped and not (comment is not None and stripped.startswith(comment)):
                        if max_line_chars is not None and len(stripped) > max_line_chars:
                            raise _line_too_wide(p, number, len(stripped), max_line_chars)
                        yield Line(number, stripped.split())
        except (EOFError, gzip.BadGzipFile, zlib.error) as exc:
            raise DatasetError(f"{shown_path(p)}: corrupt gzip data ({exc})") from None
        except OSError as exc:
            raise DatasetError(f"{shown_path(p)}: cannot read ({exc.strerror or exc})") from None


def _line_too_wide(p: Path, number: int, n: int, limit: int) -> DatasetError:
    return dataset_error(p, number, None, f"{n:,} characters, more than the {limit:,} one "
                                          f"line of this file may have; fix or delete this "
                                          f"line")


def _too_large(p: Path, max_bytes: int) -> DatasetError:
    what = ("a dataset file (the largest real recording file is 3.4 MB)"
            if max_bytes == MAX_DATASET_BYTES else
            "a Victoria Park file, whose records are all held (the Victoria Park file is "
            "0.7 MB)")
    return DatasetError(f"{shown_path(p)}: larger than {max_bytes >> 20} MiB"
                        f"{' decompressed' if p.suffix == '.gz' else ''}, the limit for {what}; "
                        f"split it")


def _line_blocks(src: IO[bytes], p: Path, max_bytes: int) -> Iterator[bytes]:
    """``src`` in blocks of whole lines (about 1 MiB each; the last may lack its newline),
    refusing a line over :data:`bomgraph.stdio.MAX_LINE_BYTES` and a file over
    ``max_bytes``. Memory: one block and one line."""
    pending: list[bytes] = []   # the start of a line longer than the chunk
    pending_n = total = newlines = 0
    while chunk := src.read(_CHUNK):
        total += len(chunk)
        cut = chunk.rfind(b"\n")
        if total > max_bytes:
            if cut < 0 and pending_n + len(chunk) > max_bytes:  # one line over the file's cap
                raise line_too_long(p, newlines + 1, max_bytes)  # (/dev/zero; h96)
            raise _too_large(p, max_bytes)
        if cut < 0:
            pending.append(chunk)
            pending_n += len(chunk)
            if pending_n > MAX_LINE_BYTES:
                raise line_too_long(p, newlines + 1)
            continue
        block = b"".join(pending + [chunk[:cut + 1]])
        newlines += block.count(b"\n")
        pending, pending_n = [chunk[cut + 1:]], len(chunk) - cut - 1
        yield block
    if pending_n:
        yield b"".join(pending)


def parse_float(token: str, path: str | os.PathLike[str], line: int, field: str) -> float:
    """A finite float, or a DatasetError naming file, line and field."""
    try:
        value = float(token)
    except ValueError:
        raise dataset_error(path, line, field, f"cannot read {token[:40]!r} as a number; "
                                               f"fix or delete this line") from None
    if not math.isfinite(value):
        raise dataset_error(path, line, field, f"{token[:40]!r} is not a finite number; "
                                               f"fix or delete this line")
    return value


def parse_int(token: str, path: str | os.PathLike[str], line: int, field: str) -> int:
    """An integer written without a fraction that fits int64 (a stream's ids are int64), or a
    DatasetError naming file, line, field."""
    try:
        value = int(token)
    except ValueError:
        raise dataset_error(path, line, field, f"cannot read {token[:40]!r} as an integer; "
                                               f"fix or delete this line") from None
    if not -MAX_ID - 1 <= value <= MAX_ID:
        raise dataset_error(path, line, field, f"{token[:40]} is out of range: integers "
                                               f"(ids) must be below 2^63; renumber it")
    return value


#: the longest data line of a table (:func:`read_table`; a MRCLAM row is about 50 characters):
#: a longer one is refused before it is split into tokens, about 20 bytes of memory a
#: character (h97: one 60 MB line of a g2o file peaked at 1.7 GB; the tables' 64 MiB line cap
#: let the same through)
MAX_TABLE_LINE_CHARS = 2**20


def read_table(path: str | os.PathLike[str], fields: Sequence[tuple[str, FieldKind]], *,
               comment: str | None = "#") -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Read a whitespace-separated numeric table with exactly ``len(fields)`` columns.

    Parameters
    ----------
    path : path-like
        The file (``.gz`` is decompressed).
    fields : sequence of (name, "int" | "float")
        Column names (used in error messages and as keys of the result) and types.
    comment : str or None
        Lines starting with this are skipped.

    Returns
    -------
    columns : dict of str to ndarray of shape (n,)
        One array per column: int64 for "int", float64 for "float".
    line_numbers : ndarray of shape (n,), int64
        The 1-based line number of each row, for later error messages.

    Raises
    ------
    DatasetError
        On a wrong number of columns, an unreadable or non-finite number, naming the file,
        the line number and the field.
    """
    names = [f for f, _ in fields]
    # typed buffers, 8 bytes a value: a file at MAX_DATASET_BYTES of MRCLAM rows is about 8
    # million rows, which as lists of Python numbers took over 1 GiB (h91's fuzz: a 6 MB
    # gzip of odometry rows ended in a MemoryError traceback under 1.5 GiB of address space)
    columns = [array.array("q" if kind == "int" else "d") for _, kind in fields]
    numbers = array.array("q")
    for line in read_lines(path, comment=comment, max_line_chars=MAX_TABLE_LINE_CHARS):
        numbers.append(line.number)
        if len(line.tokens) != len(fields):
            raise dataset_error(path, line.number, None,
                                f"expected {len(fields)} fields ({', '.join(names)}), got "
                                f"{len(line.tokens)}; fix or delete this line")
        for k, ((name, kind), token) in enumerate(zip(fields, line.tokens)):
            if kind == "int":
                columns[k].append(parse_int(token, path, line.number, name))
            else:
                columns[k].append(parse_float(token, path, line.number, name))
    table = {name: np.frombuffer(col, dtype=np.int64 if kind == "int" else float)
             for (name, kind), col in zip(fields, columns)}
    return table, np.frombuffer(numbers, dtype=np.int64)


def chain_order(edges: Sequence[tuple[int, int, int]],
                path: str | os.PathLike[str]) -> list[int]:
    """Order pose ids along a single chain of odometry edges.

    Parameters
    ----------
    edges : sequence of (from_id, to_id, line_number)
        The odometry records in file order.
    path : path-like
        For error messages.

    Returns
    -------
    list of int
        Pose ids from the chain's start to its end (``len(edges) + 1`` of them).

    Raises
    ------
    DatasetError
        When a pose has two outgoing or two incoming edges, an edge joins a pose to itself, or
        the edges form a loop or several chains (a stream holds one odometry chain).
    """
    succ: dict[int, tuple[int, int]] = {}
    pred: dict[int, tuple[int, int]] = {}
    for a, b, line in edges:
        if a == b:
            raise dataset_error(path, line, None, f"odometry from pose {a} to itself; fix or "
                                                  f"delete this line")
        if a in succ:
            raise dataset_error(path, line, None,
                                f"pose {a} already has odometry to pose {succ[a][0]} (line "
                                f"{succ[a][1]}); a stream holds one odometry chain, so loop "
                                f"closures and branches cannot be imported; delete one edge")
        if b in pred:
            raise dataset_error(path, line, None,
                                f"pose {b} already has odometry from pose {pred[b][0]} (line "
                                f"{pred[b][1]}); a stream holds one odometry chain, so loop "
                                f"closures and branches cannot be imported; delete one edge")
        succ[a] = (b, line)
        pred[b] = (a, line)
    starts = [a for a, _, _ in edges if a not in pred]
    if not edges:
        return []
    if not starts:
        raise dataset_error(path, edges[0][2], None, "the odometry edges form a closed loop; a "
                                                     "stream needs a chain with a first pose")
    if len(starts) > 1:
        line = succ[starts[1]][1]
        raise dataset_error(path, line, None,
                            f"the odometry edges form {len(starts)} separate chains (starting "
                            f"at poses {', '.join(str(s) for s in starts[:4])}); a stream "
                            f"needs one unbroken chain")
    order = [starts[0]]
    while order[-1] in succ and len(order) <= len(edges):
        order.append(succ[order[-1]][0])
    if len(order) != len(edges) + 1:
        # the chain from the start is shorter: the remaining edges form a loop
        visited = set(order)
        line = next(line for a, _, line in edges if a not in visited)
        raise dataset_error(path, line, None, "this odometry edge is on a closed loop apart "
                                              "from the main chain; a stream needs one chain")
    return order


def file_label(path: str | os.PathLike[str]) -> str:
    """The file name alone, for metadata (no absolute paths in streams)."""
    return Path(path).name


__all__ = ["dataset_error", "find_file", "file_read", "has_file", "read_lines", "Line",
           "MAX_DATASET_BYTES", "MAX_RECORD_FILE_BYTES", "MAX_TABLE_LINE_CHARS",
           "parse_float", "parse_int", "read_table", "chain_order", "file_label"]
