"""The one way tests install a method plugin by hand: a ``.dist-info`` folder with its entry
points, in a folder put on ``sys.path`` or a worker's PYTHONPATH (what ``pip install
--target`` makes)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Iterator

import pytest


def write_dist_info(folder: Path, name: str, methods: dict[str, str],
                    version: str = "0.1") -> Path:
    """``folder/NAME-VERSION.dist-info`` declaring ``methods`` (method name -> ``module:attr``)
    in the entry-point group ``bomgraph.methods``; returns the dist-info folder."""
    dist = folder / f"{name}-{version}.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n")
    (dist / "entry_points.txt").write_text(
        "[bomgraph.methods]\n" + "".join(f"{k} = {v}\n" for k, v in methods.items()))
    return dist


def installed(folder: Path, monkeypatch: pytest.MonkeyPatch, module: str, text: str,
              methods: dict[str, str]) -> Iterator[Path]:
    """For a fixture: the module ``module`` (``text``) and its dist-info declaring ``methods``
    in ``folder``, put first on ``sys.path`` for the test; the module and the plugins' caches
    forgotten after."""
    from bomgraph import plugins

    (folder / f"{module}.py").write_text(text)
    write_dist_info(folder, module, methods)
    monkeypatch.syspath_prepend(str(folder))
    plugins.refresh()
    yield folder
    monkeypatch.undo()
    sys.modules.pop(module, None)
    plugins.refresh()
