"""A package's ``.py`` files as they are on disk: which files a method's package has
(:func:`package_files`, :func:`py_files`) and the digest of each one's contents
(:func:`disk_digest`), what :mod:`bomgraph.plugins` keys a method's code and bomgraph's own
code with.

A worker checks a plugin's package before and after each run, so what is read is kept while
its status stays (:func:`bomgraph.file_digest.cached_read`, the rule every reader of a file's
status follows): a package of 300 files took 7 ms a check when each file was read, and a data
set linked into a package (100,000 files in 100 folders, one being written) 98 ms when it was
listed whole at each check (h64). A file or folder that changed too recently to be trusted is
read again the next time; :func:`forget` forgets everything kept.
"""

from __future__ import annotations

import hashlib
import importlib
import os
import sys
from pathlib import Path

from .file_digest import Status, cached_read, settled_status


def package_files(module_name: str) -> tuple[list[tuple[str, Path]], bool]:
    """The ``.py`` files of the top-level package of ``module_name`` (or its one file), each
    with its name relative to the package folder, in a fixed order; and whether the package
    is spread over several folders.

    Raises
    ------
    ImportError, or what importing the package raises
        The package cannot be imported.
    """
    top = module_name.split(".")[0]
    mod = sys.modules.get(top) or importlib.import_module(top)
    out: list[tuple[str, Path]] = []
    roots = sorted(getattr(mod, "__path__", []) or [])
    for root in roots:
        out += py_files(root)
    if not out and getattr(mod, "__file__", None):
        return [(Path(mod.__file__).name, Path(mod.__file__))], False
    return sorted(out), len(roots) > 1


def py_files(root: str) -> list[tuple[str, Path]]:
    """The ``.py`` files under ``root`` (links to nothing left out: an editor's lock
    ``.#m.py``), each with its path relative to ``root`` (as ``relative_to(root)
    .as_posix()``); a link to a folder of code is followed (a helper folder linked into
    the package is imported through it), unless to a folder already listed or above. Kept
    while no folder's status changed (a file added, removed or renamed in it) since the last
    listing, and each was settled then; otherwise only the folders whose status changed are
    listed again (:func:`_code_entries`)."""
    seen = _LISTED.get(root)
    if seen is not None and all(settled_status(d) == sig for d, sig in seen[0]):
        return list(seen[1])
    out: list[tuple[str, Path]] = []
    folders: list[tuple[str, str]] = [("", root)]
    signatures: list[tuple[str, Status | None]] = []
    real = {os.path.realpath(root)}
    while folders:
        prefix, folder = folders.pop()
        sig, entries = _code_entries(folder)
        signatures.append((folder, sig))
        for name, path, kind in entries:
            if kind == "py":
                out.append((prefix + name, Path(path)))
                continue
            follow, watched = (True, None) if kind == "dir" else _new_folder(path, real)
            if follow:
                folders.append((prefix + name + "/", path))
            elif follow is None:   # watched: code written into it lists it
                signatures.append((path, watched))
    if all(sig is not None for _, sig in signatures):
        _LISTED[root] = (signatures, list(out))
    return out


def _code_entries(folder: str) -> tuple[Status | None, list[tuple[str, str, str]]]:
    """The :func:`~bomgraph.file_digest.settled_status` of ``folder`` and, as listed after
    it, its entries that can be code: ``.py`` files (``"py"``), folders (``"dir"``) and
    links to folders (``"link"``), each as (name, path, kind). Listed again only when its
    status changed or was not settled. None and no entries when it cannot be listed (gone,
    or unreadable, as rglob skips it; or out of file handles): nothing is kept, so it is
    listed again the next time."""
    try:
        return cached_read(_FOLDERS, folder, lambda: _list_code(folder))
    except OSError:
        return None, []


def _list_code(folder: str) -> list[tuple[str, str, str]]:
    out: list[tuple[str, str, str]] = []
    entries = list(os.scandir(folder))
    fold = os.name == "nt"  # .PY is a module there
    for e in entries:  # a data file costs a name's test and its type, read with the name
        try:
            if (e.name.lower() if fold else e.name).endswith(".py") and e.is_file():
                out.append((e.name, e.path, "py"))
            elif e.is_dir():
                out.append((e.name, e.path, "link" if e.is_symlink() else "dir"))
        except OSError:
            continue
    return out


def _new_folder(path: str, real: set[str]) -> tuple[bool | None, Status | None]:
    """Whether to list the folder that the link ``path`` points to: a folder of Python code
    (a ``.py`` file at its top, not a linked data set), not one of ``real`` (those listed)
    nor one above them (a loop); its real path is then added to ``real``. None for a
    folder passed over for holding no code (or unreadable), with the status to watch, as
    the first module written into it (or its permissions given) lists it: the one taken
    before the listing that found no code (one taken after it could hold a module written
    in between, and be kept with a listing without it)."""
    target = os.path.realpath(path)
    if any(target == r or r.startswith(target.rstrip(os.sep) + os.sep) for r in real):
        return False, None
    sig, entries = _code_entries(path)
    if not any(kind == "py" for _, _, kind in entries):
        return None, sig
    real.add(target)
    return True, None


def read(path: Path) -> bytes:
    """The bytes of the file at ``path``; none for a file removed while we read (its name
    alone is then hashed)."""
    try:
        return path.read_bytes()
    except OSError:
        return b""


def digest(data: bytes) -> bytes:
    """The digest of a source file's contents ``data``."""
    return hashlib.sha256(f"{len(data)}\0".encode() + data).digest()


def disk_digest(path: Path) -> bytes:
    """The :func:`digest` of a source file's contents as they are now, read again only when
    its status changed since it was last read or was not settled then: any write changes the
    ctime, which no tool sets (an edit that keeps the size and puts the mtime back, an
    archive's fixed mtimes)."""
    return cached_read(_DISK, path, lambda: digest(read(path)))[1]


def forget() -> None:
    """Forget every listing and digest kept (each is read again)."""
    _DISK.clear()
    _LISTED.clear()
    _FOLDERS.clear()


#: Per folder: :func:`_code_entries`.
_FOLDERS: dict[str, tuple[Status, list[tuple[str, str, str]]]] = {}

#: Per package folder: the status of each of its folders and its listing.
_LISTED: dict[str, tuple[list[tuple[str, Status | None]], list[tuple[str, Path]]]] = {}

#: Per source file: its status and the digest of the contents read after it.
_DISK: dict[Path, tuple[Status, bytes]] = {}


__all__ = ["package_files", "py_files", "read", "digest", "disk_digest", "forget"]
