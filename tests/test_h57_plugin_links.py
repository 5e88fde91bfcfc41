"""h56's listing of a plugin package follows a link to a folder only when the folder holds a
``.py`` at its top; the listing is kept while no listed folder's status moves. A linked
folder passed over (no code yet) must be watched too: the first module written into it is
code of the package."""

from __future__ import annotations

import os
import time
from pathlib import Path

from _plugin_site import write

from bomgraph import plugins


def test_code_written_into_a_linked_folder_passed_over_moves_the_key(
        plugin_site: Path, tmp_path: Path) -> None:
    write(plugin_site / "h57lk" / "__init__.py", "")
    # imports by name: its key is the whole package's
    write(plugin_site / "h57lk" / "m.py",
          "import importlib\nclass M:\n    X = importlib.import_module\n")
    (tmp_path / "helpers").mkdir()
    write(tmp_path / "helpers" / "notes.txt", "not code yet\n")
    os.symlink(tmp_path / "helpers", plugin_site / "h57lk" / "helpers")
    before = plugins.disk_fingerprint("h57lk.m:M")
    assert plugins.disk_fingerprint("h57lk.m:M") == before
    time.sleep(0.05)  # past the file system's clock tick: the folder's status moves
    write(tmp_path / "helpers" / "util.py", "SCALE = 2\n")
    assert plugins.disk_fingerprint("h57lk.m:M") != before, "helpers/util.py is in no key"
