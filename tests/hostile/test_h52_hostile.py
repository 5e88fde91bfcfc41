"""h52's hostile inputs: estimate-file refusals that named no line, implausible stated noise
accepted silently, and what the fresh audit of every command found. Each test failed before
its fix."""

from __future__ import annotations

from pathlib import Path

import pytest

from hostile_helpers import bomgraph, one_error

from bomgraph.errors import StreamFormatError
from bomgraph.estimate_file import read_estimate

# ---- version-1 estimate files: every refusal names the line ---------------------------------

#: a version-1 estimate written over ten lines, as a person (or ``json.dump(indent=...)``)
#: writes it; each case replaces one line
_V1 = ['{"format": "bomgraph-estimate",',
       ' "version": 1, "method": "m",',
       ' "landmarks": [[0, 1.0, 2.0],',
       '               [1, 3.0, 4.0]],',
       ' "checkpoints": [{"t": 5,',
       '                  "landmarks": [[0, 1.0, 2.0],',
       '                                [1, 3.0, 4.0]],',
       '                  "poses": [[0, 0.0, 0.0, 0.0],',
       '                            [1, 0.1, 0.0, 0.0]]}],',
       ' "timing_s": {"total": 1.0}}']


def _v1(path: Path, line: int | None = None, text: str = "") -> Path:
    lines = list(_V1)
    if line is not None:
        lines[line - 1] = text
    path.write_text("\n".join(lines) + "\n")
    return path


def test_the_version_1_example_is_read(tmp_path: Path) -> None:
    est = read_estimate(_v1(tmp_path / "e.json"))
    assert est.version == 1 and [c.t for c in est.checkpoints] == [5]


@pytest.mark.parametrize("line,text,key", [
    (2, ' "version": 7, "method": "m",', "version"),
    (2, ' "version": 1, "method": 5,', "method"),
    (4, '               [0, 3.0, 4.0]],', "landmarks[1]"),
    (7, '                                [-1, 3.0, 4.0]],', "checkpoints[0].landmarks[1]"),
    (9, '                            [1, 0.1, NaN, 0.0]]}],', "checkpoints[0].poses[1][2]"),
    (9, '                            [0, 0.1, 0.0, 0.0]]}],', "checkpoints[0].poses[1]"),
    (9, '                            [1, 0.1, 0.0, 0.0]]}, {"t": 4, "landmarks": []}],',
     "checkpoints[1].t"),
    (5, ' "checkpoints": [{"t": 5, "t": 6,', "checkpoints[0].t"),
    (5, ' "checkpoints": [{"t": 5, "zz": 0,', "checkpoints[0].zz"),
    (10, ' "timing_s": {"total": "x"}}', "timing_s.total"),
    (10, ' "timing_s": {"total": 1.0}, "extra": 1}', "extra"),
    (3, ' "landmarks": [[0, 1.0, 2.0], "format": 3,', None),      # not JSON: the decoder's line
])
def test_a_version_1_refusal_names_the_line_and_the_key(tmp_path: Path, line, text, key) -> None:
    """Every refusal of a version-1 file (one JSON object, over any number of lines) named the
    key but no line: in a file of thousands of lines the user could not find it."""
    p = _v1(tmp_path / "e.json", line, text)
    with pytest.raises(StreamFormatError) as info:
        read_estimate(p)
    msg = str(info.value)
    assert msg.startswith(f"{p}, line {line}: "), msg
    if key is not None:
        assert f": '{key}': " in msg, msg


@pytest.mark.parametrize("line,text,needle", [
    (4, "               [1, 3" + "0" * 5000 + ", 4.0]],", "an integer of 5001 digits"),
    (4, "               [1, 3.0, " + "[" * 3000 + "]" * 3000 + "]],", "nested more than"),
])
def test_a_version_1_file_json_cannot_parse_names_the_line(tmp_path: Path, line, text,
                                                           needle) -> None:
    """Valid JSON that Python's parser gives up on (a huge integer, deep nesting) was refused
    as ``not a JSON estimate file (ValueError)``, with no line and no reason."""
    p = _v1(tmp_path / "e.json", line, text)
    with pytest.raises(StreamFormatError) as info:
        read_estimate(p)
    assert str(info.value).startswith(f"{p}, line {line}: ") and needle in str(info.value)


def test_a_version_1_file_not_utf8_names_the_line(tmp_path: Path) -> None:
    p = _v1(tmp_path / "e.json")
    p.write_bytes(p.read_bytes().replace(b'"m"', b'"\xff"'))
    with pytest.raises(StreamFormatError, match=r"e\.json, line 2: not UTF-8"):
        read_estimate(p)


@pytest.mark.parametrize("command", [
    ["evaluate", "{est}", "{stream}"],
    ["export", "--format", "tum", "--out", "{out}", "{est}"],
    ["plot", "--out", "{out}.png", "{est}", "{stream}"],
])
def test_every_command_reading_estimates_names_the_line(work: Path, command) -> None:
    p = _v1(work / "e.json", 9, '                            [1, 0.1, NaN, 0.0]]}],')
    args = [a.format(est=p, stream=work / "s.jsonl", out=work / "out") for a in command]
    one_error(bomgraph(*args), f"{p}, line 9: 'checkpoints[0].poses[1][2]'")
    assert not (work / "out").exists() and not (work / "out.png").exists()


# ---- version-2 estimate files: the header -----------------------------------------------------

_V2_BODY = '{"t": 1, "landmarks": [[0, 1.0, 2.0]]}\n{"timing_s": {"total": 1.0}}\n'


@pytest.mark.parametrize("header,key,needle", [
    ('{"format": "bomgraph-estimate", "version": 2, "method": "m", "options": {"a": NaN}}',
     "options.a", "non-finite"),
    ('{"format": "bomgraph-estimate", "version": 2, "method": "m", "options": {"a": 1e999}}',
     "options.a", "non-finite"),
    ('{"format": "bomgraph-estimate", "version": 2, "method": "m", "method": "n"}',
     "method", "appears twice"),
])
def test_a_version_2_header_is_as_strict_as_its_lines(tmp_path: Path, header, key,
                                                     needle) -> None:
    """A header's NaN or Infinity (in its options) was read; a header with a repeated key was
    refused as ``line 2: not valid JSON (Extra data ...)``."""
    p = tmp_path / "e.json"
    p.write_text(header + "\n" + _V2_BODY)
    with pytest.raises(StreamFormatError) as info:
        read_estimate(p)
    msg = str(info.value)
    assert msg.startswith(f"{p}, line 1: '{key}': ") and needle in msg, msg


def test_a_version_2_line_with_a_huge_integer_says_so(tmp_path: Path) -> None:
    """It said ``not valid JSON (ValueError)``."""
    p = tmp_path / "e.json"
    p.write_text('{"format": "bomgraph-estimate", "version": 2, "method": "m"}\n'
                 '{"t": 1, "landmarks": [[' + "9" * 5000 + ', 1.0, 2.0]]}\n'
                 '{"timing_s": {}}\n')
    with pytest.raises(StreamFormatError, match=r"line 2: not valid JSON \(an integer of 5000"):
        read_estimate(p)
