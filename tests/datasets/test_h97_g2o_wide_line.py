"""h97's review of h96: the g2o importer's file cap went from 16 MiB to 256 MiB (its held
records are capped instead), but every line is split into Python strings before it is
checked, about 20 bytes of memory a byte of text: one 60 MB line of ``12 12 12 ...`` peaked at
1.7 GB (``out of memory`` under a 1.5 GiB limit), where h91's cap refused the file at 78 MB.
A data line longer than ``MAX_G2O_HELD_BYTES`` is now refused before it is split, naming its
line; shorter lines keep their messages. The first test failed before the fix (the line was
split and refused for its field count)."""

from __future__ import annotations

from pathlib import Path

import pytest

from bomgraph.datasets import import_g2o
from bomgraph.datasets.g2o import MAX_G2O_HELD_BYTES
from bomgraph.errors import DatasetError


def test_a_line_longer_than_the_held_cap_is_refused_before_it_is_split(tmp_path: Path) -> None:
    path = tmp_path / "wide.g2o"
    n = MAX_G2O_HELD_BYTES // 3 + 1
    path.write_text("EDGE_SE2 0 1 1 0 0 500 0 0 500 0 5000\n"
                    "EDGE_BEARING_SE2_XY " + "12 " * n + "\n")
    with pytest.raises(DatasetError, match=r"^\S*wide\.g2o, line 2: [0-9,]+ characters, more "
                                           r"than the 16,777,216 one line of this file may "
                                           r"have; fix or delete this line$"):
        import_g2o(path)


def test_a_long_comment_is_still_skipped_and_short_lines_keep_their_messages(
        tmp_path: Path) -> None:
    path = tmp_path / "c.g2o"
    path.write_text("# " + "x" * (MAX_G2O_HELD_BYTES + 10) + "\n"
                    "EDGE_SE2 0 1 1 0 0 500 0 0 500 0 5000\n"
                    "EDGE_BEARING_SE2_XY 1 5 0.1 100 " + "7 " * 1000 + "\n")
    with pytest.raises(DatasetError, match=r"c\.g2o, line 3: EDGE_BEARING_SE2_XY needs 4 "
                                           r"fields \(i l bearing w\), got 1004"):
        import_g2o(path)


def test_a_table_line_longer_than_its_cap_is_refused_before_it_is_split(tmp_path: Path) -> None:
    """The same for MRCLAM's tables (``read_table``): a data line over
    ``MAX_TABLE_LINE_CHARS`` is refused naming its line, before it is split into tokens
    (before: split, about 20 bytes of memory a character up to the 64 MiB line cap, then
    refused for its field count); a short line keeps its message."""
    from bomgraph.datasets._text import MAX_TABLE_LINE_CHARS, read_table

    fields = [("time", "float"), ("v", "float"), ("w", "float")]
    wide = tmp_path / "Robot1_Odometry.dat"
    wide.write_text("# Time [s] v [m/s] w [rad/s]\n1248272272.841 0.0 0.0\n"
                    + "1 " * (MAX_TABLE_LINE_CHARS // 2 + 1) + "\n")
    with pytest.raises(DatasetError, match=r"Robot1_Odometry\.dat, line 3: [0-9,]+ characters, "
                                           r"more than the 1,048,576 one line of this file "
                                           r"may have; fix or delete this line$"):
        read_table(wide, fields)
    short = tmp_path / "short.dat"
    short.write_text("1248272272.841 0.0 0.0\n" + "1 " * 1000 + "\n")
    with pytest.raises(DatasetError, match=r"short\.dat, line 2: expected 3 fields \(time, v, "
                                           r"w\), got 1000"):
        read_table(short, fields)
