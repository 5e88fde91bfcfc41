"""The strict text helpers shared by the importers: the odometry chain."""

from __future__ import annotations

import pytest

from bomgraph.datasets._text import chain_order
from bomgraph.errors import DatasetError


def test_chain_order_follows_edges_not_ids():
    assert chain_order([(5, 2, 1), (9, 5, 2), (2, 7, 3)], "f") == [9, 5, 2, 7]
    assert chain_order([], "f") == []
    with pytest.raises(DatasetError, match="f, line 2: .*closed loop"):
        chain_order([(0, 1, 1), (2, 3, 2), (3, 2, 3)], "f")
    with pytest.raises(DatasetError, match="f, line 1: the odometry edges form a closed loop"):
        chain_order([(0, 1, 1), (1, 0, 2)], "f")
    with pytest.raises(DatasetError, match="f, line 2: pose 4 already has odometry from"):
        chain_order([(0, 4, 1), (1, 4, 2)], "f")
    with pytest.raises(DatasetError, match="to itself"):
        chain_order([(3, 3, 1)], "f")


def test_an_importer_reads_a_dataset_file_in_bounded_memory(tmp_path):
    """h18 item 09: the whole decompressed file was held several times over (a 40 KB .gz of
    comment lines cost ~490 MB); now a block of lines at a time."""
    import gzip
    import tracemalloc

    from bomgraph.datasets.victoria import import_victoria

    bomb = tmp_path / "bomb.txt.gz"
    bomb.write_bytes(gzip.compress(b"# a comment line\n" * 500_000, 9))  # 8 MiB in 25 KB
    tracemalloc.start()
    try:
        with pytest.raises(DatasetError, match="bomb.txt.gz"):
            import_victoria(bomb)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 16 * 2**20, peak  # one block: 7.5 MiB traced; the old reader: ~45 MiB


def test_a_dataset_file_over_the_cap_is_refused(tmp_path, monkeypatch):
    import gzip

    from bomgraph.datasets import _text

    monkeypatch.setattr(_text, "MAX_DATASET_BYTES", 2**20)
    big = tmp_path / "big.dat.gz"
    big.write_bytes(gzip.compress(b"1 2 3\n" * 200_000))  # 1.2 MB decompressed
    with pytest.raises(DatasetError, match=r"big\.dat\.gz: larger than 1 MiB decompressed, the "
                                           r"limit for a dataset file"):
        _text.read_table(big, [("a", "int"), ("b", "int"), ("c", "int")])
    small = tmp_path / "small.dat"
    small.write_bytes(b"# c\n1 2 3\r\n\n4 5 6")
    cols, lines = _text.read_table(small, [("a", "int"), ("b", "int"), ("c", "int")])
    assert cols["a"].tolist() == [1, 4] and lines.tolist() == [2, 4]


def test_find_file_says_what_is_there_instead_of_a_file(tmp_path):
    """h18 item 14: a data file that is a directory or a looping link was reported missing."""
    from bomgraph.datasets._text import find_file, has_file

    (tmp_path / "A.dat").mkdir()
    (tmp_path / "B.dat").symlink_to("B.dat")          # loops
    (tmp_path / "C.dat").symlink_to("nowhere.dat")    # broken
    with pytest.raises(DatasetError, match=r"A\.dat: is a directory, not a data file"):
        find_file(tmp_path, "A.dat")
    for name in ("B.dat", "C.dat"):
        assert has_file(tmp_path, name)
        with pytest.raises(DatasetError, match=rf"{name}: is a broken or looping link"):
            find_file(tmp_path, name)
    with pytest.raises(DatasetError, match="neither D.dat nor D.dat.gz exists"):
        find_file(tmp_path, "D.dat")
    assert not has_file(tmp_path, "D.dat")
    (tmp_path / "A.dat.gz").write_bytes(b"")  # a file beside the directory is still used
    assert find_file(tmp_path, "A.dat") == tmp_path / "A.dat.gz"
