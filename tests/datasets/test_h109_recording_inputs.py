"""h109: a recording's cache key is the SHA-256 of the files its importer reads, each named by
its role, not its path. The key of a recording (``DatasetSource``) hashed every file under its
folder, each named by its absolute path, and held the folder's absolute path: a compare whose
``--out`` folder was inside the recording's folder never hit its cache (its own results and
cache files changed the key, even between the runs of one compare), nor did a copied, moved or
renamed recording, while a stream file's key is its bytes only."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from dataset_excerpts import make_mrclam, rewrite_keeping_size_and_times, write_g2o

from bomgraph.bench import Executor, execute_counted, task_key
from bomgraph.errors import ConfigError, DatasetError
from bomgraph.experiments import Arm, Experiment, Task
from bomgraph.report import compare
from bomgraph.sources import DatasetSource

ARM = Arm("tri", "triangulate")


def cached_runs(source: DatasetSource, cache: Path) -> int:
    """How many of ``source``'s one task were read from ``cache`` (it runs, and is cached)."""
    (result,), n_cached = execute_counted([Task("e", ARM, source, checkpoint_every=40)],
                                          Executor("serial"), cache_dir=cache)
    assert result["ok"], result.get("error")
    return n_cached


def swap_two_bytes(data: bytes) -> bytes:
    """``data`` with its first two unequal neighbours past the middle swapped: the same size."""
    k = next(k for k in range(len(data) // 2, len(data) - 1) if data[k] != data[k + 1])
    return data[:k] + data[k + 1:k + 2] + data[k:k + 1] + data[k + 2:]


def test_a_compare_into_a_folder_inside_the_recording_hits_its_cache(tmp_path: Path) -> None:
    """``compare --out RECORDING/results`` twice: the second takes both robots' runs from the
    cache. Fails before: 0 cached (the first compare's own files changed the key)."""
    make_mrclam(tmp_path / "m")
    for name in ("Odometry", "Measurement", "Groundtruth"):  # robot 2: robot 1's files
        shutil.copy(tmp_path / "m" / f"Robot1_{name}.dat", tmp_path / "m" / f"Robot2_{name}.dat")
    exp = Experiment("m", "m", (ARM,), checkpoint_every=40,
                     sources=tuple(DatasetSource("mrclam", str(tmp_path / "m"), robot=r)
                                   for r in (1, 2)))
    first = compare([exp], tmp_path / "m" / "results", figures=False)
    assert all(r["ok"] for r in first.results)
    again = compare([exp], tmp_path / "m" / "results", figures=False)
    assert (first.n_cached, again.n_cached) == (0, 2)


def test_a_copied_moved_or_renamed_recording_hits_the_cache(tmp_path: Path) -> None:
    """The same files at another path, as a stream file's. Fails before: each missed."""
    make_mrclam(tmp_path / "a" / "mrclam")
    cache = tmp_path / "cache"
    assert cached_runs(DatasetSource("mrclam", str(tmp_path / "a" / "mrclam"), robot=1),
                       cache) == 0
    shutil.copytree(tmp_path / "a", tmp_path / "copy")
    (tmp_path / "a").rename(tmp_path / "moved")
    (tmp_path / "moved" / "mrclam").rename(tmp_path / "moved" / "renamed")
    for folder in (tmp_path / "copy" / "mrclam", tmp_path / "moved" / "renamed"):
        assert cached_runs(DatasetSource("mrclam", str(folder), robot=1), cache) == 1


def test_a_g2o_copy_under_another_name_has_the_same_key(tmp_path: Path, sim_stream) -> None:
    """Fails before: the key held the files' absolute paths."""
    write_g2o(tmp_path / "run.g2o", sim_stream)
    (tmp_path / "other").mkdir()
    shutil.copy(tmp_path / "run.g2o", tmp_path / "other" / "copy.g2o")
    shutil.copy(tmp_path / "run.g2o", tmp_path / "other" / "truth copy.g2o")
    key = DatasetSource("g2o", str(tmp_path / "run.g2o"), truth_path=str(tmp_path / "run.g2o"))
    copy = DatasetSource("g2o", str(tmp_path / "other" / "copy.g2o"),
                         truth_path=str(tmp_path / "other" / "truth copy.g2o"))
    assert copy.key() == key.key()
    assert DatasetSource("g2o", str(tmp_path / "run.g2o")).key() != key.key()  # no truth


@pytest.mark.parametrize("gz", [False, True], ids=["dat", "gz"])
def test_editing_any_file_the_importer_reads_changes_the_key(tmp_path: Path, gz: bool) -> None:
    """Each input (robot 1's odometry, measurements and ground truth, the landmark table, the
    barcodes) with two bytes swapped, its size and modification time kept: a miss. The misses
    held before too (h104: every file of the folder was hashed); what is new is that the key
    names the inputs (``inputs()``, which did not exist), so they must be every file read."""
    make_mrclam(tmp_path / "m", gz=gz)
    source = DatasetSource("mrclam", str(tmp_path / "m"), robot=1)
    files = source.inputs()
    assert sorted(files) == ["barcodes", "groundtruth", "landmarks", "measurements", "odometry"]
    assert sorted(p.name for p in files.values() if p is not None) == sorted(
        p.name for p in (tmp_path / "m").iterdir())
    seen = {task_key(Task("e", ARM, source))}
    for path in files.values():
        assert path is not None
        rewrite_keeping_size_and_times(path, swap_two_bytes)
        seen.add(task_key(Task("e", ARM, source)))
    assert len(seen) == 1 + len(files)


def test_what_the_importer_does_not_read_is_not_in_the_key_and_what_it_would_is(
        tmp_path: Path) -> None:
    """Notes, an editor's swap file, another robot's files leave the key; the robot's ground
    truth added (the importer then reads it) or a plain file beside a ``.gz`` one (the importer
    reads the plain one) change it."""
    make_mrclam(tmp_path / "m", gz=True)
    source = DatasetSource("mrclam", str(tmp_path / "m"), robot=1)
    key = source.key()
    for name in ("notes.txt", ".DS_Store", ".Robot1_Odometry.dat.swp", "Robot2_Odometry.dat",
                 "Barcodes.dat.gz~"):
        (tmp_path / "m" / name).write_text("x\n")
    (tmp_path / "m" / "results" / "cache").mkdir(parents=True)
    (tmp_path / "m" / "results" / "cache" / "k.json").write_text("{}\n")
    assert source.key() == key
    truth = tmp_path / "m" / "Robot1_Groundtruth.dat.gz"
    truth.rename(tmp_path / "truth.gz")
    assert source.key() != key
    (tmp_path / "truth.gz").rename(truth)
    assert source.key() == key
    (tmp_path / "m" / "Barcodes.dat").write_text("1 5\n")
    assert source.key() != key
    assert source.inputs()["barcodes"] == tmp_path / "m" / "Barcodes.dat"


def test_a_missing_input_gives_the_importers_error_not_one_from_the_key(tmp_path: Path) -> None:
    """The key of a folder without the robot's odometry is made (nothing raised); the run
    fails with the importer's message naming the file."""
    make_mrclam(tmp_path / "m")
    (tmp_path / "m" / "Robot1_Odometry.dat").unlink()
    source = DatasetSource("mrclam", str(tmp_path / "m"), robot=1)
    assert source.key()["sha256"]
    with pytest.raises(DatasetError, match="neither Robot1_Odometry.dat nor "
                                           "Robot1_Odometry.dat.gz exists"):
        source.stream()
    (result,), _ = execute_counted([Task("e", ARM, source)], Executor("serial"),
                                   cache_dir=tmp_path / "cache")
    assert not result["ok"] and "Robot1_Odometry.dat" in result["error"]
    g2o = DatasetSource("g2o", str(tmp_path / "none.g2o"), truth_path=str(tmp_path / "m"))
    assert g2o.key()["sha256"]
    with pytest.raises(DatasetError, match="none.g2o: file not found"):
        g2o.stream()


def test_a_source_of_no_known_kind_or_an_mrclam_one_without_a_robot_is_refused() -> None:
    with pytest.raises(ConfigError, match="unknown dataset kind 'tum'; use mrclam, g2o, victoria"):
        DatasetSource("tum", "x")
    with pytest.raises(ConfigError, match="needs a robot number"):
        DatasetSource("mrclam", "x")
