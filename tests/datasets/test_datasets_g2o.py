"""Bearing-only g2o importer: synthetic files from a simulated stream, malformed lines, the real set."""

from __future__ import annotations

import numpy as np
import pytest
from dataset_excerpts import DATA, INFO, needs_data, write_g2o

from bomgraph.datasets.calibration import bearing_residuals
from bomgraph.datasets.g2o import import_g2o, odometry_sigma_from_information
from bomgraph.errors import DatasetError
from bomgraph.geometry import between
from bomgraph.stream_file import read_stream, write_stream


def test_g2o_excerpt_reproduces_the_simulated_stream(tmp_path, sim_stream):
    write_g2o(tmp_path / "a.g2o", sim_stream)
    s = import_g2o(tmp_path / "a.g2o", truth_path=tmp_path / "a.g2o")
    assert len(s.steps) == len(sim_stream.steps)
    for a, b in zip(s.steps, sim_stream.steps):
        assert a.t == b.t and a.odom_sigma is None
        np.testing.assert_array_equal(a.landmark_ids, b.landmark_ids)
        np.testing.assert_array_equal(a.bearings_rad, b.bearings_rad)
        if b.odom is not None:
            np.testing.assert_array_equal(a.odom, b.odom)
    assert s.truth == sim_stream.truth
    assert s.header.odometry_sigma == pytest.approx((500 ** -0.5, 500 ** -0.5, 5000 ** -0.5))
    assert s.header.bearing_sigma_rad == pytest.approx(57295.8 ** -0.5)
    assert s.header.meta["fixed_steps"] == [0]
    assert s.header.meta["pose_ids"] == list(range(1200, 1226))
    assert s.header.meta["truth_check"]["bearing"]["max_abs_rad"] < 0.2
    write_stream(s, tmp_path / "a.jsonl")
    assert read_stream(tmp_path / "a.jsonl") == s


def test_g2o_line_order_does_not_matter(tmp_path, sim_stream):
    write_g2o(tmp_path / "a.g2o", sim_stream)
    write_g2o(tmp_path / "b.g2o", sim_stream, shuffle_seed=11)
    a = import_g2o(tmp_path / "a.g2o", truth_path=tmp_path / "a.g2o")
    b = import_g2o(tmp_path / "b.g2o", truth_path=tmp_path / "b.g2o")
    assert a.steps == b.steps and a.truth == b.truth


def test_g2o_varying_information_gives_per_step_sigma(tmp_path, sim_stream):
    infos = [f"{100 * (k + 1)} 0 0 {100 * (k + 1)} 0 {1000 * (k + 1)}" for k in range(25)]
    write_g2o(tmp_path / "a.g2o", sim_stream, info=infos)
    s = import_g2o(tmp_path / "a.g2o")
    assert s.truth is None and s.header.meta["odometry_sigma_per_step"]
    # step 3 has the third edge: information (300, 300, 3000)
    np.testing.assert_allclose(s.steps[3].odom_sigma, 1 / np.sqrt([300, 300, 3000]))
    np.testing.assert_allclose(s.header.odometry_sigma,
                               np.median([st.odom_sigma for st in s.steps[1:]], axis=0))


def test_g2o_information_conversion_against_numeric_jacobian():
    """The g2o error e(delta) = toVector(Z^-1 X(delta)); Sigma_stream = Je^-1 Omega^-1 Je^-T."""
    z = np.array([0.7, -0.2, 0.9])
    a = np.array([[2.0, 0.3, 0.1], [0.3, 1.0, -0.2], [0.1, -0.2, 0.5]])
    omega = np.linalg.inv(a @ a.T * 1e-3)
    eps = 1e-7
    jac = np.zeros((3, 3))
    for k in range(3):
        d = np.zeros(3)
        d[k] = eps
        jac[:, k] = (between(z, z + d) - between(z, z - d)) / (2 * eps)
    jinv = np.linalg.inv(jac)
    cov = jinv @ np.linalg.inv(omega) @ jinv.T
    sigma, corr = odometry_sigma_from_information(z[2], omega)
    np.testing.assert_allclose(sigma, np.sqrt(np.diag(cov)), rtol=1e-6)
    expected = np.max(np.abs((cov / np.outer(sigma, sigma))[np.triu_indices(3, 1)]))
    assert corr == pytest.approx(expected, rel=1e-5)


@pytest.mark.parametrize("extra, pattern", [
    (["EDGE_SE2_XY 1200 3 1.0 2.0 1 0 1"], r"line \d+: field 'tag': unsupported record"),
    (["EDGE_BEARING_SE2_XY 1201 3 0.5"], r"line \d+: EDGE_BEARING_SE2_XY needs 4 fields"),
    (["EDGE_BEARING_SE2_XY 1201 3 zero 57295.8"], r"line \d+: field 'bearing': cannot read"),
    (["EDGE_BEARING_SE2_XY 1201 -3 0.1 57295.8"], r"line \d+: field 'l': vertex id must"),
    (["EDGE_BEARING_SE2_XY 1201 3 0.1 0"], r"line \d+: field 'w': bearing information"),
    (["EDGE_BEARING_SE2_XY 999 3 0.1 57295.8"], r"line \d+: field 'i': bearing from vertex 999"),
    (["EDGE_SE2 1203 1201 1 0 0 " + INFO], r"line \d+: pose 1203 already has odometry"),
    (["EDGE_SE2 1300 1301 1 0 0 " + INFO], r"line \d+: the odometry edges form 2 separate"),
    (["EDGE_SE2 1225 1226 1 0 0 1 2 0 1 0 1"], r"line \d+: field 'information': .*positive"),
    (["VERTEX_XY 3 0 0"], r"line \d+: field 'id': vertex 3 is defined twice"),
])
def test_g2o_malformed_lines(tmp_path, sim_stream, extra, pattern):
    write_g2o(tmp_path / "bad.g2o", sim_stream, extra=extra)
    with pytest.raises(DatasetError, match=r"bad\.g2o, " + pattern):
        import_g2o(tmp_path / "bad.g2o")


def test_g2o_duplicate_bearing_names_both_lines(tmp_path, sim_stream):
    st = sim_stream.steps[2]
    line = f"EDGE_BEARING_SE2_XY 1202 {st.landmark_ids[0]} 0.1 57295.8"
    write_g2o(tmp_path / "bad.g2o", sim_stream, extra=[line])
    with pytest.raises(DatasetError, match=r"line \d+: a second bearing .* \(first on line \d+\)"):
        import_g2o(tmp_path / "bad.g2o")


def test_g2o_truth_missing_a_pose(tmp_path, sim_stream):
    write_g2o(tmp_path / "a.g2o", sim_stream)
    write_g2o(tmp_path / "t.g2o", sim_stream, pose_id0=5000)
    with pytest.raises(DatasetError, match=r"t\.g2o: no VERTEX_SE2 for pose 1200"):
        import_g2o(tmp_path / "a.g2o", truth_path=tmp_path / "t.g2o")


@needs_data
def test_real_g2o_set(tmp_path):
    d = DATA / "bearing_only_sim_g2o"
    s = import_g2o(d / "slam2D_bearing_only_initial_guess.g2o",
                   truth_path=d / "slam2D_bearing_only_ground_truth.g2o")
    assert len(s.steps) == 301
    assert sum(len(st.landmark_ids) for st in s.steps) == 2132
    assert len(s.landmark_ids()) == 141 == len(s.truth.landmark_ids)
    assert s.header.meta["fixed_steps"] == [298]  # FIX 1498, poses 1200..1500
    r, _, _ = bearing_residuals(s)
    assert abs(np.mean(r)) < 5e-4 and np.std(r) == pytest.approx(0.003, abs=5e-4)
    assert np.max(np.abs(r)) < 0.012  # SOURCE.md: max 0.011 rad
    write_stream(s, tmp_path / "g.jsonl")
    assert read_stream(tmp_path / "g.jsonl") == s


@pytest.mark.parametrize("where", ["first", "last", "isolated"])
def test_g2o_a_pose_vertex_off_the_chain_is_refused(tmp_path, sim_stream, where):
    """h18 item 15: with the first (or last) EDGE_SE2 deleted, its pose vertex was dropped
    without a word and the stream started at the next pose; an extra pose vertex likewise."""
    write_g2o(tmp_path / "a.g2o", sim_stream,
              extra=["VERTEX_SE2 5000 1.0 2.0 0.5"] if where == "isolated" else [])
    lines = (tmp_path / "a.g2o").read_text().splitlines()
    n = len(sim_stream.steps)
    drop = {"first": "EDGE_SE2 1200 1201 ", "last": f"EDGE_SE2 {1198 + n} {1199 + n} ",
            "isolated": "no such line"}[where]
    vid = {"first": 1200, "last": 1199 + n, "isolated": 5000}[where]
    # the bearings of the cut-off pose go too (else they are refused first)
    kept = [ln for ln in lines if not ln.startswith(drop)
            and not ln.startswith(f"EDGE_BEARING_SE2_XY {vid} ")]
    (tmp_path / "a.g2o").write_text("\n".join(kept) + "\n")
    line = next(k + 1 for k, ln in enumerate(kept) if ln.startswith(f"VERTEX_SE2 {vid} "))
    with pytest.raises(DatasetError, match=rf"a\.g2o, line {line}: .*VERTEX_SE2 {vid} is not on "
                                           rf"the odometry chain.*EDGE_SE2"):
        import_g2o(tmp_path / "a.g2o")


def test_a_dataset_source_reads_its_files_again_when_they_change(tmp_path, sim_stream):
    """A recording read once was kept by (kind, path, robot, truth path) only: after its files
    changed, a process that had read it (a Dask worker kept running, a library session) ran
    the old stream, keyed and cached under the new files' key."""
    from bomgraph.sources import DatasetSource

    path = tmp_path / "a.g2o"
    write_g2o(path, sim_stream)
    src = DatasetSource("g2o", str(path))
    first = src.stream()
    assert src.stream() is first   # kept while the files are unchanged
    lines = path.read_text().splitlines()
    drop = next(k for k, ln in enumerate(lines) if ln.startswith("EDGE_BEARING_SE2_XY"))
    path.write_text("\n".join(lines[:drop] + lines[drop + 1:]) + "\n")
    second = src.stream()
    n_bearings = [sum(len(st.landmark_ids) for st in s.steps) for s in (first, second)]
    assert n_bearings[1] == n_bearings[0] - 1
