"""h119's review of h116: what its "cut short?" test of a last line still said wrongly."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bomgraph.jsonio import line_not_json, loads_strict

LINE = ('{"t": 3, "odom": [0.1, -2.5e+3, 0], "s": "caf\\u00e9 \\"x\\"", "ok": true, '
        '"n": null, "b": [-0.0, 10E-2]}')


def _why(text: str) -> str:
    with pytest.raises((json.JSONDecodeError, ValueError)) as caught:
        loads_strict(text)
    return line_not_json(caught.value, text, 4)


def test_every_cut_of_a_line_with_escapes_and_exponents_is_called_cut_short() -> None:
    """h116's rule missed a line cut inside a ``\\uXXXX`` escape (``"caf\\u00``): the
    decoder's "Invalid \\uXXXX escape" was not taken for a cut."""
    assert loads_strict(LINE)
    for k in range(1, len(LINE)):
        assert "cut short?" in _why(LINE[:k]), LINE[:k]


@pytest.mark.parametrize("text", ['{"a": 1 2', '{"a": 1.2.3', '{"a": 12-', '{"a": "x"1',
                                  '{"a": [true1', '{"a": "\\uZZ', '{"a": trux'])
def test_a_stray_character_after_a_complete_value_is_not_called_cut_short(text: str) -> None:
    """No cut of a valid line ends so: h116 called the first four cut short (what followed
    the decoder's stop looked like a number, wherever it began)."""
    why = _why(text)
    assert why.startswith("not valid JSON (") and "cut short" not in why, why


def test_a_bad_stream_given_twice_is_one_error_line(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """h116's warning of the second spelling came before the refusal of the file: two
    lines for one bad input."""
    from bomgraph.cli import main

    (tmp_path / "bad.jsonl").write_text("x\n")
    assert main(["compare", "--streams", str(tmp_path / "bad.jsonl"),
                 f"{tmp_path}/./bad.jsonl", "--methods", "triangulate",
                 "--out", str(tmp_path / "out"), "--dry-run"]) == 2
    [line] = capsys.readouterr().err.strip().splitlines()
    assert line.startswith("bomgraph: error: --streams: ") and "line 1" in line, line
