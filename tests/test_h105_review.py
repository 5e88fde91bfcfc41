"""h105's review of h104's recording keys (bomgraph.file_digest) and h103's worker warnings
(bomgraph.worker_log).

- ``file_sha256`` judged a file's status racy against the clock after the read, not at the
  status: a read taking seconds (a large file on a network disk) kept a digest whose status a
  write in the same timestamp tick, during the read, leaves unchanged. A fake clock here (no
  timing): the read "takes" 3 s.
- A worker kept every warning a run logged on a ``bomgraph`` logger and sent them all back:
  a method warning 1,000 times a step over 100 steps held 101,000 (4.8 MB pickled, 17 MB
  peak), each identical one too. Now each once, at most ``MAX_KEPT``, and one more counting
  the rest.
"""

from __future__ import annotations

import hashlib
import logging
import types
from pathlib import Path

import numpy as np
import pytest
from _plugin_site import write

from bomgraph import file_digest, mapper, worker_log
from bomgraph.bench import _indexed
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream


def test_a_digest_is_not_kept_when_the_status_was_racy_when_taken(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Fails before: the status, taken 0.5 s after the file's change, was judged after the
    3 s read (3.5 s: aged) and kept."""
    path = tmp_path / "f.dat"
    path.write_bytes(b"x" * 1000)
    st = path.stat()
    clock = [max(st.st_mtime_ns, st.st_ctime_ns) + 500_000_000]

    def slow_digest(fh, name):  # noqa: ANN001, ANN202
        clock[0] += 3_000_000_000
        return hashlib.file_digest(fh, name)

    monkeypatch.setattr(file_digest, "time", types.SimpleNamespace(time_ns=lambda: clock[0]))
    monkeypatch.setattr(file_digest, "hashlib",
                        types.SimpleNamespace(file_digest=slow_digest, sha256=hashlib.sha256))
    file_digest.forget()
    assert file_digest.file_sha256(path) == hashlib.sha256(b"x" * 1000).hexdigest()
    assert str(path) not in file_digest._KEPT
    file_digest.file_sha256(path)  # now 3.5 s after its change: aged, kept
    assert str(path) in file_digest._KEPT
    file_digest.forget()


NOISY = '''
import logging
import numpy as np
from bomgraph.mapper import MapEstimate
_log = logging.getLogger("bomgraph.h105noisy")
class Noisy:
    def __init__(self, header, **options):
        self.k = 0
    def step(self, step):
        for _ in range(50):
            self.k += 1
            _log.warning("step %d: did not converge", self.k)
            _log.warning("the same each time")
    def estimate(self):
        return MapEstimate(np.zeros(0, dtype=np.int64), np.zeros((0, 2)))
'''


def test_a_worker_keeps_a_bounded_number_of_a_runs_warnings(
        plugin_site: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        caplog: pytest.LogCaptureFixture) -> None:
    """Fails before: over 2,000 kept (1,000 of them the same message) for 20 steps, all sent
    back."""
    write(plugin_site / "h105noisy" / "__init__.py", "")
    write(plugin_site / "h105noisy" / "m.py", NOISY)
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    mapper.register_method("h105-noisy", "h105noisy.m:Noisy")
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=20), np.random.default_rng(1)), stream)
    (task,) = Experiment("e", "e", (Arm("h105-noisy", "h105-noisy"),),
                         sources=(FileSource(str(stream)),)).tasks()
    _, res = _indexed(0, task)
    assert res["ok"], res.get("error")
    kept = res[worker_log.SAID]
    assert len(kept) == 100 + 1, len(kept)  # worker_log.MAX_KEPT, and the count of the rest
    messages = [m for _, _, m in kept]
    assert messages.count("the same each time") == 1
    more = messages[-1].split("a run gave ")[1].split(" other warning")[0]
    assert int(more) >= 20 * 50 + 1 - 100, messages[-1]  # the distinct ones not kept
    caplog.clear()  # the run's own records (this is not a worker)
    with caplog.at_level(logging.WARNING, logger="bomgraph"), worker_log.said_once():
        worker_log.say_kept(kept)
    assert len(caplog.records) == 100 + 1
