"""h52's hostile inputs: estimate-file refusals that named no line, implausible stated noise
accepted silently, and what the fresh audit of every command found. Each test failed before
its fix."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from hostile_helpers import ROOT, bomgraph, one_error

sys.path.insert(0, str(ROOT / "tests" / "datasets"))
from dataset_excerpts import write_g2o  # noqa: E402

from bomgraph.errors import StreamFormatError  # noqa: E402
from bomgraph.estimate_file import read_estimate  # noqa: E402

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
    # 20,000 deep: Python 3.13's parser reads 3,000 (3.11's gives up there)
    (4, "               [1, 3.0, " + "[" * 20_000 + "]" * 20_000 + "]],", "nested more than"),
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


# ---- stated noise a stream's own numbers contradict: a warning, not a refusal ----------------

def _warnings(proc) -> list[str]:
    assert proc.returncode == 0, proc.stderr.decode()
    return [ln for ln in proc.stderr.decode().splitlines() if ln.startswith("bomgraph: WARNING")]


def _restated(work: Path, name: str, header: dict | None = None,
              step_sigma: list[float] | None = None, n: int | None = None,
              straight: bool = False) -> Path:
    """``s.jsonl`` (60 simulated steps, the paper's noise) with its header's values replaced,
    each step stating ``step_sigma``, or only its first ``n`` steps; ``straight``: every turn
    +-0.01 rad."""
    head, *steps = (work / "s.jsonl").read_text().splitlines()
    obj = {**json.loads(head), **(header or {})}
    obj.pop("truth", None)
    steps = steps[:n]
    if step_sigma is not None or straight:
        lines = [json.loads(s) for s in steps]
        for st in lines[1:]:
            if step_sigma is not None:
                st["odom_sigma"] = step_sigma
            if straight:
                st["odom"][2] = 0.01 * (-1) ** st["t"]
        steps = [json.dumps(st) for st in lines]
    (work / name).write_text("\n".join([json.dumps(obj), *steps]) + "\n")
    return work / name


@pytest.mark.parametrize("header,step_sigma,straight,needles", [
    ({"bearing_sigma_rad": 3.0}, None, False,
     ["line 1: 'bearing_sigma_rad': 3 rad is above pi/sqrt(3)"]),
    ({"odometry_sigma": [0.03, 0.0, 3.0]}, None, False,
     ["line 1: 'odometry_sigma': sigma_dpsi_rad = 3 is above 1.81", "degrees?"]),
    ({"odometry_sigma": [5.0, 5.0, 0.0524]}, None, False,
     ["line 1: 'odometry_sigma': the 60 steps move 0.1", "centimetres?"]),
    ({"odometry_sigma": [0.03, 0.0, 30.0 / 57.3]}, None, False, None),  # 30 degrees: possible
    (None, [3.0, 0.0, 0.0524], False, ["line 3: 'odom_sigma': the 60 steps move",
                                       "centimetres?"]),
    ({"odometry_sigma": [0.03, 0.0, 1.0]}, None, True,
     ["line 1: 'odometry_sigma': the 60 steps turn 0.01 rad", "degrees?"]),
    ({"odometry_sigma": [0.03, 0.0, 0.0524]}, None, True, None),  # straight, paper's noise
])
def test_stated_noise_the_stream_contradicts_is_warned_of(work: Path, header, step_sigma,
                                                         straight, needles) -> None:
    """A bearing sigma of 3 rad (below pi, the old limit), a turn sigma of 3 (degrees) or a
    translation sigma of 5 (centimetres) for steps of 0.15 m were read silently. The run goes
    on (the file is valid); the warning names the line and the key, once."""
    stream = _restated(work, "x.jsonl", header, step_sigma, straight=straight)
    warned = _warnings(bomgraph("run", stream, "--method", "triangulate", "--out",
                                work / "e.json"))
    if needles is None:
        assert warned == []
        return
    assert len(warned) == 1, warned
    for n in needles:
        assert n in warned[0], (n, warned[0])
    assert warned[0].startswith(f"bomgraph: WARNING: {stream}, line ")


def test_too_few_steps_are_not_judged(work: Path) -> None:
    """Nine steps of pure noise average below a tenth of the bound once in about 1e5."""
    stream = _restated(work, "x.jsonl", {"odometry_sigma": [5.0, 5.0, 0.0524]}, n=10)
    assert _warnings(bomgraph("run", stream, "--method", "triangulate", "--out",
                              work / "e.json")) == []


@pytest.mark.parametrize("noise_scale,steps,seed", [
    ("0", "300", "0"), ("1", "300", "0"), ("10", "300", "1"), ("34", "2000", "0"),
    ("34.6", "300", "2"),
])
def test_simulate_makes_no_stream_the_reader_warns_of(tmp_path: Path, noise_scale, steps,
                                                       seed) -> None:
    """Noise scale 34 over 2000 steps drew a turn of 9.1 rad (5.1 of its sigmas, then the
    limit of a turn taken for degrees)."""
    out = tmp_path / "s.jsonl"
    assert _warnings(bomgraph("simulate", "--noise-scale", noise_scale, "--steps", steps,
                              "--seed", seed, "--out", out)) == []
    assert _warnings(bomgraph("run", out, "--method", "triangulate", "--out",
                              tmp_path / "e.json")) == []


def test_simulate_refuses_a_noise_scale_whose_bearings_mean_nothing(tmp_path: Path) -> None:
    """Scales 35 to 60 (bearing sigma 1.83 to pi rad) were written; the reader now warns of
    such a stream, so simulate refuses to make one, as it refuses scales above 60."""
    one_error(bomgraph("simulate", "--noise-scale", "35", "--out", tmp_path / "s.jsonl"),
              "noise_scale 35", "pi/sqrt(3)")
    assert not (tmp_path / "s.jsonl").exists()


# ---- a g2o bearing written in degrees -------------------------------------------------------

def test_a_g2o_bearing_beyond_a_full_turn_is_warned_of(tmp_path: Path, sim) -> None:
    """``bomgraph import g2o`` wrapped a bearing written in degrees silently (the stream then
    held a valid, wrong bearing, which its reader cannot tell); it is still wrapped (g2o
    wraps angles), with one warning naming the file, the line and the field."""
    g2o = tmp_path / "data.g2o"
    write_g2o(g2o, sim)
    lines = g2o.read_text().splitlines()
    k = next(n for n, ln in enumerate(lines) if ln.startswith("EDGE_BEARING_SE2_XY"))
    rec = lines[k].split()
    rec[3] = "57.0"                                             # degrees
    lines[k] = " ".join(rec)
    g2o.write_text("\n".join(lines) + "\n")
    proc = bomgraph("import", "g2o", g2o, "--out", tmp_path / "s.jsonl")
    warned = _warnings(proc)
    assert len(warned) == 1 and warned[0].startswith(
        f"bomgraph: WARNING: {g2o}, line {k + 1}: field 'bearing': 57 is more than a full "
        f"turn"), warned
    assert _warnings(bomgraph("run", tmp_path / "s.jsonl", "--method", "triangulate", "--out",
                              tmp_path / "e.json")) == []
