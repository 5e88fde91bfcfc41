"""h97's review of h96's clipped echo (``checks.echo``, ``MAX_ECHO_CHARS`` = 80): it cut
the ``repr`` of a value, quotes and escapes included, so an 80-character value lost its last
character, a 79-character one was echoed whole but with ``...`` for its closing quote (as if
cut), and an escape such as ``\\x00`` could be cut in half. An unknown option key holding a
newline split the one-line error in two (before h96 too). Each test failed before the fix
(but the 1-character case, kept as the baseline)."""

from __future__ import annotations

import pytest

from bomgraph.checks import MAX_ECHO_CHARS, echo
from bomgraph.errors import ConfigError
from bomgraph.mapper import check_method_options


def _refusal(options: dict[str, object]) -> str:
    with pytest.raises(ConfigError) as info:
        check_method_options("triangulate", options)
    return str(info.value)


@pytest.mark.parametrize("n", [1, MAX_ECHO_CHARS - 1, MAX_ECHO_CHARS])
def test_a_value_of_up_to_80_characters_is_echoed_whole(n: int) -> None:
    message = _refusal({"min_parallax_rad": "a" * n})
    assert f"min_parallax_rad='{'a' * n}': must be a number" in message, message
    assert "..." not in message


def test_a_longer_value_is_cut_after_80_characters() -> None:
    message = _refusal({"min_parallax_rad": "a" * (MAX_ECHO_CHARS + 1)})
    assert f"min_parallax_rad='{'a' * MAX_ECHO_CHARS}...: must be a number" in message, message


def test_multibyte_characters_and_escapes_are_cut_whole() -> None:
    assert echo("é" * 90) == "'" + "é" * MAX_ECHO_CHARS + "..."
    assert echo("é" * 90).encode("utf-8").decode("utf-8")
    cut = echo("\x00" * 81)
    assert cut == "'" + "\\x00" * MAX_ECHO_CHARS + "...", cut[-12:]


def test_an_unknown_key_with_a_newline_stays_on_one_line() -> None:
    message = _refusal({"a\nb": 1.0})
    assert "\n" not in message
    assert "unknown option 'a\\nb'; valid options:" in message, message
    # a printable key is named as written, as before
    assert "unknown option typo; valid options:" in _refusal({"typo": 1.0})
