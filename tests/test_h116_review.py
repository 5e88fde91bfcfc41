"""h116's review of h112 (the new-user audit) and the leads it left: what the checks it added
said wrongly, and the command line's duplicate streams, the estimates index and the
read-only-folder tests that never ran as root."""

from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import numpy as np
import pytest

from bomgraph.command_line_sweep import command_line_spec
from bomgraph.jsonio import line_not_json, loads_strict
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream
from bomgraph.sweep import SweepError, read_sweep

LINE = ('{"t": 3, "odom": [0.1, 0.0, -0.02], "bearings": [[4, 1.25e-1, 0.05]], "ok": true, '
        '"none": null, "no": false, "s": "a\\"b"}')


def _why(text: str, line: int = 22) -> str:
    with pytest.raises((json.JSONDecodeError, ValueError)) as caught:
        loads_strict(text)
    return line_not_json(caught.value, text, line)


def test_every_cut_of_a_last_line_is_called_cut_short() -> None:
    for k in range(1, len(LINE)):
        assert "cut short?" in _why(LINE[:k]), LINE[:k]


@pytest.mark.parametrize("text", [LINE + "x", LINE[:-1] + ",}", LINE + "}", LINE[:-1] + "]"])
def test_a_complete_last_line_wrong_otherwise_is_not_called_cut_short(text: str) -> None:
    """h112 said "cut short? complete the line or remove it" of any last line without a
    newline: of one with a stray character or a trailing comma too, where nothing is
    missing."""
    why = _why(text)
    assert why.startswith("not valid JSON (") and "cut short" not in why, why


def test_a_byte_order_mark_after_line_1_is_the_lines() -> None:
    """Files joined (``cat a.jsonl b.jsonl``), b saved with a BOM: line 57 said "the file
    starts with a UTF-8 byte-order mark"."""
    assert "the file starts with a UTF-8 byte-order mark" in _why("\ufeff" + LINE + "\n", 1)
    why = _why("\ufeff" + LINE + "\n", 57)
    assert "the line starts with a UTF-8 byte-order mark (BOM): remove it" in why, why
    assert loads_strict('{"s": "\ufeffx"}') == {"s": "\ufeffx"}  # inside a string: valid


def test_compare_streams_runs_a_file_given_twice_once_as_a_sweep_file_does(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """``compare --streams a.jsonl a.jsonl`` ran it twice (streams-w0-0 and -1), and the paired
    statistics counted one stream as two; a sweep file's globs dropped the second."""
    write_stream(simulate(SimConfig(n_steps=8), np.random.default_rng(1)), tmp_path / "a.jsonl")
    (tmp_path / "link.jsonl").symlink_to("a.jsonl")
    shutil.copyfile(tmp_path / "a.jsonl", tmp_path / "copy.jsonl")
    a, link, copy = (str(tmp_path / n) for n in ("a.jsonl", "link.jsonl", "copy.jsonl"))
    again = f"{tmp_path}/./a.jsonl"
    with caplog.at_level(logging.WARNING):
        spec = command_line_spec([a, again, link, copy], ["triangulate"], [])
    runs = spec.experiments[0].streams
    assert [p for p, _ in runs] == [a, copy] and len({lb for _, lb in runs}) == 2, runs
    said = [r.getMessage() for r in caplog.records]
    assert said == [f"streams: {again}, {link} are the same file as one before; each file "
                    f"runs once (a copy under another name runs as a stream of its own)"], said
    (tmp_path / "sweep.toml").write_text(
        'streams = ["a.jsonl", "./a.jsonl", "link.jsonl", "copy.jsonl"]\n'
        'methods = ["triangulate"]\n')
    assert read_sweep(tmp_path / "sweep.toml").experiments[0].streams == runs  # one mechanism


def test_compare_streams_names_a_bad_stream_as_given(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """The duplicates dropped, the header check still names the file as the user spelled it
    (a first version of h116's change named it by its resolved path)."""
    (tmp_path / "bad.jsonl").write_text('{"format": "nope"}\n')
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SweepError, match=r"^streams: bad\.jsonl, line 1: 'format'"):
        command_line_spec(["bad.jsonl", "./bad.jsonl"], ["triangulate"], [])
