"""A method registered at run time from a module written into the test's folder (its source
given as text), with the registry and the kept reference maps restored after the test: the
fixtures of the compare-reference tests (h63, h72) and the run-once tests (h71, h74, h76)."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path
from types import ModuleType
from typing import Iterator

import pytest

from bomgraph import mapper, run_scoring


def runtime_method(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, name: str, module: str,
                   source: str, cls: str, description: str = "") -> Iterator[ModuleType]:
    """Write ``source`` as ``module``, register its class ``cls`` as method ``name`` (with
    ``description``); yield the module (for a fixture to loop over), then forget it."""
    code = tmp_path / "code"
    code.mkdir(exist_ok=True)
    (code / f"{module}.py").write_text(source)
    monkeypatch.syspath_prepend(str(code))
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    monkeypatch.setattr(run_scoring, "_REFERENCES", {})
    mapper.register_method(name, f"{module}:{cls}", description)
    try:
        yield importlib.import_module(module)
    finally:
        sys.modules.pop(module, None)
