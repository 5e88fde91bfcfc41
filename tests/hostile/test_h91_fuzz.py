"""Faults found by helper h91's fuzz campaign against the command line (a seeded driver that
mutates valid streams, estimates, sweep files and dataset slices and runs ``bomgraph`` in
bounded subprocesses), each reduced to its smallest reproduction. Each test failed before
its fix."""

from __future__ import annotations

from pathlib import Path

import pytest
from hostile_helpers import bomgraph, one_error

from bomgraph.sweep import SweepError, read_sweep


def _worlds(n: int, seeds: str) -> str:
    return "".join(f'[[worlds]]\nname = "w{i}"\nn_steps = 15\nn_landmarks = 6\nseeds = {seeds}\n'
                   for i in range(n))


def test_a_sweep_of_many_worlds_is_bounded_as_a_whole(tmp_path: Path) -> None:
    """2,000 worlds of 100,000 seeds each (each within the per-world bound) made 200 million
    seeds while the file was read: ``compare --config`` died of a MemoryError traceback.
    The sweep's simulated runs are counted as its worlds are read."""
    path = tmp_path / "many.toml"
    path.write_text('name = "fz"\n' + _worlds(11, "100000") + '[[methods]]\nname = "triangulate"\n')
    with pytest.raises(SweepError, match=r"many.toml: worlds\[10\].seeds: the sweep's simulated "
                                         r"runs would exceed 1,000,000"):
        read_sweep(path)


def test_a_sweep_of_many_methods_is_bounded_as_a_whole(tmp_path: Path) -> None:
    """One world of 100,000 seeds and 200 methods is 20 million tasks: ``compare --dry-run``
    ran past 5 minutes, its memory growing. Runs x methods are bounded too."""
    path = tmp_path / "arms.toml"
    path.write_text('name = "fz"\n' + _worlds(1, "[" + ", ".join(map(str, range(100_000))) + "]")
                    + "".join(f'[[methods]]\nname = "triangulate"\nlabel = "m{i}"\n'
                              for i in range(11)))
    with pytest.raises(SweepError, match=r"arms.toml: methods: the sweep's runs x methods would "
                                         r"exceed 1,000,000"):
        read_sweep(path)


def test_a_dataset_table_is_held_in_8_bytes_a_value(tmp_path: Path) -> None:
    """A dataset file may be 256 MiB (``MAX_DATASET_BYTES``): about 8 million MRCLAM rows.
    ``read_table`` held them as lists of Python numbers, about 140 bytes a row of three
    columns, so a 6 MB gzip of odometry rows (1 GB decompressed, refused only at 256 MiB)
    ended ``import mrclam`` in a MemoryError traceback under 1.5 GiB of address space. The
    columns are now typed buffers: 8 bytes a value, and the line number 8 more (32 bytes a
    row here, measured as the growth of the peak from 40,000 rows to 80,000)."""
    import tracemalloc

    from bomgraph.datasets._text import read_table

    def peak(rows: int) -> int:
        path = tmp_path / f"Robot1_Odometry_{rows}.dat"
        path.write_text("# header\n" + "1248444187.156 \t 0.086 \t -0.398\n" * rows)
        tracemalloc.start()
        try:
            table, numbers = read_table(path, [("time", "float"), ("v", "float"),
                                               ("w", "float")])
            assert len(numbers) == rows and numbers[-1] == rows + 1
            assert float(table["w"][-1]) == -0.398
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    per_row = (peak(80_000) - peak(40_000)) / 40_000
    assert per_row < 64, per_row


_RECORD_FILES = {
    "victoria": lambda i: (f"ODOMETRY {i} {i + 1} 0.01 0.0 0.001 0.0001 0 0 4e-06 0 4e-06\n"
                           f"LANDMARK {i + 1} {10**8 + i % 50} 3.5 1.2 0.4 0 0.4\n"),
    "g2o": lambda i: (f"VERTEX_SE2 {i} {0.1 * i} 0 0\n"
                      f"EDGE_SE2 {i} {i + 1} 0.1 0 0.01 500 0 0 500 0 5000\n"
                      f"EDGE_BEARING_SE2_XY {i} {10**7 + i % 40} 0.5 10000\n"),
}


@pytest.mark.parametrize("kind", sorted(_RECORD_FILES))
def test_a_g2o_or_victoria_file_is_bounded_by_the_memory_its_records_take(
        tmp_path: Path, kind: str) -> None:
    """The g2o and Victoria Park importers hold every record as Python objects, then a Step a
    pose: 20-25 bytes of memory a byte of text, so a file at the dataset cap (256 MiB) asked
    for 5-6 GiB and ended in a MemoryError traceback under 1.5 GiB of address space (h91's
    fuzz; 262 MB of Victoria Park records ran 257 s, then died). Their files are now capped
    at 16 MiB, a regular file refused before it is read (before the fix this one, just
    over, was read and imported: 17 MiB of records)."""
    from bomgraph.datasets import import_g2o, import_victoria
    from bomgraph.datasets._text import MAX_RECORD_FILE_BYTES
    from bomgraph.errors import DatasetError

    path = tmp_path / f"big.{kind}"
    record = _RECORD_FILES[kind]
    with open(path, "w") as fh:
        i = 0
        # h96: the g2o records are 2/3 vertex and odometry text, so the file is larger
        while fh.tell() <= (MAX_RECORD_FILE_BYTES + 2**20) * (1.6 if kind == "g2o" else 1):
            fh.write("".join(record(k) for k in range(i, i + 1000)))
            i += 1000
        if kind == "g2o":
            fh.write(f"VERTEX_SE2 {i} {0.1 * i} 0 0\n")
    if kind == "victoria":
        with pytest.raises(DatasetError, match=r"big\.victoria: larger than 16 MiB, the limit "
                                               r"for a Victoria Park file"):
            import_victoria(path)
    else:  # h96: a g2o file is bounded by the text of the records it holds as objects
        with pytest.raises(DatasetError, match=r"big\.g2o, line \d+: more than 16 MiB of "
                                               r"VERTEX_SE2, VERTEX_XY, EDGE_SE2 and FIX"):
            import_g2o(path)


def test_an_export_refusal_names_the_estimate_file(work: Path) -> None:
    """An estimate cut short (its last checkpoint line deleted) and exported as g2o was
    refused without naming the file: ``bomgraph: error: g2o needs a pose vertex at every
    step; the estimate has none at ...``."""
    assert bomgraph("run", "s.jsonl", "--method", "triangulate", "--out", "e.est",
                    cwd=work).returncode == 0
    lines = (work / "e.est").read_text().splitlines(keepends=True)
    (work / "cut.est").write_text("".join(lines[:-2] + lines[-1:]))
    err = one_error(bomgraph("export", "cut.est", "--stream", "s.jsonl", "--format", "g2o",
                             "--out", "cut.g2o", cwd=work), "needs a pose vertex")
    assert err.startswith("bomgraph: error: cut.est: "), err
    assert not (work / "cut.g2o").exists()
    err = one_error(bomgraph("export", "-", "--stream", "s.jsonl", "--format", "g2o", "--out",
                             "cut.g2o", stdin=(work / "cut.est").read_bytes(), cwd=work))
    assert err.startswith("bomgraph: error: <stdin>: g2o needs a pose vertex"), err


def test_a_cache_entry_of_the_wrong_shape_is_a_miss(work: Path) -> None:
    """A cache entry with its key and ``ok`` intact but a landmark row cut to two numbers
    ended the next ``compare`` in a traceback while it drew the map figures, after it had
    rewritten results.json (``ValueError: setting an array element with a sequence``). It
    is now a cache miss, as an unreadable entry is: the run runs again."""
    import json

    args = ("compare", "--streams", "s.jsonl", "--methods", "triangulate", "--out", "cmp",
            "--jobs", "1", "--no-progress")
    assert bomgraph(*args, cwd=work).returncode == 0
    (entry,) = (work / "cmp" / "cache").glob("*.json")
    cached = json.loads(entry.read_text())
    del cached["final_map"]["landmarks"][0][2]
    entry.write_text(json.dumps(cached))
    proc = bomgraph(*args, cwd=work)
    err = proc.stderr.decode()
    assert proc.returncode == 0 and "Traceback" not in err, err
    assert f"ignoring the cache file {entry}" in err.replace("cmp/cache", str(work / "cmp/cache")) \
        or entry.name in err, err
    assert len(json.loads(entry.read_text())["final_map"]["landmarks"][0]) == 3  # run again


@pytest.mark.parametrize("kind,entry", [("victoria", "4.9e-324"),
                                        ("victoria", "1.7976931348623157e308"),
                                        ("g2o", "4.9e-324")])
def test_an_odometry_matrix_without_a_finite_inverse_is_refused_on_its_line(
        tmp_path: Path, kind: str, entry: str) -> None:
    """A positive definite odometry covariance (Victoria Park) or information (g2o) with a
    denormal or near-overflow diagonal entry passed the importers' checks; its inverse was
    not finite, numpy's RuntimeWarning leaked as a WARNING line with numpy's source path, and
    the stream refused ``'odom_sigma': step 1: must be 3 finite numbers``, naming neither the
    file nor the line."""
    import warnings

    from bomgraph.datasets import import_g2o, import_victoria
    from bomgraph.errors import DatasetError

    path = tmp_path / f"in.{kind}"
    if kind == "victoria":
        path.write_text(f"ODOMETRY 0 1 0.01 0.0 0.001 0.0001 0 0 4e-06 0 4e-06\n"
                        f"ODOMETRY 1 2 0.01 0.0 0.001 {entry} 0 0 4e-06 0 4e-06\n"
                        f"LANDMARK 1 100 3.5 1.2 0.4 0 0.4\nLANDMARK 2 100 3.4 1.2 0.4 0 0.4\n")
        read, field = import_victoria, "covariance"
    else:
        path.write_text(f"VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_SE2 2 2 0 0\n"
                        f"EDGE_SE2 0 1 1 0 0 500 0 0 500 0 5000\n"
                        f"EDGE_SE2 1 2 1 0 0 {entry} 0 0 500 0 5000\n"
                        f"EDGE_BEARING_SE2_XY 0 100 0.5 10000\n"
                        f"EDGE_BEARING_SE2_XY 1 100 0.7 10000\n")
        read, field = import_g2o, "information"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(DatasetError, match=rf"in\.{kind}, line (2|5): field '{field}': this "
                                               rf"matrix has no finite inverse"):
            read(path)
