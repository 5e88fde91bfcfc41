"""A plugin whose module raises while it is imported (a SyntaxError, a dataclass with a
mutable default, any module-level error) is one line naming the method, the exception and
its place, like a plugin with a missing import: before (h20) ``bomgraph methods`` listed
nothing and ``run`` / ``compare`` printed the import's traceback (exit 1)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from bomgraph import mapper
from bomgraph.cli import main
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream

BAD_DATACLASS = '''\
from dataclasses import dataclass


@dataclass(frozen=True)
class Config:
    PRESETS: dict = {"paper": {}}


class Mapper:
    pass
'''


@pytest.fixture
def broken(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    pkg = tmp_path / "h20broken"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "syntax.py").write_text("class Mapper:\n    x = (\n")
    (pkg / "dataclass.py").write_text(BAD_DATACLASS)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    for mod in ("syntax", "dataclass"):
        mapper.register_method(f"h20-{mod}", f"h20broken.{mod}:Mapper", "")
        monkeypatch.delitem(sys.modules, f"h20broken.{mod}", raising=False)
    return pkg


def test_a_plugin_that_raises_on_import_is_one_line(
        broken: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["methods"]) == 0
    listing = capsys.readouterr().out
    assert "triangulate" in listing
    assert "importing it raised SyntaxError: '(' was never closed (syntax.py, line 2)" in listing
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=5), np.random.default_rng(0)), stream)
    assert main(["run", str(stream), "--method", "h20-dataclass",
                 "--out", str(tmp_path / "e.est")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert ("importing it raised ValueError: mutable default <class 'dict'> for field PRESETS "
            "is not allowed") in err[0]
    assert f"(at {broken / 'dataclass.py'}, line " in err[0]
    assert main(["compare", "--streams", str(stream), "--methods", "h20-syntax,triangulate",
                 "--jobs", "1", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "SyntaxError" in err[0]
