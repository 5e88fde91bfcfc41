"""Which stream an estimate was computed from: :class:`StreamIdentity`, the SHA-256 of the
stream's steps and their count, recorded in an estimate file's header (``bomgraph run``) and
checked by ``bomgraph evaluate`` and ``bomgraph export``. Re-exported by
:mod:`bomgraph.estimate_file`."""

from __future__ import annotations

import hashlib
import json
import os
import weakref
from dataclasses import dataclass
from typing import Any, Iterable, Iterator

from .checks import is_integer
from .errors import ConfigError
from .stream import Step, Stream


@dataclass(frozen=True)
class StreamIdentity:
    """Which stream an estimate was computed from: the SHA-256 of its steps and their count.

    The digest is over the steps' canonical lines (``json.dumps(step_to_json(step)) + "\n"``
    each, UTF-8): for a stream file written by bomgraph it is the SHA-256 of the file's bytes
    after the header line (``tail -n +2 s.jsonl | sha256sum``).
    """

    steps_sha256: str
    n_steps: int

    def __post_init__(self) -> None:  # what an estimate file's reader accepts
        if not (isinstance(self.steps_sha256, str) and len(self.steps_sha256) == 64):
            raise ConfigError(f"StreamIdentity: steps_sha256 must be the 64 hex digits of a "
                              f"SHA-256 (stream_identity(steps) makes it), got "
                              f"{self.steps_sha256!r:.70}")
        if not (is_integer(self.n_steps) and self.n_steps >= 0):
            raise ConfigError(f"StreamIdentity: n_steps must be an integer >= 0, got "
                              f"{self.n_steps!r:.40}")

    def as_dict(self) -> dict[str, Any]:
        return {"steps_sha256": self.steps_sha256, "n_steps": self.n_steps}


def stream_identity(steps: Iterable[Step]) -> StreamIdentity:
    """The :class:`StreamIdentity` of a sequence of steps (a stream's ``steps``, a reader)."""
    if isinstance(steps, (str, os.PathLike)) or hasattr(steps, "steps") \
            or not isinstance(steps, Iterable):
        hint = (" (stream_file_identity(path) for a file)" if isinstance(steps, (str, os.PathLike))
                else " (pass stream.steps)" if hasattr(steps, "steps") else "")
        raise ConfigError(f"stream_identity(): steps must be an iterable of Step, got "
                          f"{type(steps).__name__}{hint}")
    hasher = StreamHasher()
    for st in steps:
        if not isinstance(st, Step):
            raise ConfigError(f"stream_identity(): step {hasher.n} is a {type(st).__name__}, "
                              f"not a bomgraph.stream.Step")
        hasher.add(st)
    return hasher.identity


#: the identities :func:`identity_of_stream` worked out, by ``id(stream)``: (a weak reference
#: to the stream, its identity); an entry goes with its stream
_OF_STREAM: dict[int, tuple["weakref.ref[Stream]", StreamIdentity]] = {}


def identity_of_stream(stream: Stream) -> StreamIdentity:
    """``stream_identity(stream.steps)``, worked out once per :class:`Stream` object: a
    compare with ``--estimates`` writes one estimate file per arm on the same (kept) stream,
    and hashing its steps for each cost a third of reading it. A stream cannot change (frozen,
    its steps a tuple of steps with read-only arrays)."""
    if not isinstance(stream, Stream):
        raise ConfigError(f"identity_of_stream(): stream must be a Stream, got "
                          f"{type(stream).__name__}")
    key = id(stream)
    kept = _OF_STREAM.get(key)
    if kept is not None and kept[0]() is stream:
        return kept[1]
    ident = stream_identity(stream.steps)
    _OF_STREAM[key] = (weakref.ref(stream, lambda _, k=key: _OF_STREAM.pop(k, None)), ident)
    return ident


class StreamHasher:
    """:func:`stream_identity` step by step: :meth:`add` each step in order, then read
    :attr:`identity` (for a reader that does more with the steps than hash them)."""

    def __init__(self) -> None:
        self._h = hashlib.sha256()
        self.n = 0

    def add(self, step: Step) -> None:
        from .stream_file import step_to_json

        self._h.update((json.dumps(step_to_json(step), allow_nan=False) + "\n").encode("utf-8"))
        self.n += 1

    def through(self, steps: Iterable[Step]) -> Iterator[Step]:
        """The steps, each added as it is passed on (hashed as a run reads them)."""
        for st in steps:
            self.add(st)
            yield st

    @property
    def identity(self) -> StreamIdentity:
        return StreamIdentity(self._h.hexdigest(), self.n)


def stream_file_identity(path: str | os.PathLike[str]) -> StreamIdentity:
    """The identity of a stream file (read and validated step by step)."""
    from .stream_file import StreamReader

    with StreamReader(path, warn=False) as reader:  # the run's own reader warns
        return stream_identity(reader)


__all__ = ["StreamIdentity", "StreamHasher", "stream_identity", "identity_of_stream",
           "stream_file_identity"]
