"""A folder of plugin packages on ``sys.path`` for the tests of a plugin's key (the
``plugin_site`` fixture of ``conftest.py``), and the helper that writes their files."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Iterator

import pytest

from bomgraph import file_digest, plugins


def write(path: Path, text: str) -> None:
    """Write ``text`` to ``path``, making its folders."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def plugin_site(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """``tmp_path/site``, put first on ``sys.path``, with the plugins' caches forgotten before
    and after and their files' status trusted at once (``file_digest.RACY_NS`` 0: the tests
    sleep past the file system's clock tick); the modules imported from it are forgotten
    after."""
    root = tmp_path / "site"
    root.mkdir()
    monkeypatch.syspath_prepend(str(root))
    monkeypatch.setattr(file_digest, "RACY_NS", 0)
    plugins.refresh()
    yield root
    plugins.refresh()
    for name, module in list(sys.modules.items()):
        where = [getattr(module, "__file__", None), *(getattr(module, "__path__", None) or [])]
        if any(isinstance(w, str) and Path(w).is_relative_to(root) for w in where):
            del sys.modules[name]
