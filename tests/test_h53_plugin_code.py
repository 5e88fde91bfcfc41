"""The code of a plugin as the runner keys and checks it (h53).

- A worker checks a plugin's package before and after each run; each check listed and read
  every file of it: 20 ms a check on a package of 300 files (800 runs: 33 s of CPU). A file
  is now read again only when its status changed, a folder listed again only when its
  status changed; an edit is still seen at the next check, however it is made.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from bomgraph import plugins


@pytest.fixture
def package(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A plugin package of a few modules in two folders, importable, its files' status
    trusted at once (``RACY_NS`` 0: the tests sleep past the file system's clock tick)."""
    pkg = tmp_path / "site" / "h53pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    for i in range(5):
        (pkg / f"m{i}.py").write_text(f"X = {i}\n")
        (pkg / "sub" / f"s{i}.py").write_text(f"Y = {i}\n")
    monkeypatch.syspath_prepend(str(pkg.parent))
    monkeypatch.setattr(plugins, "RACY_NS", 0, raising=False)
    plugins.refresh()
    yield pkg
    plugins.refresh()
    import sys
    for name in [n for n in sys.modules if n == "h53pkg" or n.startswith("h53pkg.")]:
        del sys.modules[name]


def _fp() -> str | None:
    return plugins.disk_fingerprint("h53pkg.m0:X")


def test_an_unchanged_package_is_not_read_again(package: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    first = _fp()
    reads: list[Path] = []
    read_bytes = Path.read_bytes

    def counted(self: Path) -> bytes:
        reads.append(self)
        return read_bytes(self)

    monkeypatch.setattr(Path, "read_bytes", counted)
    assert _fp() == first and reads == [], f"{len(reads)} files read again"


def _later() -> None:
    time.sleep(0.05)  # past the file system's timestamp tick (a jiffy)


@pytest.mark.parametrize("edit", ["same size, mtime put back", "file added", "file removed",
                                  "folder added", "file renamed"])
def test_every_edit_is_seen_at_the_next_check(package: Path, edit: str) -> None:
    first = _fp()
    _later()
    target = package / "sub" / "s3.py"
    if edit == "same size, mtime put back":
        st = target.stat()
        target.write_text("Y = 9\n")
        os.utime(target, ns=(st.st_atime_ns, st.st_mtime_ns))
        assert target.stat().st_size == st.st_size and target.stat().st_mtime_ns == st.st_mtime_ns
    elif edit == "file added":
        (package / "sub" / "new.py").write_text("Z = 1\n")
    elif edit == "file removed":
        target.unlink()
    elif edit == "folder added":
        (package / "sub" / "deeper").mkdir()
        (package / "sub" / "deeper" / "d.py").write_text("Z = 1\n")
    else:
        target.rename(package / "sub" / "s9.py")
    assert _fp() != first, edit
