"""A data set linked into a plugin's package (``mypkg/data -> /data``, 100,000 files in 100
folders, a ``convert.py`` at its top so it is followed) was listed whole at each check of the
package (a worker checks before and after each run) as soon as one of its folders changed:
98 ms a check while data were being written into it. Each folder's listing is now kept by its
own status: only the folder written is listed again (h64)."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
from _plugin_site import write

from bomgraph import plugins


def test_a_write_into_a_linked_data_folder_lists_that_folder_alone(
        plugin_site: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    write(plugin_site / "h64ls" / "__init__.py", "")
    # imports by name: its key is the whole package's
    write(plugin_site / "h64ls" / "m.py",
          "import importlib\nclass M:\n    X = importlib.import_module\n")
    data = tmp_path / "data"
    write(data / "convert.py", "X = 1\n")  # code at its top: followed
    for d in range(20):
        for i in range(5):
            write(data / f"d{d:02d}" / f"f{i}.csv", "1\n")
    os.symlink(data, plugin_site / "h64ls" / "data")
    before = plugins.disk_fingerprint("h64ls.m:M")
    listed: list[str] = []
    scandir = os.scandir

    def counted(path: str) -> object:
        listed.append(os.path.basename(path))
        return scandir(path)

    monkeypatch.setattr(os, "scandir", counted)
    time.sleep(0.05)  # past the file system's clock tick: the folder's status moves
    write(data / "d07" / "new.csv", "1\n")
    assert plugins.disk_fingerprint("h64ls.m:M") == before
    assert listed == ["d07"], f"{len(listed)} folders listed again: {listed[:5]}"
    listed.clear()
    time.sleep(0.05)
    write(data / "d07" / "tool.py", "Y = 2\n")  # code written there is still seen
    assert plugins.disk_fingerprint("h64ls.m:M") != before
    assert listed == ["d07"], listed
