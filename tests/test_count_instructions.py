"""``scripts/count_instructions.py``: the child's map digest is the map's, bit for bit, and the
script refuses to overwrite its output (before it looks for valgrind)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "count_instructions.py"


def _child(method: str, run: int) -> str:
    out = subprocess.run([sys.executable, str(SCRIPT), "--child", method, "--run", str(run)],
                         capture_output=True, text=True, check=True).stdout
    return out.strip().splitlines()[-1]


def test_the_child_digest_names_the_map() -> None:
    a, b = _child("ekf", 0), _child("ekf", 0)
    assert a == b and a.startswith("digest ") and a.endswith("landmarks 50")
    assert _child("ekf", 1) != a          # another world, another map
    assert _child("stmds-smacof", 0) != a  # another method, another map


def test_the_digest_of_a_map_without_poses_is_the_same_in_every_process() -> None:
    # stmds-smacof maps without poses: None's bytes were hashed (its address, other in each
    # process), so one tree's runs disagreed with themselves
    a, b = _child("stmds-smacof", 0), _child("stmds-smacof", 0)
    assert a == b and a.endswith("landmarks 50")


def test_an_existing_output_is_refused(tmp_path: Path) -> None:
    out = tmp_path / "counts.json"
    out.write_text("keep me")
    proc = subprocess.run([sys.executable, str(SCRIPT), "--out", str(out)],
                          capture_output=True, text=True)
    assert proc.returncode == 2 and "exists" in proc.stderr
    assert out.read_text() == "keep me"


def test_the_subtracted_run_imports_the_method_and_maps_nothing() -> None:
    """The subtracted run imported gtsam and filterpy but not the method's own module, so
    each count included that import (h50): ``import:METHOD`` imports the method's factory."""
    assert _child("import:gtsam-isam2", 0) == "digest import baselines.isam2"
    assert _child("import:ekf", 0).startswith("digest import baselines.")


def _modules(method: str) -> set[str]:
    """The modules loaded when the child of ``method`` ends."""
    code = (f"import runpy, sys\nrunpy.run_path({str(SCRIPT)!r})['child']({method!r}, 0)\n"
            "print(' '.join(sorted(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    return set(out.strip().splitlines()[-1].split())


def test_the_subtracted_run_imports_all_that_the_run_imports() -> None:
    """``import:hybrid-isam2`` imported the hybrid's module, not its seed's (bomgraph.stmds
    and scipy.sparse.csgraph, 59 modules), which the hybrid imports when it builds its seed:
    each hybrid's count still included that import (h51)."""
    ran, subtracted = _modules("hybrid-isam2"), _modules("import:hybrid-isam2")
    assert "bomgraph.stmds.mapper" in ran
    assert ran - subtracted == set()
