"""What ``bomgraph compare`` owns in its output folder, and what it must leave alone.

* the names it writes: :data:`COMPARE_FILES`, :data:`COMPARE_FOLDERS`, file and folder names
  made from experiment, arm and run names (:func:`slug`, :func:`unique_slugs`);
* the inputs it must never overwrite (:func:`refuse_inputs_among_outputs`);
* the manifest of what it wrote (:data:`MANIFEST`): the next compare in the folder removes the
  files of it that it does not write again, if nobody changed them since, and nothing else
  (:func:`drop_earlier_outputs`).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import re
from pathlib import Path
from typing import Any, Sequence

from .experiments import DatasetSource, Experiment, FileSource
from .stdio import InputTooLargeError, OutputPathError, read_regular_file, write_text

_log = logging.getLogger(__name__)


#: What :func:`compare` writes into its folder: these files, every ``.png`` there, and
#: everything under these sub-folders (``streams/`` is not among them: compare writes there
#: only the streams of simulated and imported runs, never over a stream file it reads, which
#: :func:`write_estimate_files` refuses as it writes).
COMPARE_FILES = ("results.json", "results.csv", "summary.csv", "final_by_run.csv",
                 "paired.csv", "example_map.txt")
COMPARE_FOLDERS = ("cache", "estimates")


def input_paths(experiments: Sequence[Experiment]) -> dict[str, str]:
    """The stream files and recordings ``experiments`` read: real path -> path as given."""
    inputs: dict[str, str] = {}
    for e in experiments:
        for src in e.sources:
            paths = ([src.path] if isinstance(src, FileSource) else
                     [src.path, src.truth_path] if isinstance(src, DatasetSource) else [])
            inputs.update((os.path.realpath(p), str(p)) for p in paths if p is not None)
    return inputs


def refuse_inputs_among_outputs(out: Path, experiments: Sequence[Experiment]) -> None:
    """Refuse, before anything runs, a stream file or recording that ``compare`` would
    overwrite in ``out``: one of :data:`COMPARE_FILES`, a ``.png`` in it or a file under one
    of :data:`COMPARE_FOLDERS`, or a link there to an input (outputs follow links).

    Raises
    ------
    OutputPathError
        Naming the input and what to do.
    """
    inputs = input_paths(experiments)
    if not inputs or not out.is_dir():
        return
    folder = os.path.realpath(out)
    if folder in inputs:
        raise OutputPathError(f"--out {out}: is the input {inputs[folder]}; compare writes its "
                              f"results there: choose another folder")
    written = [out / n for n in COMPARE_FILES] + list(out.glob("*.png"))
    for sub in COMPARE_FOLDERS:
        written += [p for p in (out / sub).rglob("*") if not p.is_dir()]
    for path in written:
        real = os.path.realpath(path)
        if real in inputs:
            raise OutputPathError(f"--out {out}: compare writes {path}, which is the input "
                                  f"{inputs[real]}; refusing to overwrite an input: move it "
                                  f"or choose another folder")


#: The files a compare wrote in its folder, written last (JSON: each file's path relative to
#: the folder, size and modification time): the next compare there removes those it does not
#: write again and nobody changed since, and nothing else.
MANIFEST = ".bomgraph-compare-files"
_MANIFEST_FORMAT = "bomgraph-compare-files"


def _file_id(path: str | os.PathLike[str]) -> tuple[int, int] | None:
    """``(device, inode)`` of an existing file (the same file whatever its name's case or the
    links to it), or None."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino


def _earlier_entries(out: Path) -> list[dict[str, Any]]:
    """The previous manifest's entries; none if it is missing or not one (a foreign or
    damaged file is never acted on)."""
    try:
        obj = json.loads(read_regular_file(out / MANIFEST).decode("utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError, InputTooLargeError):
        return []
    if not isinstance(obj, dict) or obj.get("format") != _MANIFEST_FORMAT:
        return []
    files = obj.get("files")
    if not isinstance(files, list):
        return []
    return [e for e in files if isinstance(e, dict) and isinstance(e.get("path"), str)
            and isinstance(e.get("size"), int) and isinstance(e.get("mtime_ns"), int)]


def drop_earlier_outputs(out: Path, written: Sequence[Path],
                         experiments: Sequence[Experiment]) -> None:
    """Remove the files the previous compare in ``out`` wrote (its :data:`MANIFEST`) that this
    one did not write (estimate files, streams, figures of other arms, runs or experiments:
    beside this compare's results they would no longer match them), then record this one's.

    Left alone: a file compare did not write (a user's own figure in the folder); one changed
    since compare wrote it (its size or modification time differ); one this compare wrote or
    reads (compared as files, not names: a case-insensitive disk or a link is no escape); any
    entry that is not plainly inside ``out`` (``..``, an absolute path, a link on the way).
    Folders the removals empty go too. A removal that fails is logged, never raised: the
    results are written by then.
    """
    root = os.path.realpath(out)
    keep = {i for p in [*written, *input_paths(experiments)] if (i := _file_id(p)) is not None}
    for entry in _earlier_entries(out):
        rel = entry["path"]
        plain = os.path.normpath(os.path.join(root, rel))
        path = Path(plain)
        if (not rel or os.path.isabs(rel) or os.path.realpath(plain) != plain
                or not plain.startswith(root + os.sep) or not path.is_file()):
            continue
        st = path.stat()
        if (st.st_dev, st.st_ino) in keep or (st.st_size, st.st_mtime_ns) != (
                entry["size"], entry["mtime_ns"]):
            continue
        try:
            path.unlink()
            parent = path.parent
            while str(parent) != root and not any(parent.iterdir()):
                parent.rmdir()
                parent = parent.parent
        except OSError as exc:
            _log.warning("could not remove %s, an earlier compare's output: %s", path, exc)
    entries = []
    for p in written:
        try:
            st = os.stat(p)
        except OSError:
            continue
        entries.append({"path": os.path.relpath(p, out), "size": st.st_size,
                        "mtime_ns": st.st_mtime_ns})
    write_text(out / MANIFEST, json.dumps({"format": _MANIFEST_FORMAT, "version": 1,
                                           "files": entries}, indent=0) + "\n")


def slug(name: str) -> str:
    """``name`` as a file or folder name: letters, digits, ``.``, ``-``, ``_``, ``@``, the
    rest ``_``."""
    return re.sub(r"[^A-Za-z0-9._@-]+", "_", name).strip("_") or "_"


def unique_slugs(names: Sequence[str]) -> dict[str, str]:
    """Each name's :func:`slug`; names whose slugs coincide, or differ in case only (``tri
    (x)`` and ``tri_x``, ``EKF`` and ``ekf``), get their own short hash appended, so no two
    share a file."""
    slugs = {n: slug(n) for n in dict.fromkeys(names)}
    folded = [v.casefold() for v in slugs.values()]    # one file on a case-insensitive disk
    return {n: (f"{v}-{hashlib.sha256(n.encode()).hexdigest()[:8]}"
                if folded.count(v.casefold()) > 1 else v) for n, v in slugs.items()}


__all__ = ["COMPARE_FILES", "COMPARE_FOLDERS", "MANIFEST", "drop_earlier_outputs",
           "input_paths", "refuse_inputs_among_outputs", "slug", "unique_slugs"]
