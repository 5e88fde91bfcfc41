"""h113, a review of h109 (a recording's cache key is the SHA-256 of the files its importer
reads): a recording's input that is not a regular file (a FIFO, a device) was keyed by what it
is, not by its bytes, so a FIFO fed other data later was served the old result from the cache;
and computing a key imported scipy.optimize (through the g2o importer's calibration)."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from dataset_excerpts import write_g2o

from bomgraph.bench import Executor, execute_counted, task_key
from bomgraph.errors import ConfigError, DatasetError
from bomgraph.experiments import Arm, Task
from bomgraph.sources import DatasetSource

ARM = Arm("tri", "triangulate")


def feed(fifo: Path, data: bytes) -> threading.Thread:
    """A thread writing ``data`` into ``fifo`` once a reader opens it."""
    def write() -> None:
        try:
            with open(fifo, "wb") as fh:
                fh.write(data)
        except BrokenPipeError:  # the reader closed it unread
            pass
    thread = threading.Thread(target=write, daemon=True)
    thread.start()
    return thread


def release(fifo: Path, writer: threading.Thread) -> None:
    """Let ``writer`` finish if nothing read ``fifo`` (its open waits for a reader)."""
    if writer.is_alive():
        fd = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
        os.close(fd)
    writer.join(10)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes here")
def test_a_recording_read_through_a_fifo_is_refused_not_cached(tmp_path: Path,
                                                               sim_stream) -> None:
    """g2o truth given as a FIFO: the run fails, naming the file and saying what to do, and
    nothing is cached. Fails before: the run read the FIFO and was cached under a key that
    is the same whatever the FIFO gives, so the next run, fed other truth, got the old
    result from the cache."""
    write_g2o(tmp_path / "run.g2o", sim_stream)
    truth = tmp_path / "truth.g2o"
    os.mkfifo(truth)
    source = DatasetSource("g2o", str(tmp_path / "run.g2o"), truth_path=str(truth))
    writer = feed(truth, (tmp_path / "run.g2o").read_bytes())
    try:
        with pytest.raises(DatasetError, match="truth.g2o: a FIFO, not a regular file"):
            source.stream()
        (result,), n_cached = execute_counted([Task("e", ARM, source, checkpoint_every=40)],
                                              Executor("serial"), cache_dir=tmp_path / "cache")
    finally:
        release(truth, writer)
    assert not result["ok"] and n_cached == 0
    assert "truth.g2o: a FIFO, not a regular file" in result["error"], result["error"]
    assert not list((tmp_path / "cache").glob("*.json"))


def test_computing_a_recordings_key_does_not_import_scipy_optimize(tmp_path: Path,
                                                                   sim_stream) -> None:
    """Fails before: ``key()`` imported the importers, whose calibration imported
    scipy.optimize (about 0.3 s) at import."""
    write_g2o(tmp_path / "run.g2o", sim_stream)
    code = ("import sys\n"
            "from bomgraph.sources import DatasetSource\n"
            f"DatasetSource('g2o', {str(tmp_path / 'run.g2o')!r}).key()\n"
            f"DatasetSource('mrclam', {str(tmp_path)!r}, robot=1).key()\n"
            f"DatasetSource('victoria', {str(tmp_path / 'run.g2o')!r}).key()\n"
            "print('scipy.optimize' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"


def test_a_numpy_robot_number_is_keyed_as_an_int_and_a_bad_one_refused() -> None:
    """``robot=np.int64(1)`` (``for r in np.arange(1, 6)``) is robot 1, which the importer
    takes. Fails before: ``task_key`` raised ``TypeError: Object of type int64 is not JSON
    serializable``, a traceback; ``robot=1.5`` was taken until the run failed."""
    source = DatasetSource("mrclam", "m", robot=np.int64(1))
    assert type(source.robot) is int and source == DatasetSource("mrclam", "m", robot=1)
    assert task_key(Task("e", ARM, source)) == task_key(
        Task("e", ARM, DatasetSource("mrclam", "m", robot=1)))
    for bad in (1.5, "1", True, 0):
        with pytest.raises(ConfigError, match=r"DatasetSource\('mrclam'\): robot must be an "
                                              r"integer >= 1"):
            DatasetSource("mrclam", "m", robot=bad)
