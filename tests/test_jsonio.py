"""The shared JSON helpers: the sanitiser, strict reading, the option parser."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from bomgraph.errors import ConfigError
from bomgraph.jsonio import (DuplicateKeyError, find_nonfinite, is_id, is_num, jsonable,
                             line_of_key, loads_strict, parse_option_value, parse_options,
                             path_of)


def test_jsonable_plain_values_numpy_and_non_finite() -> None:
    got = jsonable({"a": np.float64(1.5), "b": np.int64(3), "c": (1, np.nan), 4: np.array([2.0]),
                    "d": np.bool_(True), "e": object()})
    assert got == {"a": 1.5, "b": 3, "c": [1, None], "4": [2.0], "d": True, "e": None}
    assert jsonable([1, 2, 3], max_items=2) is None
    with pytest.raises(ValueError):
        jsonable({"x": math.inf}, strict=True)
    with pytest.raises(TypeError):
        jsonable({"x": object()}, strict=True)


def test_jsonable_keeps_sets_and_paths_a_plugin_puts_in_info() -> None:
    """A set or a path in a method's ``info`` became ``null``: now a sorted list and a string
    (in order whatever the set's hash order), and still refused where data must read back."""
    from pathlib import Path

    assert jsonable({"ids": {3, 1, 2}, "f": frozenset({"b", "a"}), "p": Path("/x/y.est")}) == {
        "ids": [1, 2, 3], "f": ["a", "b"], "p": "/x/y.est"}
    assert jsonable({1, "a"}) == ["a", 1]                      # by repr: "'a'" < "1"
    with pytest.raises(TypeError):
        jsonable({"ids": {1, 2}}, strict=True)


def test_strict_reading_refuses_duplicates_and_finds_non_finite() -> None:
    with pytest.raises(DuplicateKeyError):
        loads_strict('{"a": 1, "a": 2}')
    assert find_nonfinite(loads_strict('{"a": [1, {"b": NaN}]}')) == "a[1].b"
    assert find_nonfinite({"a": [1.0, 2.0]}) is None
    deep: list = [math.inf]
    for _ in range(5000):  # deeper than the interpreter's recursion limit
        deep = [deep]
    assert find_nonfinite(deep) is not None
    assert is_id(2**63 - 1) and not is_id(2**63) and not is_id(True) and not is_id(-1)
    assert is_num(1e300) and not is_num(10**400) and not is_num(False)



def test_find_nonfinite_spells_no_path_per_element() -> None:
    # a stream header of 60 MiB (a list of 31 million numbers, under the line cap) took over
    # 3 GiB here: one path string and one tuple per element (session 12)
    import tracemalloc

    data = {"meta": {"a": [1] * 300_000 + [0.5] * 300_000, "b": [[1.0, 2.0]] * 100_000}}
    tracemalloc.start()
    try:
        assert find_nonfinite(data) is None
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 1_000_000, peak
    data["meta"]["b"][70_000] = [1.0, math.nan]
    assert find_nonfinite(data, "h") == "h.meta.b[70000][1]"
    assert find_nonfinite([{"x": [math.inf]}, math.nan]) == "[0].x[0]"  # depth first, in order

def test_option_parser_accepts_infinity_and_refuses_nan() -> None:
    got = parse_options(["a=inf", "b=-Infinity", "c=3", "d=abc", "e=[1, 2]", "f=null",
                         "g=1e-3", "h=true"])
    assert got == {"a": math.inf, "b": -math.inf, "c": 3, "d": "abc", "e": [1, 2], "f": None,
                   "g": 1e-3, "h": True}
    assert parse_option_value("Infinity") == math.inf
    for bad in ("nan", "NaN"):
        with pytest.raises(ConfigError, match="NaN"):
            parse_option_value(bad)
    for bad in ("novalue", "=3"):
        with pytest.raises(ConfigError):
            parse_options([bad])


def test_line_of_key_follows_the_path_and_nothing_else() -> None:
    data = {"a": 1, "b": {"c": [1, [2, 3], {"d": 4}]}, "x.y": 5, "x": {"y": 6}}
    text = json.dumps(data, indent=1)
    lines = text.split("\n")
    for key, needle in [("a", '"a"'), ("b.c", '"c"'), ("b.c[1][1]", "3"), ("b.c[2].d", '"d"'),
                        ("x.y", '"x.y"'), ("x", '"x": {')]:
        line = line_of_key(text, key)
        assert needle in lines[line - 1], (key, line)
    assert line_of_key(text, "b.c[9]") == line_of_key(text, "b.c")   # as far as it goes
    assert line_of_key(text, None) == line_of_key(text, "zz") == 1
    assert line_of_key('{"a": 1,\n "a": 2}', "a") == 2                 # the repeat
    assert line_of_key('{"a": [1,\n 2, oops', "a[1]") == 2              # not JSON beyond
    assert path_of(data, data["b"]["c"][2]) == "b.c[2]" and path_of(data, data) == ""
    assert path_of(data, []) is None


def test_line_of_key_is_not_fooled_by_strings_escapes_or_repeats() -> None:
    """Brackets, braces, commas and quotes inside strings, escaped keys, non-ASCII keys and
    the longest key that begins the path (h62: the walk is vectorised over the text's
    brackets and commas, so strings must be told apart from structure)."""
    text = ('{"s": "a,]}[{\\"",\n "k\\u00e9": [\n  "x,y",\n  {"\\"q": 1,\n   "é.z": 2,\n'
            '   "é": {"z": [3,\n 4]}}],\n "k": {},\n "k": [[],\n  [5]]}')
    assert json.loads(text)["ké"][1]["é"]["z"] == [3, 4]
    for key, line in [("s", 1), ("ké", 2), ("ké[0]", 3), ("ké[1]", 4), ('ké[1]."q', 4),
                      ("ké[1].é.z", 5), ("ké[1].é.z[1]", 5), ("ké[1].é", 6), ("k", 9),
                      ("k[1]", 10), ("k[1][0]", 10), ("k[0][0]", 9), ("k[2]", 9),
                      ("ké[1].zz", 4), ("zz", 1)]:
        assert line_of_key(text, key) == line, key


def test_line_of_key_of_a_deep_value_in_a_long_list() -> None:
    """Millions of values are stepped over at C speed (9 s before h62 for 1,000,000
    landmarks; no timing asserted here): the line is the same as counting the lines."""
    lms = [[i, 0.5 * i, 1.25] for i in range(20000)]
    text = json.dumps({"format": "x", "landmarks": lms, "timing_s": {f"k{i}": 1 for i in
                                                                      range(20000)}}, indent=1)
    lines = text.split("\n")
    line = line_of_key(text, "landmarks[19999][1]")
    assert lines[line - 1].strip() == "9999.5,"
    assert lines[line_of_key(text, "timing_s.k19999") - 1].strip() == '"k19999": 1'


def test_line_of_key_of_a_path_as_deep_as_json_parses() -> None:
    """A path 900 keys deep (about what :mod:`json` parses), one key per line, before a long
    list (h70: each level no longer scans to the end of the text, nor spells every prefix of
    the rest of the path: 14 s -> 1.3 s at 59 MiB; no timing asserted here)."""
    deep = 900
    text = ('{"format": "x",\n "options": ' + '{"b": 1, "a":\n' * deep + '1'
            + '}' * deep + ',\n "landmarks": [' + ",\n".join(f"[{i}, 1.5]" for i in range(2000))
            + ']}')
    assert line_of_key(text, "options" + ".a" * deep) == deep + 1
    assert line_of_key(text, "options" + ".a" * 500) == 500 + 1
    assert line_of_key(text, "options" + ".a" * 499 + ".b") == 500 + 1
    assert line_of_key(text, "options" + ".a" * 499 + ".c.a") == 500 + 1   # leaves the data
    assert line_of_key(text, "landmarks[1999][1]") == text.count("\n") + 1


def test_line_of_key_of_a_text_not_json_gives_a_line() -> None:
    """As the docstring says (a best guess beyond where the text is not JSON) and as before
    h62, the line reached so far: h70 found the vectorised walk raising JSONDecodeError on a
    key holding a raw newline, and IndexError on a bracket its unpaired quotes put
    "inside" a string (found by fuzzing broken texts against the pre-h62 walk)."""
    text = '{"a": 1,\n "\n": 2,\n "d": 3}'
    assert line_of_key(text, "d") == 1
    text = '{\n "[.[":\n[ ],\n "0.":\n{\n  """ [ ] ],\n  "":\n[],\n  "0.":"x"\n}\n}'
    assert line_of_key(text, "0..[0]") == 6
