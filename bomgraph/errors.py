"""The exceptions bomgraph raises: one base class, one subclass per kind of mistake.

Every message says what is wrong and, where it can, what to do about it.
"""

from __future__ import annotations

import os


def shown_path(path: str | bytes | os.PathLike[str] | os.PathLike[bytes]) -> str:
    """A file name as every message shows it: as written when each of its characters is
    printable, else as a Python string literal (``'a\\nb.jsonl'``: quoted, a backslash
    doubled, a newline as ``\\n``, any other control or undecodable character as its escape),
    so a name never splits a message's one line, moves the cursor or hides what follows;
    an empty name is ``'' (an empty file name)``. Every message that names a file (the
    errors' and the warnings') shows it through here."""
    text = os.fsdecode(path)
    if not text:
        return "'' (an empty file name)"
    return text if text.isprintable() else repr(text)


def one_line(text: str) -> str:
    """``text`` with each character that is not printable (a newline, a tab, an escape, an
    undecodable byte) written as its escape, as :func:`shown_path` writes it: the CLI's net
    under every line it prints to stderr (an error, a warning), for a message that echoes
    other input (a method name, an option value) or a file name not yet shown through
    :func:`shown_path`."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def exception_line(exc: BaseException) -> str:
    """``"Type: message"`` of an exception a method raised, as every place shows it (``run``,
    ``compare``'s table and stderr line, results.json, the CSVs): its message's line breaks
    (and the blanks around them) turned into single spaces, so a message written over several
    lines (GTSAM's "Indeterminate linear system ...") reads as one sentence, and any other
    character that is not printable (a tab, an escape sequence) written as its escape
    (:func:`one_line`), so the table on a terminal is not recoloured or cut; ``"Type"`` alone
    for an empty message (``ZeroDivisionError()``), not a dangling ``"Type: "``."""
    text = message_line(str(exc))
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def message_line(text: str) -> str:
    """``text`` on one line: its line breaks (and the blanks around them) a single space,
    any other character that is not printable escaped (:func:`one_line`)."""
    return one_line(" ".join(part for part in (p.strip() for p in text.splitlines()) if part))


class BomgraphError(Exception):
    """Base class of every error bomgraph raises on purpose."""


class StreamFormatError(BomgraphError, ValueError):
    """A measurement stream or estimate file breaks the format (names file, line and key)."""

    def __init__(self, message: str, *, path: str | None = None, line: int | None = None,
                 key: str | None = None) -> None:
        where = []
        if path is not None:
            where.append(shown_path(path))
        if line is not None:
            where.append(f"line {line}")
        prefix = ": ".join([", ".join(where)]) if where else ""
        if key is not None:
            message = f"'{key}': {message}"
        super().__init__(f"{prefix}: {message}" if prefix else message)
        self.path = path
        self.line = line
        self.key = key


class ConfigError(BomgraphError, ValueError):
    """A configuration value is out of range or inconsistent."""


class EvaluationError(BomgraphError, ValueError):
    """An estimate cannot be scored against the truth (e.g. too few common landmarks)."""


class TooFewLandmarksError(EvaluationError):
    """Fewer than 3 landmarks are common to an estimate and the truth: no alignment exists."""


class UndeterminedAlignmentError(EvaluationError):
    """The points to align do not fix the transform asked for: fewer than 3 common poses for
    a trajectory fit, or every source point at one place for a similarity (no scale)."""


class OutOfRangeError(EvaluationError):
    """Coordinates so large (beyond :data:`bomgraph.evaluate.MAX_SCORED_M`) that their errors
    leave the floating-point range: a diverged estimate, not scored."""


class UnknownMethodError(BomgraphError, KeyError):
    """A method name is not in the registry."""

    def __str__(self) -> str:  # KeyError quotes its message; keep it readable
        return str(self.args[0])


class DatasetError(BomgraphError, ValueError):
    """A recorded dataset file is missing or malformed (names file and line)."""


class DegenerateGeometryError(BomgraphError, ValueError):
    """The geometry does not determine the quantity asked for (no parallax, too few points)."""


class StreamValueError(DegenerateGeometryError):
    """A method cannot use a value of a valid stream (a sigma or a move far beyond what it
    can compute with): names the step ``t`` (None: the header) and the ``key``;
    :meth:`in_file` names the file and the line first, as the reader's refusals do, for a
    caller that read the stream from a file (``bomgraph run``, ``compare``). ``method``: the
    words ``message`` begins with, naming what refused (``"GTSAM"``, ``"the EKF"``), which
    :meth:`in_file` replaces with the method the user ran (h161: a ``hybrid-isam2`` run's
    refusal said "STMDS cannot use", a ``gtsam-isam2`` run's "GTSAM cannot use")."""

    def __init__(self, message: str, *, t: int | None, key: str,
                 path: str | os.PathLike[str] | None = None, line: int | None = None,
                 method: str | None = None) -> None:
        self.t, self.key, self.message, self.path, self.line = t, key, message, path, line
        self.method = method
        if path is None:
            text = f"{'the header' if t is None else f'step {t}'}: '{key}': {message}"
        else:
            text = (f"{shown_path(path)}, line {line}: '{key}': "
                    + ("" if t is None else f"step {t}: ") + message)
        super().__init__(text)

    def __reduce__(self) -> tuple:   # keyword-only arguments: rebuilt from them (a worker's)
        return (_stream_value_error, (self.message, self.t, self.key, self.path, self.line,
                                      self.method), self.__dict__)

    def in_file(self, path: str | os.PathLike[str], line: int,
                method: str | None = None) -> StreamValueError:
        """The same refusal naming ``path`` and ``line`` (the header's, or step ``t``'s) and,
        given ``method``, naming it instead of the words :attr:`method` it begins with."""
        message, named = self.message, self.method
        if method and named and message.startswith(named + " "):
            message, named = method + message[len(named):], method
        located = StreamValueError(message, t=self.t, key=self.key, path=path, line=line,
                                   method=named)
        for note in getattr(self, "__notes__", ()):
            located.add_note(note)
        return located


def _stream_value_error(message: str, t: int | None, key: str,
                        path: str | os.PathLike[str] | None, line: int | None,
                        method: str | None = None) -> StreamValueError:
    return StreamValueError(message, t=t, key=key, path=path, line=line, method=method)


class ExportError(BomgraphError, ValueError):
    """An export that cannot be written as asked (no poses for a pose format, no stream for
    g2o, an output that is one of the inputs)."""


class MethodProtocolError(BomgraphError, TypeError):
    """A method breaks the :class:`~bomgraph.mapper.Mapper` protocol that :func:`run` relies
    on (its factory returns no mapper, its ``estimate()`` returns no ``MapEstimate``): the
    message names the method and what it returned."""


class PairingError(BomgraphError, ValueError):
    """Per-run results that cannot be paired between arms (a run twice for one arm, a
    reference arm that is not in its experiment)."""
