"""``NAME@PRESET`` means the same everywhere: ``run --method stmds-smacof@improved`` (it was
an unknown method there, though ``compare --methods`` takes it), and ``evaluate`` names the
estimate's method with its preset (it said ``stmds-smacof`` of an ``@improved`` estimate)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bomgraph.cli import main
from bomgraph.estimate_file import read_estimate


@pytest.fixture
def stream(tmp_path: Path) -> Path:
    s = tmp_path / "s.jsonl"
    assert main(["simulate", "--steps", "60", "--landmarks", "15", "--out", str(s)]) == 0
    return s


def test_run_takes_name_at_preset_as_the_preset_option(stream: Path, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture) -> None:
    at, opt = tmp_path / "at.est", tmp_path / "opt.est"
    assert main(["run", str(stream), "--method", "stmds-smacof@improved", "--out", str(at)]) == 0
    assert capsys.readouterr().out.startswith("stmds-smacof@improved: ")  # the label, as given
    assert main(["run", str(stream), "--method", "stmds-smacof", "--option", "preset=improved",
                 "--out", str(opt)]) == 0
    a, b = read_estimate(at), read_estimate(opt)
    assert a.method == b.method == "stmds-smacof" and a.options == b.options == {
        "preset": "improved"}
    assert (a.final.landmarks_xy == b.final.landmarks_xy).all()
    capsys.readouterr()
    # the evaluation names the setting, in text and JSON, for the estimate and a reference
    assert main(["evaluate", str(at), str(stream)]) == 0
    assert "method stmds-smacof@improved:" in capsys.readouterr().out
    assert main(["evaluate", str(at), str(stream), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["method"] == "stmds-smacof@improved"
    plain = tmp_path / "plain.est"
    assert main(["run", str(stream), "--method", "ekf", "--out", str(plain)]) == 0
    capsys.readouterr()
    assert main(["evaluate", str(plain), str(stream), "--reference", str(at), "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["method"] == "ekf" and got["reference"] == "stmds-smacof@improved"


@pytest.mark.parametrize("method, says", [
    ("stmds-smacof@nope", "unknown preset 'nope' of stmds-smacof"),
    ("stmds-smacof@", "is not NAME or NAME@PRESET"),
    ("nosuch@real", "unknown method 'nosuch'")])
def test_run_refuses_a_bad_name_at_preset_in_one_line(stream: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture,
                                                      method: str, says: str) -> None:
    out = tmp_path / "e.est"
    assert main(["run", str(stream), "--method", method, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0] and "--method" in err[0], err
    assert not out.exists()
    assert main(["run", str(stream), "--method", "stmds-smacof@improved", "--option",
                 "preset=paper", "--out", str(out)]) == 2
    assert "give the preset once" in capsys.readouterr().err


def test_plot_titles_the_estimate_with_its_preset(stream: Path, tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """``plot`` titled an ``@improved`` estimate ``stmds-smacof``, unlike ``evaluate``."""
    from bomgraph import figures

    est = tmp_path / "at.est"
    assert main(["run", str(stream), "--method", "stmds-smacof@improved", "--out", str(est)]) == 0
    titles: list[str] = []
    real = figures.write_figure

    def keep_title(fig, path, dpi):
        titles.append(" ".join(t.get_text() for ax in fig.axes for t in [ax.title]
                               ) + " " + (fig._suptitle.get_text() if fig._suptitle else ""))
        return real(fig, path, dpi)

    monkeypatch.setattr(figures, "write_figure", keep_title)
    figures.plot_run(est, stream, tmp_path / "m.png")
    assert titles and "stmds-smacof@improved" in titles[0], titles


def test_config_and_preset_together_are_refused_in_a_readable_line() -> None:
    """The message glued two lists: "got config= with ['preset'][]" (h50 noticed)."""
    from bomgraph.config import resolve
    from bomgraph.errors import ConfigError
    from bomgraph.stmds.config import StmdsConfig

    cfg = StmdsConfig.preset("paper")
    with pytest.raises(ConfigError, match=r"\(got config= with preset\)$"):
        resolve(StmdsConfig, cfg, "improved")
    with pytest.raises(ConfigError, match=r"\(got config= with preset, window\)$"):
        resolve(StmdsConfig, cfg, "improved", {"window": 3})
    with pytest.raises(ConfigError, match=r"\(got config= with preset\)$"):  # was "with )"
        resolve(StmdsConfig, cfg, "")


def test_methods_says_what_name_at_preset_does_for_a_method_without_presets(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture) -> None:
    """``bomgraph methods NAME`` said "NAME@PRESET is refused" of every method without
    presets, though a factory taking ``**options`` gets ``preset=PRESET`` and runs (h50)."""
    from _depth_mapper import depth_mapper

    from bomgraph import mapper

    (tmp_path / "h25_any.py").write_text(depth_mapper("1.0"))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    mapper.register_method("any-options", "h25_any:DepthMapper", "takes any option")
    capsys.readouterr()
    assert main(["methods", "any-options"]) == 0
    out = capsys.readouterr().out
    assert out.rstrip().endswith(
        "presets: none declared (NAME@PRESET is passed on to the factory as preset=PRESET)")
    # h152: its options are any, not "none" (docs/USAGE.md's Factory(header, **options))
    assert "options: any (the factory takes **options" in out and "options: none" not in out
    # h154: and so does --json, where "options": [] read as none
    assert main(["methods", "any-options", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["any_option"] is True
    assert main(["methods", "triangulate", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["any_option"] is False


def test_methods_does_not_call_a_preset_parameter_of_the_factory_refused(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture) -> None:
    """A factory's own ``preset: Literal["fast", "slow"]`` parameter refuses the value
    "PRESET" the line was checked with, so ``methods NAME`` said "NAME@PRESET is refused"
    though ``NAME@fast`` runs (h51)."""
    from bomgraph import mapper

    (tmp_path / "h51_lit.py").write_text(
        "from typing import Literal\n"
        "class LitMapper:\n"
        "    def __init__(self, header, *, preset: Literal['fast', 'slow'] = 'fast'):\n"
        "        pass\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    mapper.register_method("lit", "h51_lit:LitMapper", "a preset parameter")
    mapper.check_method_options("lit", {"preset": "fast"})      # lit@fast is taken
    capsys.readouterr()
    assert main(["methods", "lit"]) == 0
    last = capsys.readouterr().out.rstrip().splitlines()[-1]
    assert "refused" not in last and "preset" in last, last


@pytest.mark.parametrize("args", [["--method", "stmds-smacof@improved"],
                                  ["--method", "stmds-smacof", "--option", "preset=improved"]])
def test_run_names_the_preset_however_it_is_given(stream: Path, tmp_path: Path, args: list,
                                                  capsys: pytest.CaptureFixture) -> None:
    """``run --method X --option preset=P`` said ``X: N landmarks ...`` (and ``"method": "X"``
    in ``--json``) where ``--method X@P`` said ``X@P``, for the same run, and ``evaluate`` of
    either estimate says ``X@P`` (h53); fails before for the ``--option`` form."""
    est = tmp_path / "e.est"
    assert main(["run", str(stream), *args, "--out", str(est)]) == 0
    assert capsys.readouterr().out.startswith("stmds-smacof@improved: ")
    assert main(["run", str(stream), *args, "--out", str(est), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["method"] == "stmds-smacof@improved"


def test_compare_labels_a_preset_option_as_name_at_preset(stream: Path, tmp_path: Path) -> None:
    """``compare --methods X@paper,X@improved --option X:preset=real`` ran both arms with
    ``real`` under their ``@paper`` and ``@improved`` labels (two identical rows named as
    two settings); ``--option X:preset=P`` on ``--methods X`` and a sweep file's
    ``options = { preset = "P" }`` labelled the arm ``X`` (h53). Fails before."""
    from bomgraph.command_line_sweep import command_line_spec
    from bomgraph.sweep import SweepError, read_sweep

    with pytest.raises(SweepError, match="give the preset once"):
        command_line_spec([str(stream)], ["stmds-smacof@paper", "stmds-smacof@improved"],
                          ["stmds-smacof:preset=real"])
    spec = command_line_spec([str(stream)], ["stmds-smacof", "ekf"],
                             ["stmds-smacof:preset=improved"])
    assert [(m.label, dict(m.options)) for m in spec.experiments[0].methods] == [
        ("stmds-smacof@improved", {"preset": "improved"}), ("ekf", {})]
    toml = tmp_path / "s.toml"
    toml.write_text(f'streams = ["{stream.name}"]\n[[methods]]\nname = "stmds-smacof"\n'
                    f'options = {{ preset = "improved" }}\n')
    (exp,) = read_sweep(toml).experiments
    assert [m.label for m in exp.methods] == ["stmds-smacof@improved"]


def test_a_preset_given_twice_names_the_option_as_written(stream: Path, tmp_path: Path,
                                                          capsys: pytest.CaptureFixture) -> None:
    """It named ``--option stmds-cs:preset=...`` for ``--option stmds-cs@improved:preset=``
    (h56); fails before."""
    assert main(["compare", "--streams", str(stream), "--methods", "stmds-cs@improved",
                 "--option", "stmds-cs@improved:preset=paper", "--out", str(tmp_path / "o"),
                 "--dry-run"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--option stmds-cs@improved:preset=..." in err[0], err
