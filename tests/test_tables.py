"""Tables: a title or cell holding characters that LaTeX or Markdown treat as markup prints
as written. Checked by reading the output back with a small reader written apart from the
escaping (not by comparing with the escaping's own table)."""

from __future__ import annotations

import re

import pytest

from bomgraph.tables import Column, format_table

#: every printable ASCII character, LaTeX's ten specials and Markdown's markup among them
HOSTILE = "".join(chr(c) for c in range(32, 127)) + " méthode σ"

#: how LaTeX prints each escape sequence (what a reader of the compiled table sees)
_LATEX_PRINTS = {r"\textbackslash{}": "\\", r"\textasciitilde{}": "~",
                 r"\textasciicircum{}": "^"}


def _latex_read(text: str) -> str:
    """What LaTeX typesets for ``text`` in text mode, for the constructs an escaped string may
    hold; raises where a special character would act as markup instead of printing."""
    out, k = [], 0
    while k < len(text):
        word = next((w for w in _LATEX_PRINTS if text.startswith(w, k)), None)
        if word is not None:
            out.append(_LATEX_PRINTS[word])
            k += len(word)
        elif text[k] == "\\":
            assert text[k + 1] in "&%$#_{}", f"control sequence at {text[k:k + 12]!r}"
            out.append(text[k + 1])
            k += 2
        else:
            assert text[k] not in "&%$#_{}~^\\", f"unescaped {text[k]!r} at {k}"
            out.append(text[k])
            k += 1
    return "".join(out)


def test_latex_caption_prints_every_character_as_written() -> None:
    tex = format_table([Column("mpe_m", "MPE [cm]", 100, ".2f")], [{"mpe_m": 0.0123}],
                       "latex", title=HOSTILE)
    caption = re.search(r"^\\caption\{(.*)\}$", tex, re.M)
    assert caption is not None
    assert _latex_read(caption.group(1)) == HOSTILE
    assert "1.23 \\\\" in tex


def test_latex_backslash_then_brace() -> None:
    """The old escaping replaced ``\\`` by ``\\textbackslash{}`` first; a later pass over
    braces would have escaped those braces too. One pass keeps them."""
    tex = format_table([Column("t", "t")], [{"t": 1}], "latex", title="a\\{b}")
    assert _latex_read(re.search(r"\\caption\{(.*)\}", tex).group(1)) == "a\\{b}"


@pytest.mark.parametrize("title", [HOSTILE, "*my* method_v2 | [x](y) `z`"])
def test_markdown_title_shows_as_written(title: str) -> None:
    md = format_table([Column("t", "t")], [{"t": 1}], "markdown", title=title)
    first = md.splitlines()[0]
    assert first.startswith("**") and first.endswith("**")
    inner = first[2:-2]
    # CommonMark: a backslash before an ASCII punctuation character prints that character
    unescaped = re.sub(r"\\([!-/:-@\[-`{-~])", r"\1", inner)
    assert unescaped == title
    # and no markup character is left bare in the title
    assert not re.search(r"(?<!\\)[*_`|\[\]<>]", re.sub(r"\\\\", "", inner))


def _gfm_cells(line: str) -> list[str]:
    """The cells of one GitHub-flavoured Markdown table row, as a reader splits them: on
    every ``|`` not preceded by a backslash, the outer pipes dropped, each cell stripped and
    its backslash escapes of ASCII punctuation undone."""
    parts = re.split(r"(?<!\\)\|", line.strip())
    assert parts[0] == "" and parts[-1] == "", f"row not fenced by pipes: {line!r}"
    return [re.sub(r"\\([!-/:-@\[-`{-~])", r"\1", p.strip()) for p in parts[1:-1]]


@pytest.mark.parametrize("name", ["my|method", "*my* method_v2 | [x](y) `z`", HOSTILE.strip()])
def test_markdown_cells_and_headers_show_as_written(name: str) -> None:
    """A method (or file) name in a cell or a header keeps its table row's shape: a bare
    ``|`` split the cell in two and shifted every column after it."""
    md = format_table([Column("arm", name), Column("mpe_m", "MPE [cm]", 100, ".2f")],
                      [{"arm": name, "mpe_m": 0.0123}], "markdown")
    head, rule, row = md.splitlines()
    assert _gfm_cells(head) == [name, "MPE [cm]"]
    assert _gfm_cells(row) == [name, "1.23"]
    assert rule == "|---|---|"


def test_a_huge_value_in_a_fixed_point_column_prints_in_exponent_form() -> None:
    """A diverged map 1e300 m away printed 300 digits of centimetres in the text table."""
    cols = [Column("mpe_m", "MPE [cm]", 100, ".2f"), Column("n", "n")]
    txt = format_table(cols, [{"mpe_m": 1e300, "n": 3}, {"mpe_m": 0.0123, "n": 4}], "text")
    assert "1.000e+302" in txt and "1.23" in txt
    assert max(len(line) for line in txt.splitlines()) < 40
    # the machine-readable formats keep the value itself
    assert '"mpe_m": 1e+300' in format_table(cols, [{"mpe_m": 1e300, "n": 3}], "json")


def test_written_csv_ends_lines_as_the_printed_csv_does(tmp_path) -> None:
    """compare's CSV files (results.csv, estimates/index.csv) end lines in ``\\n`` as
    ``--format csv`` prints them: a shell's ``cut -d, -f5`` of index.csv gives the path
    without a carriage return (with ``\\r\\n`` it named no file). A value holding a comma or
    a newline is still quoted, and reads back."""
    import csv

    from bomgraph.tables import write_csv
    path = tmp_path / "t.csv"
    rows = [{"a": 1, "b": "x,y", "c": "two\nlines"}, {"a": 2, "b": "z", "c": "p.est"}]
    write_csv(path, rows)
    data = path.read_bytes()
    assert b"\r" not in data and data.endswith(b"\n")
    assert data.splitlines()[-1].split(b",")[-1] == b"p.est"
    with open(path, newline="") as fh:
        back = list(csv.DictReader(fh))
    assert [r["c"] for r in back] == ["two\nlines", "p.est"] and back[0]["b"] == "x,y"
