"""Which stream an estimate was computed from: :class:`StreamIdentity`, the SHA-256 of the
stream's steps and their count, recorded in an estimate file's header (``bomgraph run``) and
checked by ``bomgraph evaluate`` and ``bomgraph export``. Re-exported by
:mod:`bomgraph.estimate_file`."""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from typing import Any, Iterable

from .stream import Step


@dataclass(frozen=True)
class StreamIdentity:
    """Which stream an estimate was computed from: the SHA-256 of its steps and their count.

    The digest is over the steps' canonical lines (``json.dumps(step_to_json(step)) + "\n"``
    each, UTF-8): for a stream file written by bomgraph it is the SHA-256 of the file's bytes
    after the header line (``tail -n +2 s.jsonl | sha256sum``).
    """

    steps_sha256: str
    n_steps: int

    def as_dict(self) -> dict[str, Any]:
        return {"steps_sha256": self.steps_sha256, "n_steps": self.n_steps}


def stream_identity(steps: Iterable[Step]) -> StreamIdentity:
    """The :class:`StreamIdentity` of a sequence of steps (a stream's ``steps``, a reader)."""
    from .stream_file import step_to_json

    h = hashlib.sha256()
    n = 0
    for st in steps:
        h.update((json.dumps(step_to_json(st), allow_nan=False) + "\n").encode("utf-8"))
        n += 1
    return StreamIdentity(h.hexdigest(), n)


def stream_file_identity(path: str | os.PathLike[str]) -> StreamIdentity:
    """The identity of a stream file (read and validated step by step)."""
    from .stream_file import StreamReader

    with StreamReader(path, warn=False) as reader:  # the run's own reader warns
        return stream_identity(reader)


__all__ = ["StreamIdentity", "stream_identity", "stream_file_identity"]
