"""What a new user met (nineteenth session's walkthrough of the README): names that shadow
each other, messages that did not say what to do, settings that were dropped silently."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bomgraph import mapper
from bomgraph.cli import main
from bomgraph.errors import ConfigError
from bomgraph.mapper import create_mapper, method_info, register_method
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream


@pytest.fixture()
def registry(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))


def test_register_method_refuses_a_taken_name_unless_asked_to_replace(registry) -> None:
    with pytest.raises(ConfigError, match=r"'ekf' is taken \(builtin method "
                                          r"baselines.ekf.mappers:EkfMapper\).*replace=True"):
        register_method("ekf", "baselines.triangulate:TriangulateMapper", "not the EKF")
    assert method_info("ekf").target == "baselines.ekf.mappers:EkfMapper"
    register_method("mine", "baselines.triangulate:TriangulateMapper", "d")
    register_method("mine", "baselines.triangulate:TriangulateMapper", "d")  # the same: kept
    with pytest.raises(ConfigError, match="'mine' is taken"):
        register_method("mine", "baselines.ekf.mappers:EkfMapper", "d")
    register_method("mine", "baselines.ekf.mappers:EkfMapper", "d", replace=True)
    assert method_info("mine").target == "baselines.ekf.mappers:EkfMapper"
    register_method("ekf", "baselines.triangulate:TriangulateMapper", "d", replace=True)
    assert method_info("ekf").target == "baselines.triangulate:TriangulateMapper"


def test_a_method_that_reads_the_truth_says_how_to_give_it(tmp_path: Path, capsys) -> None:
    s = simulate(SimConfig(n_steps=12, n_landmarks=6), np.random.default_rng(1))
    with pytest.raises(ConfigError, match=r"truth=stream\.truth"):
        create_mapper("oracle", s.header)
    from bomgraph.stream import Stream

    write_stream(Stream(s.header, s.steps, None), tmp_path / "nt.jsonl")
    assert main(["run", str(tmp_path / "nt.jsonl"), "--method", "oracle", "--allow-truth",
                 "--out", str(tmp_path / "o.est")]) == 2
    err = capsys.readouterr().err
    assert "nt.jsonl: method 'oracle' reads the ground truth, and this stream has none" in err


RAYMEAN = '''
from dataclasses import dataclass
from typing import ClassVar, Mapping, Any

from bomgraph.config import Presets, resolve
from bomgraph.mapper import MapEstimate


@dataclass(frozen=True)
class RaymeanConfig(Presets):
    """Attributes
    ----------
    min_rays : rays before a landmark is mapped
    """

    min_rays: int = 2
    PRESETS: ClassVar[Mapping[str, Mapping[str, Any]]] = {"paper": {}, "real": {"min_rays": 4}}


class Raymean:
    """maps nothing (a plugin with a real preset)"""

    config_class = RaymeanConfig

    def __init__(self, header, *, config=None, preset=None, **options) -> None:
        self.config = resolve(RaymeanConfig, config, preset, **options)

    def step(self, step) -> None:
        pass

    def estimate(self):
        return MapEstimate.empty()


class Bare(Raymean):
    """no configuration class"""

    config_class = None

    def __init__(self, header) -> None:
        pass
'''


def test_compare_real_runs_a_plugins_real_preset_beside_its_defaults(
        registry, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from bomgraph.experiments import real_experiments, real_variants

    (tmp_path / "raymean_plugin.py").write_text(RAYMEAN)
    monkeypatch.syspath_prepend(str(tmp_path))
    register_method("raymean", "raymean_plugin:Raymean", "d")
    register_method("plain", "raymean_plugin:Bare", "d")
    assert real_variants("raymean") == (("raymean (real)", {"preset": "real"}),)
    assert real_variants("plain") == ()                       # no configuration, no presets
    assert real_variants("hybrid")[0] == ("hybrid (real seed)", {"preset": "real-seed"})
    (tmp_path / "data" / "mrclam6").mkdir(parents=True)
    exps = real_experiments(tmp_path / "data", methods=["raymean", "ekf"])
    assert [(a.label, dict(a.options)) for a in exps["mrclam6"].arms] == [
        ("raymean", {}), ("raymean (real)", {"preset": "real"}),
        ("ekf", {}), ("ekf (real)", {"preset": "real"})]


def test_tum_export_without_the_stream_says_its_stamps_are_step_indices(tmp_path: Path,
                                                                         capsys) -> None:
    s = simulate(SimConfig(n_steps=20, n_landmarks=6), np.random.default_rng(2))
    write_stream(s, tmp_path / "s.jsonl")
    assert main(["run", str(tmp_path / "s.jsonl"), "--method", "triangulate", "--out",
                 str(tmp_path / "e.est")]) == 0
    capsys.readouterr()
    assert main(["export", str(tmp_path / "e.est"), "--format", "tum", "--out",
                 str(tmp_path / "a.tum")]) == 0
    assert "TUM time stamps are step indices; give --stream FILE" in capsys.readouterr().err
    assert main(["export", str(tmp_path / "e.est"), "--stream", str(tmp_path / "s.jsonl"),
                 "--format", "tum", "--out", str(tmp_path / "b.tum")]) == 0
    assert "note" not in capsys.readouterr().err


def test_an_option_given_twice_is_refused_not_the_last_kept(tmp_path: Path, capsys) -> None:
    s = simulate(SimConfig(n_steps=20, n_landmarks=6), np.random.default_rng(3))
    write_stream(s, tmp_path / "s.jsonl")
    base = ["compare", "--streams", str(tmp_path / "s.jsonl"), "--out", str(tmp_path / "c"),
            "--no-figures", "--jobs", "1"]
    assert main([*base, "--methods", "stmds-cs", "--option", "stmds-cs:tri_window=4",
                 "--option", "stmds-cs:tri_window=6"]) == 2
    assert "stmds-cs:tri_window is given twice" in capsys.readouterr().err
    assert not (tmp_path / "c").exists()
    assert main(["run", str(tmp_path / "s.jsonl"), "--method", "stmds-cs", "--option",
                 "tri_window=4", "--option", "tri_window=6", "--out", str(tmp_path / "e.est")]) == 2
    assert "option tri_window is given twice" in capsys.readouterr().err
    # one arm by its label, over the method-wide value: allowed, and each arm gets its own
    from bomgraph.command_line_sweep import command_line_spec

    spec = command_line_spec([str(tmp_path / "s.jsonl")], ["stmds-cs", "stmds-cs@real"],
                             ["stmds-cs:min_degree=4", "stmds-cs@real:min_degree=5"])
    got = {a.label: a.options.get("min_degree") for a in spec.experiments[0].methods}
    assert got == {"stmds-cs": 4, "stmds-cs@real": 5}


def test_a_g2o_export_reads_back_with_its_sensor_range_and_time_stamps(tmp_path: Path) -> None:
    from dataclasses import replace

    from bomgraph.datasets.g2o import import_g2o
    from bomgraph.export import to_g2o
    from bomgraph.stream import Stream

    s = simulate(SimConfig(n_steps=15, n_landmarks=6), np.random.default_rng(5))
    s = Stream(replace(s.header, sensor_range_m=7.25),
               tuple(replace(st, time_s=100.0 + 0.25 * st.t) for st in s.steps), s.truth)
    est = mapper.MapEstimate(s.truth.landmark_ids, s.truth.landmarks_xy,
                             pose_t=np.arange(len(s.steps)), poses=s.truth.poses)
    (tmp_path / "a.g2o").write_text(to_g2o(est, s))
    back = import_g2o(tmp_path / "a.g2o")
    assert back.header.sensor_range_m == 7.25
    assert [st.time_s for st in back.steps] == [st.time_s for st in s.steps]
    assert all(a.t == b.t and np.array_equal(a.landmark_ids, b.landmark_ids)
               for a, b in zip(back.steps, s.steps))
    # what an older export (no header comment) or another tool's file gives: as before
    text = (tmp_path / "a.g2o").read_text()
    plain = "".join(ln for ln in text.splitlines(keepends=True)
                    if not ln.startswith("# bomgraph header: "))
    (tmp_path / "b.g2o").write_text(plain)
    old = import_g2o(tmp_path / "b.g2o")
    assert old.header.sensor_range_m is None and old.steps[3].time_s is None


@pytest.mark.parametrize("comment, what", [
    ('{"sensor_range_m": -1}', "sensor_range_m must be a number > 0"),
    ('{"sensor_range_m": 5, "time_s": [1, 2]}', "time_s has 2 stamps for 16 poses"),
    ('{"colour": "red"}', "sensor_range_m, time_s and priors only"),
    ('{"sensor_range_m": 5', "not JSON"),
])
def test_a_bad_bomgraph_header_comment_is_refused_naming_its_line(tmp_path: Path, comment: str,
                                                                  what: str) -> None:
    from bomgraph.datasets.g2o import import_g2o
    from bomgraph.errors import DatasetError
    from bomgraph.export import to_g2o

    s = simulate(SimConfig(n_steps=15, n_landmarks=6), np.random.default_rng(5))
    est = mapper.MapEstimate(s.truth.landmark_ids, s.truth.landmarks_xy,
                             pose_t=np.arange(len(s.steps)), poses=s.truth.poses)
    lines = to_g2o(est, s).splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith("# bomgraph header: "))
    lines[k] = "# bomgraph header: " + comment
    (tmp_path / "c.g2o").write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError, match=f"c.g2o, line {k + 1}.*{what}"):
        import_g2o(tmp_path / "c.g2o")


def test_summary_columns_widen_for_wide_cells_and_stay_aligned() -> None:
    from bomgraph.report import format_summary

    def row(arm: str, mean_m: float) -> dict:
        return {"experiment": "e", "arm": arm, "method": arm, "runs": 25, "failed": 0,
                "errors": [], "n_scored@50": 25, "mpe_mean_m@50": mean_m,
                "mpe_median_m@50": mean_m, "mpe_std_m@50": mean_m * 1.1, "wall_s_mean": 0.1}

    lines = format_summary([row("narrow", 0.012), row("first-sight", 1601.9)]).splitlines()
    head, narrow, wide = lines[-3:]
    assert "160190.00/160190.00±176209.00" in wide
    # each row's MPE cell ends where the header's t=50 ends
    end = head.index("t=50") + len("t=50")
    assert narrow[:end].endswith("1.20/1.20±1.32") and wide[:end].endswith("176209.00")


CRASH_KINDS = '''
from bomgraph.errors import ConfigError
from bomgraph.mapper import MapEstimate


class Refuses:
    """refuses its stream at t = 3 (a BomgraphError: the user's to fix)"""

    def __init__(self, header) -> None:
        pass

    def step(self, step) -> None:
        if step.t == 3:
            raise ConfigError("this stream has no odometry sigma for me")

    def estimate(self):
        return MapEstimate.empty()


class Disk(Refuses):
    """an OSError from inside the method"""

    def step(self, step) -> None:
        if step.t == 3:
            raise OSError(28, "No space left on device")
'''


def test_a_refusal_from_a_method_exits_2_an_oserror_from_it_exits_1(
        registry, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    (tmp_path / "crash_kinds.py").write_text(CRASH_KINDS)
    monkeypatch.syspath_prepend(str(tmp_path))
    register_method("refuses", "crash_kinds:Refuses", "d")
    register_method("disk", "crash_kinds:Disk", "d")
    s = simulate(SimConfig(n_steps=10, n_landmarks=5), np.random.default_rng(6))
    write_stream(s, tmp_path / "s.jsonl")
    out = tmp_path / "e.est"
    assert main(["run", str(tmp_path / "s.jsonl"), "--method", "refuses", "--out", str(out)]) == 2
    assert capsys.readouterr().err.strip() == (
        "bomgraph: error: this stream has no odometry sigma for me (raised in Refuses.step() "
        "at t = 3)")
    assert main(["run", str(tmp_path / "s.jsonl"), "--method", "disk", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "method disk failed: OSError: [Errno 28] No space left on device (raised in " \
           "Disk.step() at t = 3)" in err and "--out" not in err
    # a failing reference (used on a stream without truth): FAILED with where, exit 1
    from bomgraph.stream import Stream

    write_stream(Stream(s.header, s.steps, None), tmp_path / "nt.jsonl")
    assert main(["compare", "--streams", str(tmp_path / "nt.jsonl"), "--methods", "triangulate",
                 "--reference", "disk", "--out", str(tmp_path / "c"), "--no-figures",
                 "--jobs", "1"]) == 1
    assert "reference disk failed: OSError: [Errno 28] No space left on device (raised in " \
           "Disk.step() at t = 3)" in capsys.readouterr().err


def test_register_method_same_target_again_is_kept_other_needs_truth_refused(registry) -> None:
    register_method("mine2", "baselines.triangulate:TriangulateMapper", "first words")
    register_method("mine2", "baselines.triangulate:TriangulateMapper", "edited words")
    assert method_info("mine2").description == "edited words"
    with pytest.raises(ConfigError, match=r"'mine2' is taken \(runtime method baselines"
                                          r"\.triangulate:TriangulateMapper, needs_truth=False"):
        register_method("mine2", "baselines.triangulate:TriangulateMapper", "d",
                        needs_truth=True)


def test_the_empirical_prior_needs_inverse_depth_and_reports_itself() -> None:
    s = simulate(SimConfig(n_steps=40), np.random.default_rng(7))
    with pytest.raises(ConfigError, match="rho_prior='empirical' needs candidates="):
        create_mapper("ekf", s.header, rho_prior="empirical")
    from bomgraph.mapper import run

    info = run(create_mapper("ekf-invdepth", s.header, rho_prior="empirical"), s.steps).final.info
    rho, sd = info["rho_prior_per_m"]
    assert info["rho_prior_from_features"] >= 1 and 0 < sd <= rho      # sd = max(rho/2, MAD)
    assert info["rho_prior_from"] == "empirical"
    # the range prior says where it came from: the stated range, or Civera's default without
    from dataclasses import replace

    r = s.header.sensor_range_m
    info = run(create_mapper("ekf-invdepth", s.header), s.steps).final.info
    assert info["rho_prior_per_m"] == [2.0 / r, 1.0 / r] and info["rho_prior_from"] == \
        "sensor_range_m"
    info = run(create_mapper("ekf-invdepth", replace(s.header, sensor_range_m=None)),
               s.steps).final.info
    assert info["rho_prior_per_m"] == [0.1, 0.5] and "no sensor_range_m" in info["rho_prior_from"]
    assert "rho_prior_from" not in run(create_mapper("ekf", s.header), s.steps).final.info


@pytest.mark.parametrize("line", ['#bomgraph header:{"sensor_range_m":7.25}',
                                  '#  bomgraph header:   {"sensor_range_m": 7.25}'])
def test_the_g2o_header_comment_is_read_however_it_is_spaced(tmp_path: Path, line: str) -> None:
    from bomgraph.datasets.g2o import import_g2o
    from bomgraph.export import to_g2o

    s = simulate(SimConfig(n_steps=8, n_landmarks=5), np.random.default_rng(8))
    est = mapper.MapEstimate(s.truth.landmark_ids, s.truth.landmarks_xy,
                             pose_t=np.arange(len(s.steps)), poses=s.truth.poses)
    text = "\n".join(line if ln.startswith("# bomgraph header: ") else ln
                     for ln in to_g2o(est, s).splitlines()) + "\n"
    (tmp_path / "h.g2o").write_text(text)
    assert import_g2o(tmp_path / "h.g2o").header.sensor_range_m == 7.25


def test_the_tum_note_is_quiet_with_q(tmp_path: Path, capsys) -> None:
    s = simulate(SimConfig(n_steps=12, n_landmarks=5), np.random.default_rng(9))
    write_stream(s, tmp_path / "s.jsonl")
    assert main(["run", str(tmp_path / "s.jsonl"), "--method", "triangulate", "--out",
                 str(tmp_path / "e.est")]) == 0
    capsys.readouterr()
    assert main(["-q", "export", str(tmp_path / "e.est"), "--format", "tum", "--out",
                 str(tmp_path / "a.tum")]) == 0
    assert capsys.readouterr().err == ""
