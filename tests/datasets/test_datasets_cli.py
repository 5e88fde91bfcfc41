"""The ``bomgraph import`` commands for the three formats."""

from __future__ import annotations

from dataset_excerpts import VICTORIA, make_mrclam, write_g2o

from bomgraph.datasets.mrclam import import_mrclam
from bomgraph.stream_file import read_stream


def test_cli_import_commands(tmp_path, sim_stream, capsys):
    from bomgraph.cli import main

    make_mrclam(tmp_path / "m")
    assert main(["import", "mrclam", str(tmp_path / "m"), "--robot", "1", "--out",
                 str(tmp_path / "m.jsonl")]) == 0
    assert read_stream(tmp_path / "m.jsonl") == import_mrclam(tmp_path / "m", 1)
    write_g2o(tmp_path / "a.g2o", sim_stream)
    assert main(["import", "g2o", str(tmp_path / "a.g2o"), "--truth", str(tmp_path / "a.g2o"),
                 "--out", str(tmp_path / "g.jsonl")]) == 0
    assert read_stream(tmp_path / "g.jsonl").truth == sim_stream.truth
    (tmp_path / "v.txt").write_text(VICTORIA)
    assert main(["import", "victoria", str(tmp_path / "v.txt"), "--out",
                 str(tmp_path / "v.jsonl")]) == 0
    assert "4 steps, 3 bearings, 2 landmarks" in capsys.readouterr().out
    (tmp_path / "v.txt").write_text(VICTORIA + "LANDMARK 3 6 1.0 oops 0.4 0 0.4\n")
    assert main(["import", "victoria", str(tmp_path / "v.txt"), "--out",
                 str(tmp_path / "x.jsonl")]) == 2
    err = capsys.readouterr().err
    assert "v.txt, line 7: field 'y'" in err and not (tmp_path / "x.jsonl").exists()


def test_cli_import_mrclam_odometry_scale(tmp_path, capsys):
    from bomgraph.cli import main

    make_mrclam(tmp_path / "m")
    assert main(["import", "mrclam", str(tmp_path / "m"), "--robot", "1", "--out",
                 str(tmp_path / "s.jsonl"), "--odometry-scale", "0.95"]) == 0
    assert read_stream(tmp_path / "s.jsonl") == import_mrclam(tmp_path / "m", 1,
                                                              odometry_scale=0.95)
    assert read_stream(tmp_path / "s.jsonl").header.meta["odometry_scale"] == 0.95
    capsys.readouterr()
    assert main(["import", "mrclam", str(tmp_path / "m"), "--robot", "1", "--out",
                 str(tmp_path / "x.jsonl"), "--odometry-scale", "3"]) == 2
    err = capsys.readouterr().err
    assert "odometry_scale must be a number in [0.5, 2]" in err and err.count("\n") == 1
    assert not (tmp_path / "x.jsonl").exists()


def test_import_summary_line_gives_units_and_says_when_each_step_has_its_own_sigma(
        tmp_path, sim_stream, capsys):
    """The line ``bomgraph import`` prints: the odometry sigmas with their units (m, m, rad),
    and, when the steps carry their own sigmas (the calibrated MRCLAM import: a model per
    step), that the figures are their median. Before the twenty-first session's report audit
    it printed ``odometry sigma 0.0408, 0.0106, 0.0486`` with no unit, the header's median
    of per-step sigmas spanning 0.005-0.24 m on MRCLAM6 robot 3, as if it were the sigma."""
    import numpy as np

    from bomgraph.cli import main

    make_mrclam(tmp_path / "m")
    assert main(["import", "mrclam", str(tmp_path / "m"), "--robot", "1", "--out",
                 str(tmp_path / "m.jsonl")]) == 0
    s = read_stream(tmp_path / "m.jsonl")
    own = np.array([st.odometry_sigma(s.header) for st in s.steps if st.odom is not None])
    assert any(st.odom_sigma is not None for st in s.steps)
    med = np.median(own, axis=0)
    out = capsys.readouterr().out
    assert (f"odometry sigma per step, median {med[0]:.4f} m, {med[1]:.4f} m, "
            f"{med[2]:.4f} rad;") in out
    write_g2o(tmp_path / "a.g2o", sim_stream)
    assert main(["import", "g2o", str(tmp_path / "a.g2o"), "--out",
                 str(tmp_path / "g.jsonl")]) == 0
    g = read_stream(tmp_path / "g.jsonl")
    assert all(st.odom_sigma is None for st in g.steps)
    sig = g.header.odometry_sigma
    assert (f"odometry sigma {sig[0]:.4f} m, {sig[1]:.4f} m, {sig[2]:.4f} rad;"
            in capsys.readouterr().out)


def test_import_g2o_summary_names_the_priors_and_the_fix_it_carried(tmp_path, capsys):
    """A g2o file written by ``bomgraph export --format g2o`` carries the stream's priors
    (landmark distances) in its ``# bomgraph header`` comment, and the import puts them back
    into the stream; its summary line did not say so (h92: 38 priors imported, none named).
    A FIX record (the gauge; the Sapienza file fixes pose 1498) is recorded in meta and used
    by no method: the line says that too. Fails before h92."""
    import numpy as np

    from bomgraph.cli import main
    from bomgraph.sim import SimConfig, make_priors, simulate, with_priors
    from bomgraph.stream_file import write_stream

    s = simulate(SimConfig(n_steps=25, n_landmarks=20), np.random.default_rng(4))
    s = with_priors(s, make_priors(s.truth, 0.2, 0.03, np.random.default_rng(5)))
    n = len(s.header.priors)
    assert n > 0
    write_stream(s, tmp_path / "p.jsonl")
    assert main(["export", "--truth", str(tmp_path / "p.jsonl"), "--format", "g2o",
                 "--out", str(tmp_path / "p.g2o")]) == 0
    text = (tmp_path / "p.g2o").read_text()
    assert "\nFIX 20\n" in text  # its first pose: the gauge
    capsys.readouterr()
    assert main(["import", "g2o", str(tmp_path / "p.g2o"), "--out",
                 str(tmp_path / "back.jsonl")]) == 0
    assert len(read_stream(tmp_path / "back.jsonl").header.priors) == n
    out = capsys.readouterr().out
    assert f"; {n} priors (landmark distances);" in out, out
    assert "; FIX of vertex 20 (step 0) not used: a gauge;" in out, out
    (tmp_path / "nofix.g2o").write_text(text.replace("\nFIX 20\n", "\n"))
    assert main(["import", "g2o", str(tmp_path / "nofix.g2o"), "--out",
                 str(tmp_path / "plain.jsonl")]) == 0
    out = capsys.readouterr().out
    assert "FIX" not in out and f"{n} priors" in out
    make_mrclam(tmp_path / "m")
    assert main(["import", "mrclam", str(tmp_path / "m"), "--robot", "1", "--out",
                 str(tmp_path / "m.jsonl")]) == 0
    assert "prior" not in capsys.readouterr().out  # none: not a word about them


def test_import_summary_of_one_pose_says_no_odometry_and_counts_in_the_singular(tmp_path,
                                                                                capsys):
    """A g2o file of one pose (bearings, no EDGE_SE2) imports as a stream of one step and no
    odometry; its summary line said ``1 steps, 1 bearings, 1 landmarks; ... odometry sigma
    0.0000 m, 0.0000 m, 0.0000 rad``, as if the odometry were exact; it says ``no
    odometry`` now, and counts one step, bearing, landmark and prior in the singular (h93's
    review of h92, who wrote ``1 prior`` but left ``1 steps``). Fails before h93."""
    from bomgraph.cli import main

    (tmp_path / "one.g2o").write_text(
        '# bomgraph header: {"priors": [{"i": 100, "j": 101, "distance_m": 5.0, '
        '"sigma_m": 0.1}]}\nVERTEX_SE2 1 0 0 0\nVERTEX_XY 100 5 0\nVERTEX_XY 101 0 5\n'
        "EDGE_BEARING_SE2_XY 1 100 0.0 400\nFIX 1\n")
    assert main(["import", "g2o", str(tmp_path / "one.g2o"), "--out",
                 str(tmp_path / "one.jsonl")]) == 0
    out = capsys.readouterr().out
    assert "1 step, 1 bearing, 1 landmark; " in out, out
    assert "odometry sigma" not in out and ", no odometry; 1 prior (landmark distances); " in out
