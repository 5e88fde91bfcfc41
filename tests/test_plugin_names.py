"""A method name holding '@', ',', ':' or a space is listed by ``bomgraph methods`` but
``compare --methods NAME@PRESET,...`` and ``--option NAME:KEY=VALUE`` split on those, so
compare answered "unknown method 'esl'" for a listed plugin 'esl@x' (h20). Such a name is
now named in a warning, where it is installed or registered; ``run`` still runs it."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest
from _plugin_dist import write_dist_info

from bomgraph import mapper, plugins


def test_an_installed_plugin_with_an_unusable_name_is_warned_about(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    write_dist_info(tmp_path, "badnames", {"esl@x": "m:F", "good-name_2.0": "m:F"})
    monkeypatch.syspath_prepend(str(tmp_path))
    plugins.refresh()
    try:
        with caplog.at_level(logging.WARNING, logger="bomgraph.plugins"):
            found = plugins.discover()
        assert "esl@x" in found and "good-name_2.0" in found  # kept: `run` can use it
        warned = [r.getMessage() for r in caplog.records]
        assert len(warned) == 1 and "badnames" in warned[0]
        assert "method name 'esl@x' holds '@'" in warned[0] and "compare cannot run it" in warned[0]
    finally:
        monkeypatch.undo()
        plugins.refresh()


def test_register_method_warns_about_an_unusable_name(
        monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    with caplog.at_level(logging.WARNING, logger="bomgraph.plugins"):
        mapper.register_method("mine:v2", "toy:F", "x")
        mapper.register_method("mine-v2", "toy:F", "x")
    assert [r.getMessage() for r in caplog.records] == [
        "register_method: method name 'mine:v2' holds ':', which `compare --methods "
        "NAME@PRESET,...` and `--option NAME:KEY=VALUE` split on, so compare cannot run it; "
        "rename it (letters, digits, '-', '_', '.')"]
