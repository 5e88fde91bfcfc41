"""h96 (from h91's notes): a refusal that echoes an option's value repeated all of it:
``compare --option 'triangulate:min_parallax_rad=[[[...]]]'`` of 100,000 characters gave a
200,147-character error line (the value twice). Values and unknown keys are now echoed to
80 characters and ``...``. Each test failed before the fix."""

from __future__ import annotations

from pathlib import Path

import pytest

from bomgraph.errors import ConfigError
from bomgraph.mapper import check_method_options
from bomgraph.sweep import SweepError, read_sweep

LONG = "[" * 5_000 + "]" * 5_000


@pytest.mark.parametrize("options", [{"min_parallax_rad": LONG}, {LONG: 1.0}])
def test_a_bad_option_is_echoed_in_part(options: dict[str, object]) -> None:
    with pytest.raises(ConfigError) as info:
        check_method_options("triangulate", options)
    message = str(info.value)
    assert len(message) < 300 and "[[[..." in message and "\n" not in message


def test_a_sweep_methods_options_are_echoed_in_part(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    path.write_text(f'name = "x"\n[[worlds]]\nname = "w"\nn_steps = 15\nn_landmarks = 6\n'
                    f'seeds = 1\n[[methods]]\nname = "triangulate"\n'
                    f'options = {{ min_parallax_rad = "{LONG}" }}\n')
    with pytest.raises(SweepError) as info:
        read_sweep(path)
    message = str(info.value)
    assert len(message) < 500 and "options {'min_parallax_rad': '[[[[" in message, message[:300]
