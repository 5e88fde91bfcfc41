"""A sweep file's stream globs, bounded: ``**`` searches every folder below those the part of
its pattern before it names (``/**/*.jsonl``: the whole file system, over 90 s; a folder
holding two links to itself: without end), so a glob with ``**`` counts the folders it would
search first (those below ``runs*`` for ``runs*/**/*.jsonl``, not the folders beside them)
and is refused beyond :data:`MAX_GLOB_FOLDERS`, naming the folder, before it is expanded.
A glob without ``**`` is bounded the same way, level by level: each ``*`` searches every
folder the pattern before it matches (``/*/*/*/*/*.jsonl`` searches some 10,000 folders here;
``loop/*/*/.../*.jsonl`` through a folder holding two links to itself, 2^k paths for k
levels: 3.4 s for 17, an hour for 27), and so are the ``*`` levels before a ``**``
(``loop/*/.../*/x/**/*.jsonl`` expands ``loop/*/.../*/x`` first).
"""

from __future__ import annotations

import glob
import os
from typing import Iterable, Iterator

from .errors import ConfigError, shown_path

#: The most folders a stream glob may search (a recording collection of a few
#: hundred runs in folders of their own is far below; counting that many takes a fraction of
#: a second).
MAX_GLOB_FOLDERS = 10_000


class GlobTooWideError(ConfigError):
    """A glob that would search more than :data:`MAX_GLOB_FOLDERS` folders."""


def _prefix(pattern: str, parts: list[str], i: int) -> str:
    """The folder ``parts[:i]`` of ``pattern`` names (``.`` or ``/`` when none)."""
    return os.sep.join(parts[:i]) or (os.sep if pattern.startswith(os.sep) else os.curdir)


def _head(pattern: str) -> str:
    """The part of ``pattern`` before its first ``**`` (``.`` or ``/`` when none)."""
    parts = pattern.split(os.sep)
    return _prefix(pattern, parts, parts.index("**"))


def _searched_roots(head: str) -> Iterator[str]:
    """The folders a ``**`` after ``head`` searches below: ``head`` as glob expands it
    (``runs*/**/*.jsonl``: each ``runs*`` folder, not the folders beside them)."""
    if glob.has_magic(head):
        yield from (p for p in glob.iglob(head) if os.path.isdir(p))
    else:
        yield head


def _more_folders_than(tops: Iterable[str], limit: int) -> bool:
    """Whether more than ``limit`` folders are at or below ``tops``, counted as ``**``
    searches them (links to folders followed, names starting with ``.`` left out), stopping
    once ``limit + 1`` are found (searched or waiting to be)."""
    stack: list[str] = []
    seen = 0
    for top in tops:
        stack.append(top)
        while stack:
            folder = stack.pop()
            seen += 1
            if seen > limit:
                return True
            try:
                with os.scandir(folder) as entries:
                    for entry in entries:
                        try:
                            if not entry.name.startswith(".") and entry.is_dir():
                                stack.append(entry.path)
                        except OSError:
                            continue
                        if seen + len(stack) > limit:   # each to be searched: memory bounded
                            return True
            except OSError:   # unreadable, gone, not a folder: glob skips it too
                continue
    return False


def _too_wide_level(pattern: str, limit: int) -> str | None:
    """The part of ``pattern`` (without ``**``) before the magic level at which it would
    have searched more than ``limit`` folders in all, or None: each magic level searches the
    folders the part before it matches, counted lazily (stopping at ``limit + 1``), level by
    level, so that a level is expanded only once the levels before it are within bounds."""
    parts = pattern.split(os.sep)
    searched = 0
    for i, part in enumerate(parts):
        if not glob.has_magic(part):
            continue
        prefix = _prefix(pattern, parts, i)
        for _ in _searched_roots(prefix):
            searched += 1
            if searched > limit:
                return prefix
    return None


def bounded_glob(pattern: str, limit: int = MAX_GLOB_FOLDERS) -> list[str]:
    """``glob.glob(pattern, recursive=True)``, sorted, or, for a ``**`` or the ``*`` levels
    of a pattern (those before its ``**``) that would search more than ``limit`` folders,
    :class:`GlobTooWideError` saying how to narrow it."""
    recursive = "**" in pattern.split(os.sep)
    # the levels before a ** are expanded first (``loop/*/.../*/x/**/*.jsonl``): bounded too
    if at := _too_wide_level(_head(pattern) if recursive else pattern, limit):
        raise GlobTooWideError(
            f"the pattern would search more than {limit:,} folders below {shown_path(at)}; "
            f"name more of the folders the streams are in (e.g. 'runs/*/*.jsonl', not "
            f"'/*/*/*/*.jsonl'), or list the files")
    if recursive and _more_folders_than(
            _searched_roots(head := _head(pattern)), limit):
        raise GlobTooWideError(
            f"'**' would search more than {limit:,} folders below {shown_path(head)}; "
            f"start the pattern at the folder the streams are in (e.g. "
            f"'runs/**/*.jsonl', not '/**/*.jsonl'), or list the files")
    return sorted(glob.glob(pattern, recursive=True))


__all__ = ["GlobTooWideError", "MAX_GLOB_FOLDERS", "bounded_glob"]
