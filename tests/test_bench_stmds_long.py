"""``scripts/bench_stmds_long.py``: one line per stream with the CPU time and a hash of every
checkpoint's map, the same hash run after run and at either cadence's own maps."""

from __future__ import annotations

import re
from pathlib import Path

from bomgraph.sim import SimConfig, paper_design, simulate_run
from bomgraph.stream_file import write_stream

from _scripts import load_script


def test_prints_cpu_and_a_stable_map_hash(tmp_path: Path, capsys) -> None:
    path = tmp_path / "sim.jsonl"
    write_stream(simulate_run(paper_design(0)[0], SimConfig(n_steps=60)), path)
    mod = load_script("bench_stmds_long")
    hashes = []
    for every in ("0", "0", "10"):
        assert mod.main([str(path), "--every", every, "--steps", "55"]) == 0
        line = capsys.readouterr().out.strip()
        m = re.fullmatch(r"sim\.jsonl: 55 steps, stmds-smacof@real, every (end|10): CPU "
                         r"[0-9.]+ s, \d+ landmarks, maps sha256 ([0-9a-f]{16})", line)
        assert m, line
        hashes.append(m.group(2))
    assert hashes[0] == hashes[1]          # the same bits run after run
    assert hashes[2] != hashes[0]          # every 10 hashes six maps, end only one
