"""The one preset mechanism: Presets.preset and resolve."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import pytest

from bomgraph.config import Presets, resolve
from bomgraph.errors import ConfigError


@dataclass(frozen=True)
class Toy(Presets):
    a: int = 1
    b: float = 2.0

    PRESETS: ClassVar = {"paper": {}, "big": {"a": 10}}

    def __post_init__(self) -> None:
        if not self.a > 0:
            raise ConfigError("a must be > 0")


def test_presets_apply_overrides_and_refuse_unknowns() -> None:
    assert Toy.preset() == Toy()
    assert Toy.preset("big") == Toy(a=10)
    assert Toy.preset("big", b=3.0) == Toy(a=10, b=3.0)
    assert Toy.preset_names() == ("paper", "big")
    with pytest.raises(ConfigError, match="unknown Toy preset 'huge'"):
        Toy.preset("huge")
    with pytest.raises(ConfigError, match="unknown option.*c.*valid options: a, b"):
        Toy.preset(c=1)
    with pytest.raises(ConfigError, match="bad option value"):
        Toy.preset(a="abc")  # '>' between str and int: a TypeError becomes a ConfigError


def test_resolve_takes_a_config_alone_or_a_preset_with_options() -> None:
    cfg = Toy(a=5)
    assert resolve(Toy, cfg) is cfg
    assert resolve(Toy, None, "big", {"b": 1.0}) == Toy(a=10, b=1.0)
    assert resolve(Toy, None, None, {}) == Toy()
    with pytest.raises(ConfigError, match="not both"):
        resolve(Toy, cfg, "big")
    with pytest.raises(ConfigError, match="not both"):
        resolve(Toy, cfg, None, {"a": 2})
    with pytest.raises(ConfigError, match="must be a Toy"):
        resolve(Toy, object())  # type: ignore[arg-type]


def test_requirement_names_its_owner() -> None:
    from bomgraph.config import requirement

    need = requirement("Toy")
    need(True, "never raised")
    with pytest.raises(ConfigError, match="^Toy: a must be > 0$"):
        need(False, "a must be > 0")


def test_every_option_of_every_method_has_a_one_line_doc() -> None:
    from bomgraph.config import describe_options
    from bomgraph.mapper import available_methods, method_config_class

    for m in available_methods():
        if m.origin != "builtin":  # an installed plugin documents its options as it likes
            continue
        cls = method_config_class(m.name)
        assert cls is not None, m.name
        missing = [o.name for o in describe_options(cls) if not o.doc]
        assert missing == [], f"{m.name}: {missing}"


def test_informal_and_inherited_attribute_docs_are_read() -> None:
    from bomgraph.config import describe_options

    @dataclass(frozen=True)
    class Base(Presets):
        """Base options.

        a : the first option. More text.
        b, c : two options sharing
            one line.
        """

        a: int = 1
        b: int = 2
        c: int = 3

    @dataclass(frozen=True)
    class Child(Base):
        """Child options.

        Attributes
        ----------
        d : float
            The fourth one.
        """

        d: float = 0.5

    docs = {o.name: o.doc for o in describe_options(Child)}
    assert docs == {"a": "the first option", "b": "two options sharing one line",
                    "c": "two options sharing one line", "d": "The fourth one"}


def test_an_abbreviation_does_not_end_an_option_doc() -> None:
    """``std. dev. (m)`` is not the end of a sentence: ``bomgraph methods hybrid-isam2`` showed
    ``seed_sigma_m`` as "Std. dev" and the EKFs' ``wide_prior_heading_sd_rad`` as "... heading
    std. dev" (h20)."""
    from bomgraph.config import describe_options
    from bomgraph.mapper import method_config_class

    @dataclass(frozen=True)
    class Opts(Presets):
        """Options.

        Attributes
        ----------
        s : float
            Std. dev. (m) of a prior, e.g. (here) one. Then more.
        """

        s: float = 1.0

    assert {o.name: o.doc for o in describe_options(Opts)} == {
        "s": "Std. dev. (m) of a prior, e.g. (here) one"}
    seed = {o.name: o.doc for o in describe_options(method_config_class("hybrid-isam2"))}
    assert seed["seed_sigma_m"].startswith("Std. dev. (m) of a prior put on a seeded landmark")
    ekf = {o.name: o.doc for o in describe_options(method_config_class("ekf"))}
    assert "std. dev. (rad) exceeds this" in ekf["wide_prior_heading_sd_rad"]



@dataclass(frozen=True)
class _Pair(Presets):
    sigma: tuple[float, ...] = (1.0, 1.0)


def test_a_bad_item_of_a_tuple_option_says_it_must_be_a_number() -> None:
    # the message read "each item be a number" (its "must" cut off)
    with pytest.raises(ConfigError, match="sigma=.*: each item must be a number$"):
        _Pair.preset(sigma=["a", 1])
