"""The warnings of a sweep's runs, said once, by the process that runs the sweep.

A worker process (joblib's, Dask's) has no handler of its own: what a run logged there went
to Python's last resort on the worker's stderr, unprefixed, under ``-q`` too, and once for
each worker that read the stream (h103: the stream reader's warning of priors no step
observes, h101, came once per worker and again from the figures' reading, 6 lines for 2
streams). In a worker, :func:`kept_warnings` keeps the warnings a run logs, which go back with
its result (:data:`SAID`); the sweep's process logs them (:func:`say_kept`), each message
once in :func:`said_once`'s block, as the stream reader's own warnings there are."""

from __future__ import annotations

import contextlib
import contextvars
import logging
from typing import Any, Iterable, Iterator

from .tables import counted

#: the key of a worker's result that holds the warnings its run logged (never cached)
SAID = "_worker_warnings"

_SAID: contextvars.ContextVar[set[str] | None] = contextvars.ContextVar(
    "bomgraph_said_once", default=None)

#: A run's distinct warnings kept at most (h105: a method warning once a step kept every one,
#: 101,000 of them 4.8 MB sent back and 17 MB held); the rest are counted, and said as one.
MAX_KEPT = 100


class _Kept(list):  # type: ignore[type-arg]
    """A run's warnings ``(logger, level, message)``, each once, at most :data:`MAX_KEPT`."""

    def __init__(self) -> None:
        super().__init__()
        self.seen: set[tuple[str, int, str]] = set()
        self.dropped = 0

    def keep(self, item: tuple[str, int, str]) -> None:
        if item in self.seen:
            return
        if len(self) >= MAX_KEPT:
            self.dropped += 1
            return
        self.seen.add(item)
        self.append(item)


_KEPT: contextvars.ContextVar[_Kept | None] = contextvars.ContextVar(
    "bomgraph_kept_warnings", default=None)


@contextlib.contextmanager
def said_once() -> Iterator[None]:
    """A message :func:`first_time` has seen in the block is not said again (the outermost
    block's messages: a sweep's inside a compare's)."""
    if _SAID.get() is not None:
        yield
        return
    token = _SAID.set(set())
    try:
        yield
    finally:
        _SAID.reset(token)


def first_time(message: str) -> bool:
    """False for a message said already in :func:`said_once`'s block (True outside one)."""
    said = _SAID.get()
    if said is None:
        return True
    if message in said:
        return False
    said.add(message)
    return True


class OnceInASweep(logging.Filter):
    """A logger's filter: a record said already in :func:`said_once`'s block is dropped."""

    def filter(self, record: logging.LogRecord) -> bool:
        return getattr(record, "said_once", False) or first_time(record.getMessage())


class _Keeper(logging.Handler):
    """On the ``bomgraph`` logger of a worker: a run's warnings kept for its result; others
    to Python's last resort, as before, when nothing else handles them."""

    def emit(self, record: logging.LogRecord) -> None:
        kept = _KEPT.get()
        if kept is not None:
            kept.keep((record.name, record.levelno, record.getMessage()))
        elif not logging.getLogger().handlers and logging.lastResort is not None \
                and record.levelno >= logging.lastResort.level:
            logging.lastResort.handle(record)


@contextlib.contextmanager
def kept_warnings() -> Iterator[list[tuple[str, int, str]]]:
    """In a worker: the warnings (and errors) bomgraph's loggers give in the block (this
    thread's), in the list yielded, not on the worker's stderr: each once, the first
    :data:`MAX_KEPT` of them, and a last one that counts the others."""
    lg = logging.getLogger("bomgraph")
    if not any(isinstance(h, _Keeper) for h in lg.handlers):
        lg.addHandler(_Keeper(logging.WARNING))
    kept = _Kept()
    token = _KEPT.set(kept)
    try:
        yield kept
    finally:
        _KEPT.reset(token)
        if kept.dropped:
            kept.append(("bomgraph", logging.WARNING,
                         f"a run gave {counted(kept.dropped, 'other warning')} than these "
                         f"{MAX_KEPT} (a worker sends back {MAX_KEPT} a run; run it with "
                         f"--jobs 1 to see them all)"))


def say_kept(kept: Iterable[Any]) -> None:
    """Log the warnings a worker's run kept (``(logger, level, message)``) here, each message
    once in :func:`said_once`'s block."""
    for item in kept:
        try:
            name, level, message = item
            name, level, message = str(name), int(level), str(message)
        except (TypeError, ValueError):
            continue
        lg = logging.getLogger(name)
        if lg.isEnabledFor(level) and first_time(message):
            record = lg.makeRecord(name, level, "(worker)", 0, "%s", (message,), None)
            record.said_once = True  # not judged again by an OnceInASweep filter
            lg.handle(record)


__all__ = ["SAID", "OnceInASweep", "first_time", "kept_warnings", "said_once", "say_kept"]
