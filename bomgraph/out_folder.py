"""What ``bomgraph compare`` owns in its output folder, and what it must leave alone.

* the names it writes: :data:`COMPARE_FILES`, :data:`COMPARE_FOLDERS`, file and folder names
  made from experiment, arm and run names (:func:`slug`, :func:`unique_slugs`);
* the inputs it must never overwrite (:func:`refuse_inputs_among_outputs`);
* the manifest of what it wrote (:data:`MANIFEST`), kept as a journal (:class:`OutputRecord`):
  a file is listed, with its size and SHA-256, once written beside its name and before it
  takes that name, so the manifest proves which files of the folder are compare's, after an
  interrupted or killed compare too;
* what it refuses to replace (:meth:`OutputRecord.refuse_foreign`): a file at one of the
  names it would write that the manifest does not show compare wrote, unchanged since (a
  user's ``results.csv``; a folder from a bomgraph older than the manifest);
* what the next compare removes: the files the manifest lists that it does not write again,
  if nobody changed them since, and nothing else (:func:`drop_earlier_outputs`);
* a link to a folder on the way (``estimates/`` linked to a folder on a bigger disk): followed,
  and named in the entries of the files written through it (``via``); they prove a file only
  while the same links lead to the same folders (:func:`_proves`). A link at a file's name is
  never written through.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import random
import time
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

from .claims import remove_leftovers
from .slugs import figure_names, slug, unique_slugs  # re-exported: out_folder.slug
from .experiments import DatasetSource, Experiment, FileSource, Task
from .checks import out_named
from .errors import shown_path
from .stdio import (FolderBusyError, InputTooLargeError, OutputPathError, folder_lock,
                    read_regular_file, write_text)

_log = logging.getLogger(__name__)


#: What :func:`compare` writes into its folder: these files (``example_map.txt`` when the
#: example map cannot be drawn), ``.png`` figures, and files under these sub-folders
#: (``streams/`` is not among them: compare writes there only the streams of simulated and
#: imported runs, never over a stream file it reads, which :func:`write_estimate_files`
#: refuses as it writes). :func:`planned_outputs` names each file.
COMPARE_FILES = ("results.json", "results.csv", "summary.csv", "final_by_run.csv",
                 "paired.csv", "example_map.txt")
RESULT_FILES = COMPARE_FILES[:5]
COMPARE_FOLDERS = ("cache", "estimates")


def figure_paths(out: Path, experiments: Sequence[Experiment]) -> list[Path]:
    """The figures :func:`write_compare_figures` may write (and ``example_map.txt``, which
    stands for the example map when it cannot be drawn)."""
    paths = [out / name for name in figure_names(experiments).values()]
    if any(e.designed for e in experiments):
        paths += [out / "example_map.png", out / "example_map.txt"]
    return paths


def source_hash(task: Task) -> str:
    """A short hash of a task's source: it tells apart the streams a run's arms saw."""
    return hashlib.sha256(json.dumps(task.source.key(), sort_keys=True).encode()).hexdigest()[:8]


def estimate_paths(out: Path, tasks: Sequence[Task]) -> list[tuple[Path, Path | None]]:
    """Where :func:`write_estimate_files` writes each task's estimate and, unless it read a
    stream file the user has, its stream: ``out/estimates/EXPERIMENT/ARM/RUN.est`` and
    ``out/streams/EXPERIMENT/RUN.jsonl`` (a run whose arms saw different streams, e.g. with
    priors, gets its stream's short hash in the name). Names keep letters, digits and
    ``.-_@``, the rest turned to ``_`` (and a name ``.`` or ``..``, :func:`slug`); names that
    coincide so get a short hash each."""
    names: dict[tuple[str, str], set[str]] = {}
    for t in tasks:  # a stream file is not hashed again (it may be gone since its runs)
        if not isinstance(t.source, FileSource):
            names.setdefault((t.experiment, t.source.name), set()).add(source_hash(t))
    exps = unique_slugs([t.experiment for t in tasks])
    arms = {e: unique_slugs([t.arm.label for t in tasks if t.experiment == e]) for e in exps}
    runs = {e: unique_slugs([t.source.name for t in tasks if t.experiment == e]) for e in exps}
    paths: list[tuple[Path, Path | None]] = []
    for t in tasks:
        exp, run = exps[t.experiment], runs[t.experiment][t.source.name]
        est = out / "estimates" / exp / arms[t.experiment][t.arm.label] / f"{run}.est"
        if isinstance(t.source, FileSource):
            paths.append((est, None))
            continue
        stem = (run if len(names[(t.experiment, t.source.name)]) == 1
                else f"{run}-{source_hash(t)}")
        paths.append((est, out / "streams" / exp / f"{stem}.jsonl"))
    return paths


def planned_outputs(out: Path, experiments: Sequence[Experiment], *, estimates: bool,
                    figures: bool) -> list[Path]:
    """Every file :func:`compare` with these settings may write in ``out``, but the cache's
    (named by a hash of the task and the code: a file there is only ever replaced by a result
    of that task, when it is not one)."""
    paths = [out / n for n in RESULT_FILES]
    if estimates:
        tasks = [t for e in experiments for t in e.tasks()]
        paths += [p for pair in estimate_paths(out, tasks) for p in pair if p is not None]
        paths.append(out / "estimates" / "index.csv")
    if figures:
        paths += figure_paths(out, experiments)
    return list(dict.fromkeys(paths))


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
        raise OutputPathError(f"{out_named('out_dir', out)}: is the input {inputs[folder]}; compare writes its "
                              f"results there: choose another folder")
    written = [out / n for n in COMPARE_FILES] + list(out.glob("*.png"))
    for sub in COMPARE_FOLDERS:
        written += [p for p in (out / sub).rglob("*") if not p.is_dir()]
    for path in written:
        real = os.path.realpath(path)
        if real in inputs:
            raise OutputPathError(f"{out_named('out_dir', out)}: compare writes "
                                  f"{shown_path(path)}, which is the input {inputs[real]}; "
                                  f"refusing to overwrite an input: move it or choose another "
                                  f"folder")


#: The record of the files a compare wrote in its folder: each one's path relative to the
#: folder, size, modification time and SHA-256. While compare writes it is a journal (a JSON
#: header line, then one JSON line per file, appended as soon as the file is written); when it
#: is done, one JSON object (``files``: the entries). It proves which files of the folder are
#: compare's, unchanged since: those the next compare may replace, or remove when it does not
#: write them again; nothing else.
MANIFEST = ".bomgraph-compare-files"
_MANIFEST_FORMAT = "bomgraph-compare-files"
_VERSION = 3  # 1: entries without sha256, proved by size and modification time; 2: no via


def _file_id(path: str | os.PathLike[str]) -> tuple[int, int] | None:
    """``(device, inode)`` of an existing file (the same file whatever its name's case or the
    links to it), or None."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino


def _sha256(path: str | os.PathLike[str]) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while chunk := fh.read(2**20):
            h.update(chunk)
    return h.hexdigest()


def _links_on_the_way(out: Path, rel: str) -> dict[str, str]:
    """The folders between ``out`` and ``out/rel`` that are links (a user's ``estimates/`` on
    another disk): each one's path relative to ``out`` -> the real folder it leads to now."""
    parts = Path(rel).parts[:-1]
    subs = [os.path.join(*parts[:i]) for i in range(1, len(parts) + 1)]
    return {sub: os.path.realpath(out / sub) for sub in subs if os.path.islink(out / sub)}


def _plain(rel: str) -> str | None:
    """``rel`` normalised when it names a file under the folder (no ``..``, not absolute)."""
    norm = os.path.normpath(rel)
    if (not rel or os.path.isabs(norm) or norm in (".", "..")
            or norm.startswith(os.pardir + os.sep)):
        return None
    return norm


def _entry(out: Path, path: Path, name: Path | None = None) -> dict[str, Any] | None:
    """``path``'s entry, listed as ``name`` (default ``path``): the file about to take that
    name (its size, modification time and contents stay as it is renamed), and the links to
    folders on the way to it (``via``, when there are)."""
    try:
        st = os.stat(path)
        digest = _sha256(path)
    except OSError:
        return None
    rel = os.path.relpath(path if name is None else name, out)
    entry = {"path": rel, "size": st.st_size, "mtime_ns": st.st_mtime_ns, "sha256": digest}
    if links := _links_on_the_way(out, rel):
        entry["via"] = links
    return entry


def _parse_manifest(data: bytes) -> list[dict[str, Any]] | None:
    """A manifest's entries (either form); None when ``data`` is not a manifest."""
    try:
        text = data.decode("utf-8")
        try:
            obj = json.loads(text)
        except ValueError:  # a journal: its last line may be cut by an interruption
            obj = None
        if isinstance(obj, dict) and "files" in obj:
            head, files = obj, obj["files"]
        else:
            lines = text.splitlines()
            head = json.loads(lines[0]) if lines else None
            files = []
            for line in lines[1:]:
                with contextlib.suppress(ValueError):
                    files.append(json.loads(line))
    except (UnicodeDecodeError, ValueError, RecursionError):
        return None
    if (not isinstance(head, dict) or head.get("format") != _MANIFEST_FORMAT
            or not isinstance(files, list)):
        return None
    return [e for e in files if isinstance(e, dict) and isinstance(e.get("path"), str)
            and isinstance(e.get("size"), int) and isinstance(e.get("mtime_ns"), int)
            and isinstance(e.get("sha256", ""), str) and isinstance(e.get("via", {}), dict)]


def _read_manifest(out: Path) -> list[dict[str, Any]] | None:
    """The manifest's entries: none when there is none; None when the file is there but
    is not one (a foreign or damaged file is never acted on)."""
    path = out / MANIFEST
    if not os.path.lexists(path):
        return []
    try:
        return _parse_manifest(read_regular_file(path))
    except (OSError, InputTooLargeError):
        return None


def _earlier_entries(out: Path) -> list[dict[str, Any]]:
    return _read_manifest(out) or []


def _unchanged(path: str | os.PathLike[str], entry: Mapping[str, Any]) -> bool:
    """Whether ``path`` holds what compare wrote when it listed ``entry``: the same size and
    SHA-256 (an entry of version 1: the same size and modification time)."""
    try:
        st = os.stat(path)
        if st.st_size != entry["size"]:
            return False
        if "sha256" in entry:
            return _sha256(path) == entry["sha256"]
    except OSError:
        return False
    return st.st_mtime_ns == entry["mtime_ns"]


def _proves(out: Path, entry: Mapping[str, Any]) -> bool:
    """Whether ``entry`` proves the file at its path compare's, unchanged (:func:`_unchanged`):
    the path plainly under ``out``, no link at the file's name, and the same links on the way
    leading to the same folders as when it was written. Files reached through a link changed
    since (or made, or removed) are not proved: a copy of compare's files, a folder another
    compare wrote, may hold the same bytes; its stale files are not compare's to remove."""
    rel = _plain(entry["path"])
    if rel is None or os.path.islink(out / rel):
        return False
    return entry.get("via", {}) == _links_on_the_way(out, rel) and _unchanged(out / rel, entry)


def _link_changed(out: Path, rel: str, entry: Mapping[str, Any]) -> str:
    """Why ``entry`` proves no file at ``out/rel`` now that its links on the way differ, and
    what to do, for an error."""
    was, now = entry.get("via", {}), _links_on_the_way(out, rel)
    sub = min(k for k in {*was, *now} if was.get(k) != now.get(k))
    back = (f"link {out / sub} back to {was[sub]}, move away the files there, or choose "
            f"another folder" if sub in was else
            "move away the files there or choose another folder")
    # no via: no link then, or a list of a bomgraph before h80, which named no links (h82)
    then = (f"the earlier compare wrote it when that was a link to {was[sub]}" if sub in was
            else "the earlier compare's list names no link there (it was none, or that "
                 "bomgraph named none)")
    now_is = f"which is a link to {now[sub]}" if sub in now else "now a folder"
    return (f"through {out / sub}, {now_is}: {then}; files reached "
            f"through another link are not proved compare's: {back}")


def _inside(root: str, rel: str) -> str | None:
    """``root/rel`` when it is plainly inside ``root`` (no ``..``, absolute path or link on
    the way), else None."""
    plain = os.path.normpath(os.path.join(root, rel))
    if (not rel or os.path.isabs(rel) or os.path.realpath(plain) != plain
            or not plain.startswith(root + os.sep)):
        return None
    return plain


def _compacted(out: Path, entries: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    """One entry per file still there: the one that proves it as it is (a compare killed
    between a file's line and its rename listed contents that never took the name), else
    the last (the file was changed since: refused as such). Entries of files gone prove
    nothing and go. Every interrupted compare used to copy them all again (h75)."""
    by_path: dict[str, list[Mapping[str, Any]]] = {}
    for e in entries:
        by_path.setdefault(os.path.normpath(e["path"]), []).append(e)
    kept = []
    for rel, listed in by_path.items():
        path = out / rel
        if not os.path.lexists(path):
            continue
        if len(listed) > 1:
            proving = [e for e in listed if _proves(out, e)]
            listed = proving or listed
        kept.append(listed[-1])
    return kept


def _writing(out: Path) -> list[str]:
    """The files an interrupted compare was writing: its journal's header's (none when the
    manifest is a finished one, missing or not one)."""
    try:
        head = json.loads(read_regular_file(out / MANIFEST).split(b"\n", 1)[0].decode("utf-8"))
    except (OSError, InputTooLargeError, UnicodeDecodeError, ValueError, RecursionError):
        return []
    names = head.get("writing") if isinstance(head, dict) else None
    return ([n for n in names if isinstance(n, str)]
            if isinstance(names, list) and head.get("format") == _MANIFEST_FORMAT else [])


class OutputRecord:
    """This compare's :data:`MANIFEST` in ``out``: :meth:`refuse_foreign` before anything
    runs and again before anything is written, :meth:`begin` just before writing, each file
    written with :meth:`ready`'s callback, :meth:`finish` at the end."""

    def __init__(self, out: Path) -> None:
        self.out = out
        self.path = out / MANIFEST
        self.entries: list[dict[str, Any]] = []

    def refuse_foreign(self, paths: Sequence[Path], folders: Sequence[Path] = ()) -> None:
        """Refuse, naming the first, a file at one of ``paths`` (the names this compare may
        write) that the manifest does not show compare wrote, unchanged since: a user's own
        file, or one of a compare without a manifest (an older bomgraph); a link there
        (written through, a file outside the folder was replaced: a user's copy of
        results.csv, moved out and linked back); a file reached through a link to a folder on
        the way that led elsewhere (or was no link) when compare wrote it; a folder there, a
        file or a link to no folder where compare makes a folder (one of ``folders``, or on
        the way to a path). A link to a folder on the way is no reason (``estimates/`` on
        another disk).

        Raises
        ------
        OutputPathError
            Naming the file and what to do: move it or choose another folder.
        """
        out, todo = self.out, "move it or choose another folder"
        listed = _read_manifest(out)
        if listed is None:
            raise OutputPathError(f"{out_named('out_dir', out)}: {shown_path(self.path)} is not "
                                  f"the list of files bomgraph compare keeps there; {todo}")
        by_path: dict[str, list[dict[str, Any]]] = {}
        for e in listed:
            by_path.setdefault(os.path.normpath(e["path"]), []).append(e)
        for folder in [*folders, *sorted({q for p in paths for q in p.parents if out in q.parents})]:
            if os.path.lexists(folder) and not folder.is_dir():
                what = (f"a link to {os.path.realpath(folder)}, which is not a folder"
                        if os.path.islink(folder) else "a file")
                raise OutputPathError(f"{out_named('out_dir', out)}: compare writes a folder "
                                      f"{shown_path(folder)}, which is {what}; {todo}")
        for p in paths:
            if not os.path.lexists(p):
                continue
            if p.is_dir():
                raise OutputPathError(f"{out_named('out_dir', out)}: compare writes the file "
                                      f"{shown_path(p)}, which is a folder; {todo}")
            rel = os.path.normpath(os.path.relpath(p, out))
            if os.path.islink(p):
                raise OutputPathError(f"{out_named('out_dir', out)}: compare would replace "
                                      f"{shown_path(p)}, which is a link to {shown_path(os.path.realpath(p))}"
                                      f" (compare writes through no link at a file's name); {todo}")
            if any(_proves(out, e) for e in by_path.get(rel, ())):
                continue
            links = _links_on_the_way(out, rel)
            if by_path.get(rel) and all(e.get("via", {}) != links for e in by_path[rel]):
                raise OutputPathError(f"{out_named('out_dir', out)}: compare would replace "
                                      f"{shown_path(p)} {_link_changed(out, rel, by_path[rel][-1])}")
            # not listed: never compare's, or changed since and then left out of the list by
            # a compare that did not write it again (h75: "which compare did not write")
            why = ("which was changed since an earlier compare wrote it" if rel in by_path else
                   f"which is not listed as compare's, unchanged, in {shown_path(self.path)}" if listed or
                   os.path.lexists(self.path) else
                   f"which is not listed as compare's (the folder has no {MANIFEST}: not "
                   f"compare's, or an older bomgraph's)")
            raise OutputPathError(f"{out_named('out_dir', out)}: compare would replace {shown_path(p)}, {why}; {todo}")

    def remove_leftovers(self, paths: Sequence[Path]) -> int:
        """Remove the temporary files that compares killed while writing (``kill -9``, a
        power cut) left beside the names compare writes: ``paths`` (this compare's), the
        manifest's, those it lists and those an interrupted compare's journal was writing,
        and nothing else (only names exactly of the writers' pattern,
        :data:`bomgraph.claims.TEMP_NAME`). Call it holding the folder's lock: then no other
        compare is writing them; nor is any other writer of bomgraph (it holds its temporary
        file's lock while it writes: :func:`bomgraph.claims.remove_leftovers`). Only in
        folders plainly inside ``out``: one linked elsewhere may be another folder's, under
        its own lock. The sweep cache's are left here (each cache file's writer removes its
        name's). Returns how many were removed (logged too)."""
        root = os.path.realpath(self.out)
        names: dict[str, set[str]] = {}  # where the writers put them: beside the real path
        for rel in [MANIFEST, *(os.path.relpath(p, self.out) for p in paths),
                    *(e["path"] for e in _earlier_entries(self.out)), *_writing(self.out)]:
            # only plainly inside: a folder linked elsewhere (estimates/ on another disk) may
            # be another compare's, holding another lock, or hold a user's file (h77)
            folder, name = os.path.split(os.path.normpath(rel))
            where = root if not folder else _inside(root, folder)
            if where is not None and name not in ("", ".", "..") and not os.path.isabs(rel):
                names.setdefault(where, set()).add(name)
        removed = sum(remove_leftovers(folder, wanted) for folder, wanted in names.items())
        if removed:
            _log.info("removed %d temporary file(s) that interrupted compares left in %s",
                      removed, self.out)
        return removed

    def begin(self, paths: Sequence[Path] = ()) -> None:
        """The manifest as a journal: a header naming the files this compare may write
        (``paths``: a compare killed before it listed one left its temporary file beside a
        name the next one may neither list nor write, h77), the earlier entries that still
        prove a file (:func:`_compacted`: so an interrupted compare leaves every file of
        compare's still proved, and the journal does not grow with each one), then each file
        as written."""
        writing = sorted(os.path.relpath(p, self.out) for p in paths)
        lines = [json.dumps({"format": _MANIFEST_FORMAT, "version": _VERSION,
                             "writing": writing})]
        lines += [json.dumps(e) for e in _compacted(self.out, _earlier_entries(self.out))]
        write_text(self.path, "\n".join(lines) + "\n")

    def ready(self, path: Path) -> Callable[[str], None]:
        """The ``ready`` of a writer of ``path`` (:func:`bomgraph.stdio.output_file`): it lists
        the finished file, still beside ``path``, in the journal before it replaces ``path``.
        A compare interrupted or killed at any point leaves each file proved: either the one
        listed earlier or the new one (listed after a written file: killed in between, the new
        one was not, and the next compare refused the folder)."""
        def journal(tmp: str) -> None:
            entry = _entry(self.out, Path(tmp), path)
            if entry is None:
                raise OSError(f"cannot read {tmp}, just written")
            with open(self.path, "a", encoding="utf-8") as fh:
                fh.write(json.dumps(entry) + "\n")
                fh.flush()
                os.fsync(fh.fileno())
            self.entries.append(entry)
        return journal

    def finish(self, written: Sequence[Path], experiments: Sequence[Experiment]) -> None:
        """Remove what an earlier compare wrote and this one did not
        (:func:`drop_earlier_outputs`); the manifest lists this compare's files only."""
        drop_earlier_outputs(self.out, written, experiments, self.entries)


def _touched(out: Path, paths: Sequence[Path]) -> list[str]:
    """``paths`` relative to ``out``, and the files of the manifest reached through links that
    still lead where they did (:func:`drop_earlier_outputs` may remove them: a compare without
    ``--estimates`` removes the earlier estimates through the link)."""
    rels = [os.path.relpath(p, out) for p in paths]
    for e in _earlier_entries(out):
        if (rel := _plain(e["path"])) is not None and e.get("via") and (out / rel).is_file():
            rels += [rel] if e["via"] == _links_on_the_way(out, rel) else []  # not: unmounted
    return rels


def linked_folders(out: Path, paths: Sequence[Path]) -> dict[str, Path]:
    """The real folders that links on the way to ``paths`` (:func:`_touched`) lead to
    (``out/estimates`` linked to another disk), ``out``'s own left out: each -> the first link
    to it. ``compare`` locks them as it locks ``out``: another folder's compare may write one
    through a link too. One folder reached by two real paths (a bind mount; names differing in
    case on a case-insensitive disk) is named once, and not at all when it is ``out``: compare
    locked it twice and refused itself (h82)."""
    seen, found = {_file_id(out)}, {}
    for rel in _touched(out, paths):
        for sub, real in _links_on_the_way(out, rel).items():
            if (i := _file_id(real)) not in seen or i is None:  # refused: no lock file
                seen.add(i)
                found.setdefault(real, out / sub)
    return found


def folders_below_locked(out: Path, rels: Sequence[str], held: set[Any]) -> dict[str, str]:
    """The folders ``compare`` writes below that hold a lock file (another compare writes into
    one, or through a link into one), but those of ``held`` (``(device, inode)``, added to it):
    on the real way to the files ``rels`` (:func:`_touched`) from ``/``. Each -> the folder
    compare writes into below it; outermost first. Before h100 only a folder above a linked one
    holding a manifest; before h120 none above ``out`` unless through a link: one into ``x/e``
    ran beside one into ``x --estimates`` that held ``x`` (refused the other way round)."""
    found: dict[str, str] = {}
    for sub in dict.fromkeys(os.path.dirname(rel) for rel in rels):
        real = Path(os.path.realpath(out / sub))
        for q in [real, *real.parents]:
            if os.path.lexists(q / ".bomgraph.lock") and (i := _file_id(q)) not in held:
                held.add(i)
                found[str(q)] = str(real)
    return dict(sorted(found.items(), key=lambda kv: len(Path(kv[0]).parts)))


LOCK_RETRIES, RETRY_S = 3, 0.1  # compare_locks' tries after the first; pauses: RETRY_S * 2**k
_JITTER = random.Random()  # its pauses' own: a user's random.seed sequence is left alone


@contextlib.contextmanager
def compare_locks(out: Path, paths: Sequence[Path]) -> Iterator[None]:
    """Hold what ``compare`` writing ``paths`` into ``out`` locks (:func:`folder_lock`):
    ``out`` and its :func:`linked_folders` exclusive, :func:`folders_below_locked` shared (a
    compare into a folder above is kept out, two writing into two of its subfolders run side
    by side: stop 43's CI). Those are looked for again once the exclusive ones are held: of
    two compares that may write one file, the second to start finds the other's lock (h100).
    First too: one refused there leaves no lock file in a folder it links to. Refused at
    ``out``: at once; after (maybe by one that holds it only while refused by ours): all let
    go, and taken again. Two compares that each held what the other wanted (each linked into
    the other's folder, starting at once) were both refused, neither ran (h110)."""
    who = "`bomgraph compare`"
    for attempt in range(LOCK_RETRIES + 1):
        with folder_lock(out, who), contextlib.ExitStack() as stack:
            try:
                _lock_the_rest(out, paths, stack, who)
            except FolderBusyError:
                if attempt == LOCK_RETRIES:
                    raise
            else:
                yield
                return
        time.sleep(_JITTER.uniform(0, RETRY_S * 2**attempt))  # let go: the other one's turn


def _lock_the_rest(out: Path, paths: Sequence[Path], stack: contextlib.ExitStack,
                   who: str) -> None:  # compare_locks' but out's, into stack
    linked, rels = linked_folders(out, paths), _touched(out, paths)
    held = {_file_id(out), *(_file_id(real) for real in linked)}

    def below() -> None:
        for folder, into in folders_below_locked(out, rels, held).items():
            stack.enter_context(folder_lock(folder, f"{who} (into it, or through a link into "
                                                    f"it; this one writes into {into})",
                                            shared=True))
    below()
    for real, link in linked.items():  # two folders may link one
        stack.enter_context(folder_lock(real, f"{who} (into it, or through a link into it "
                                              f"as {link} is one)"))
    below()


def drop_earlier_outputs(out: Path, written: Sequence[Path],
                         experiments: Sequence[Experiment],
                         entries: Sequence[Mapping[str, Any]] | None = None) -> None:
    """Remove the files the previous compare in ``out`` wrote (its :data:`MANIFEST`) that this
    one did not write (estimate files, streams, figures of other arms, runs or experiments:
    beside this compare's results they would no longer match them), then record this one's
    (``entries``: :meth:`OutputRecord.add`'s, else taken from ``written`` now).

    Left alone: a file compare did not write (a user's own figure in the folder); one changed
    since compare wrote it (its size or SHA-256 differ); one this compare wrote or
    reads (compared as files, not names: a case-insensitive disk or a link is no escape); any
    entry that is not plainly under ``out`` (``..``, an absolute path) or that the links on
    its way no longer prove (:func:`_proves`). Folders the removals empty go too, up to
    ``out`` or a link (a linked folder stays, and so does the link). A removal that fails is
    logged, never raised: the results are written by then.
    """
    keep = {i for p in [*written, *input_paths(experiments)] if (i := _file_id(p)) is not None}
    for entry in _earlier_entries(out):
        rel = _plain(entry["path"])
        if rel is None or not (path := out / rel).is_file():
            continue
        if _file_id(path) in keep or not _proves(out, entry):
            continue
        try:
            path.unlink()
            parent = path.parent
            while parent != out and not parent.is_symlink() and not any(parent.iterdir()):
                parent.rmdir()
                parent = parent.parent
        except OSError as exc:
            _log.warning("could not remove %s, an earlier compare's output: %s", path, exc)
    if entries is None:
        entries = [e for p in written if (e := _entry(out, p)) is not None]
    write_text(out / MANIFEST, json.dumps({"format": _MANIFEST_FORMAT, "version": _VERSION,
                                           "files": list(entries)}, indent=0) + "\n")


__all__ = ["COMPARE_FILES", "COMPARE_FOLDERS", "MANIFEST", "OutputRecord", "RESULT_FILES",
           "compare_locks", "drop_earlier_outputs", "estimate_paths", "figure_paths",
           "folders_below_locked", "input_paths", "linked_folders", "planned_outputs",
           "refuse_inputs_among_outputs", "slug", "source_hash", "unique_slugs"]
