"""A plugin's key and loaded-code check in cases h53's review (h56) found wrong.

- A package with a linked folder (``mypkg/shared -> ../shared``, a helper folder linked into
  two plugins): the listing followed no link to a folder, so the linked modules were in no
  key: an edit of them, or of a method module inside one, re-ran nothing (a stale cached
  result).
- An editor's lock file (Emacs: ``.#bench.py``, a link to nothing) in bomgraph's or a
  plugin's folder: ``code_fingerprint`` read it and every sweep failed with
  ``No such file or directory``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bomgraph import plugins


@pytest.fixture
def site(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    root = tmp_path / "site"
    root.mkdir()
    monkeypatch.syspath_prepend(str(root))
    monkeypatch.setattr(plugins, "RACY_NS", 0)
    plugins.refresh()
    yield root
    plugins.refresh()
    for name in [n for n in sys.modules if n.split(".")[0] in ("h56ln", "h56lo")]:
        del sys.modules[name]


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


@pytest.mark.parametrize("target, edited", [("h56ln.m:M", "shared/h.py"),
                                            ("h56ln.inner.m:M", "inner/m.py")])
def test_an_edit_in_a_linked_folder_of_the_package_moves_the_key(
        site: Path, tmp_path: Path, target: str, edited: str) -> None:
    _write(site / "h56ln" / "__init__.py", "")
    _write(site / "h56ln" / "m.py", "from .shared.h import K\nclass M: pass\n")
    _write(tmp_path / "shared" / "__init__.py", "")
    _write(tmp_path / "shared" / "h.py", "K = 1\n")
    _write(tmp_path / "inner" / "__init__.py", "")
    _write(tmp_path / "inner" / "m.py", "class M: pass\n")
    os.symlink(tmp_path / "shared", site / "h56ln" / "shared")
    os.symlink(tmp_path / "inner", site / "h56ln" / "inner")
    os.symlink(site, site / "h56ln" / "loop")  # a link up the tree is not followed
    before = plugins.disk_fingerprint(target)
    time.sleep(0.05)
    (tmp_path / edited).write_text((tmp_path / edited).read_text() + "K = 2\n")
    assert plugins.disk_fingerprint(target) != before, f"an edit of {edited} re-ran nothing"


def test_a_link_to_nothing_named_py_is_not_read(site: Path) -> None:
    _write(site / "h56lo" / "__init__.py", "")
    # imports by name: its key is the whole package's
    _write(site / "h56lo" / "m.py", "import importlib\nclass M:\n    X = importlib.import_module\n")
    before = plugins.disk_fingerprint("h56lo.m:M")
    time.sleep(0.05)  # past the file system's clock tick: the folder's status moves
    os.symlink("user@host.1234:1700000000", site / "h56lo" / ".#m.py")  # Emacs's lock
    assert plugins.disk_fingerprint("h56lo.m:M") == before


def test_bomgraphs_key_reads_no_link_to_nothing(tmp_path: Path) -> None:
    """In a copy of the sources (bomgraph's own folder is never touched)."""
    repo = Path(__file__).resolve().parents[1]
    for pkg in ("bomgraph", "baselines"):
        subprocess.run(["cp", "-r", str(repo / pkg), str(tmp_path / pkg)], check=True)
    os.symlink("user@host.1234:1700000000", tmp_path / "baselines" / ".#triangulate.py")
    out = subprocess.run([sys.executable, "-c", "from bomgraph import plugins as p\n"
                          "print(p.code_fingerprint(), p.code_changed())"],
                         cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(tmp_path)},
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-300:]
    assert out.stdout.split()[1] == "False"
