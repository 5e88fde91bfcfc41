"""Paths under the top-level key "" (h55 made ``line_of_key("")`` find that key, but a
path below it lost the "": ``root[""]["b"]`` was spelled ``b``, i.e. ``root["b"]``) and
under a top-level key starting with "." (``line_of_key`` took its dot for a separator)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bomgraph.errors import StreamFormatError
from bomgraph.estimate_file import read_estimate
from bomgraph.jsonio import find_nonfinite, line_of_key

TEXT = '{\n "a": 1,\n "": {\n  "": 2,\n  "b": NaN\n },\n ".x": {\n  "c": 3\n }\n}\n'


def test_a_value_under_the_empty_key_is_spelled_and_found() -> None:
    obj = json.loads(TEXT, parse_constant=float)
    assert find_nonfinite(obj) == ".b"
    assert line_of_key(TEXT, ".b") == 5
    assert line_of_key(TEXT, ".") == 4       # root[""][""]
    assert line_of_key(TEXT, "") == 3        # root[""]
    assert line_of_key(TEXT, ".x.c") == 8    # root[".x"]["c"]
    assert line_of_key(TEXT, "a") == 2


@pytest.mark.parametrize("outer, line, named", [("", 5, ".b"), (".x", 5, ".x.b")])
def test_a_repeated_key_under_such_a_key_is_named_on_its_line(
        tmp_path: Path, outer: str, line: int, named: str) -> None:
    path = tmp_path / "e.json"
    path.write_text('{\n "format": "bomgraph-estimate",\n "%s": {\n  "b": 1,\n  "b": 2\n }\n}\n'
                    % outer)
    with pytest.raises(StreamFormatError) as info:
        read_estimate(path)
    assert f"line {line}: '{named}': appears twice" in str(info.value), str(info.value)
