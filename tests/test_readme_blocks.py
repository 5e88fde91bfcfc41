"""The code blocks of README.md and docs/*.md, run as a reader would run them, with what
they print checked against what the text says (h37 audit). Every block is either run here or
named in LEFT_OUT with the reason, so a new block cannot go untried."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from _plugin_dist import write_dist_info
from _shared_data import DATA, missing  # tests/_shared_data.py

ROOT = Path(__file__).resolve().parents[1]
DOCS = ("README.md", "docs/USAGE.md", "docs/METHODS.md", "docs/FORMATS.md", "docs/measurements.md",
        "docs/measurements-early.md")
#: the README and the reference pages its details moved to (h164): prose checks read them all
READ = ("README.md", "docs/USAGE.md", "docs/METHODS.md")
BOMGRAPH = f'"{sys.executable}" -m bomgraph'

# (document, how the block starts): the test that runs it, or why it is left out
RUN = {
    ("docs/USAGE.md", "bomgraph simulate --seed 0 --out s.jsonl;"): "test_export_block",
    ("README.md", "bomgraph import mrclam"): "test_benchmark_your_own_method_blocks",
    ("README.md", "== streams, final map per run =="): "test_benchmark_your_own_method_blocks",
    ("docs/USAGE.md", '[project.entry-points."bomgraph.methods"]'):
        "test_benchmark_your_own_method_blocks",
    ("docs/USAGE.md", 'name = "mine"'): "test_sweep_file_block_plans_and_its_quoted_mistakes",
    ("docs/USAGE.md", "import numpy as np\nfrom bomgraph import create_mapper"):
        "test_library_use_and_gtsam_helper_blocks",
    ("docs/USAGE.md", "from baselines import gtsam_tools as gt"):
        "test_library_use_and_gtsam_helper_blocks",
    ("docs/USAGE.md", "from bomgraph.bench import Executor"): "test_library_sweep_block",
    ("docs/FORMATS.md", '{"format": "bomgraph-stream"'): "test_formats_stream_blocks",
    ("docs/FORMATS.md", "import numpy as np\nfrom bomgraph.stream import"):
        "test_formats_stream_blocks",
    ("docs/measurements-early.md", 'checkpoint_every = 10\n[[experiments]]\nname = "lw1"'):
        "test_measurement_sweep_block_plans",
}
LEFT_OUT = {
    ("README.md", "python3 -m venv .venv && . .venv/bin/activate && pip install . &&"):
        "a fresh venv and the 2-minute main job (`compare --quick` runs in "
        "tests/test_compare_estimates.py)",
    ("README.md", "python3 -m venv .venv && . .venv/bin/activate && pip install '.[test]'"):
        "the test suite itself",
    ("README.md", "python scripts/bench_generality.py"): "280 runs, minutes on two cores",
    ("docs/FORMATS.md", '{"format": "bomgraph-estimate"'):
        "an annotated schema, not a file (the reader's tests: tests/test_estimate_file.py)",
    ("docs/FORMATS.md", '{"t": 10,'): "an annotated schema, not a file",
}


#: what to do when a block is new, or its entry no longer names one block
HOW = ("in tests/test_readme_blocks.py, add the block's first line(s) to RUN with the test that "
       "runs it, or to LEFT_OUT with the reason it is not run")


def read_docs() -> str:
    """The README and its reference pages as one text, for the checks of what the prose says
    (a section moved from one to another is still found)."""
    return "\n\n".join((ROOT / doc).read_text() for doc in READ)


def blocks(doc: str) -> list[str]:
    """The fenced code blocks of ``doc``, in order: the lines between a line opening with
    ```` ``` ```` (any info string after it, ```` ```toml title="x" ```` too) and the next such
    line. A fence left open is an error naming its line."""
    out: list[str] = []
    body: list[str] | None = None
    opened = 0
    for n, line in enumerate((ROOT / doc).read_text().splitlines(), 1):
        if line.lstrip().startswith("```"):
            if body is None:
                body, opened = [], n
            else:
                out.append("".join(f"{b}\n" for b in body))
                body = None
        elif body is not None:
            body.append(line)
    assert body is None, f"{doc}, line {opened}: a code fence is opened and never closed"
    return out


def block(doc: str, start: str) -> str:
    found = [b for b in blocks(doc) if b.startswith(start)]
    assert found, (f"{doc}: no code block starts with {start!r} any more (changed or "
                   f"removed): update or remove its entry in RUN or LEFT_OUT")
    assert len(found) == 1, (f"{doc}: {len(found)} code blocks start with {start!r}: give "
                             f"its entry in RUN or LEFT_OUT a longer start, one that names "
                             f"one block, and {HOW} for the other")
    return found[0]


def shell(script: str, cwd: Path, env: dict | None = None) -> subprocess.CompletedProcess:
    """Run shell lines as written, ``bomgraph`` being this tree's (``python -m bomgraph``)."""
    script = re.sub(r"(^|; |&& )bomgraph ", rf"\g<1>{BOMGRAPH} ", script, flags=re.M)
    env = env or {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    proc = subprocess.run(["bash", "-e", "-c", script], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc


def test_every_block_is_run_or_left_out_with_a_reason() -> None:
    for doc in DOCS:
        for text in blocks(doc):
            keys = [k for k in [*RUN, *LEFT_OUT] if k[0] == doc and text.startswith(k[1])]
            assert keys, (f"{doc}: a code block is neither run nor left out (a new one?); "
                          f"{HOW}. It starts:\n{text[:200]}")
            assert len(keys) == 1, (f"{doc}: a code block starts as {len(keys)} entries of "
                                    f"RUN and LEFT_OUT do ({[k[1] for k in keys]}): make "
                                    f"them longer, so that one names it. It starts:\n"
                                    f"{text[:200]}")
    for doc, start in [*RUN, *LEFT_OUT]:
        block(doc, start)  # each entry names one block that is still there
    assert set(RUN.values()) <= set(globals())


def test_export_block(tmp_path: Path) -> None:
    """docs/USAGE.md, "Export" (from the README, h164): the commands as written; evo's figures
    (its comment) are bomgraph's
    APE and mean robot error aligned on the trajectory, when evo is not installed; and the
    mirrored estimate's "landmark MPE 1.68 cm, robot 1.04 cm mean" is what evaluate prints.
    evo is no dependency of bomgraph, so the block installs it before it calls ``evo_ape``
    (h112: in a fresh `pip install .` venv the block stopped at "evo_ape: command not found");
    the test does not run that pip line (the test extra has evo)."""
    text = block("docs/USAGE.md", "bomgraph simulate --seed 0 --out s.jsonl;")
    *commands, install, evo = text.splitlines()
    assert install.split("#")[0].split() == ["pip", "install", "evo"], text
    shell("\n".join(commands), tmp_path)
    rows = [r.split() for r in (tmp_path / "est.tum").read_text().splitlines()
            if not r.startswith("#")]
    assert len(rows) == 301 and all(len(r) == 8 for r in rows)
    rmse, mean = map(float, re.search(r"# rmse ([\d.]+), mean ([\d.]+) \(m\)", evo).groups())
    if shutil.which("evo_ape"):
        out = shell(evo.split("#")[0], tmp_path).stdout
        assert f"rmse\t{rmse:.6f}" in out and f"mean\t{mean:.6f}" in out, out
    ev = json.loads(shell(f"{BOMGRAPH} evaluate e.est s.jsonl --align trajectory --json",
                          tmp_path).stdout)
    assert (round(ev["ape_trans_rmse_m"], 6), round(ev["robot_mean_m"], 6)) == (rmse, mean)
    readme = read_docs()
    mpe, robot = re.search(r"unchanged \(landmark MPE ([\d.]+) cm, robot ([\d.]+) cm mean",
                           readme).groups()
    out = shell(f"{BOMGRAPH} evaluate e.est s.jsonl", tmp_path).stdout
    assert f"landmark MPE {mpe} cm" in out and f"mean over 301 poses {robot} cm" in out, out


def test_library_use_and_gtsam_helper_blocks(tmp_path: Path) -> None:
    """docs/USAGE.md, "Library use" then "GTSAM helpers", with ``stmds_map`` as the text after the
    second block defines it; the second prints what its comment says."""
    lib = block("docs/USAGE.md", "import numpy as np\nfrom bomgraph import create_mapper")
    gt = block("docs/USAGE.md", "from baselines import gtsam_tools as gt")
    defined = 'run(create_mapper("stmds-smacof", stream.header), stream.steps).final'
    assert f"`stmds_map` any `MapEstimate` (e.g. `{defined}`)" in " ".join(
        read_docs().split())
    (tmp_path / "lib.py").write_text(f"{lib}\nstmds_map = {defined}\n{gt}")
    out = shell(f'"{sys.executable}" lib.py', tmp_path).stdout.splitlines()
    assert len(out) == 2 and 0 < float(out[0]) < 0.1, out
    assert f'# "{out[1]}"' in gt, out


def test_library_sweep_block(tmp_path: Path) -> None:
    """docs/USAGE.md, "Library use", "A sweep from Python": a method registered in-process and the
    toy plugin's class, swept serially twice through the library, print what its comment
    says (the second time from the cache); the numbers are the README's final-map table's."""
    code = block("docs/USAGE.md", "from bomgraph.bench import Executor")
    shell("bomgraph simulate --seed 7 --out sim7.jsonl", tmp_path)
    (tmp_path / "sweep.py").write_text(code)
    out = shell(f'"{sys.executable}" sweep.py', tmp_path, _toy_plugin_env(tmp_path)).stdout
    said = " ".join(ln.lstrip("# ") for ln in code.splitlines()[-2:])
    assert [s.strip() for s in said.split(" / ")] == out.splitlines(), out
    assert (tmp_path / "mine-py" / "results.json").is_file()


def _toy_plugin_env(tmp_path: Path) -> dict:
    """An environment with the README's toy plugin installed as pip would, from its
    pyproject.toml, whose entry point is the README's."""
    entry = tomllib.loads(block("docs/USAGE.md", '[project.entry-points."bomgraph.methods"]'))
    plugin = ROOT / "docs" / "examples" / "toy_plugin"
    project = tomllib.loads((plugin / "pyproject.toml").read_text())
    methods = project["project"]["entry-points"]["bomgraph.methods"]
    assert entry["project"]["entry-points"]["bomgraph.methods"] == methods
    site = tmp_path / "site"
    write_dist_info(site, "bomgraph_toy_plugin", methods)
    return {**os.environ, "OMP_NUM_THREADS": "1",
            "PYTHONPATH": os.pathsep.join(map(str, (ROOT, site, plugin)))}


@pytest.mark.skipif(not (DATA / "mrclam6").is_dir(), reason=missing("mrclam6"))
def test_benchmark_your_own_method_blocks(tmp_path: Path) -> None:
    """README, "Benchmark your own method on your own data": the four commands (the plugin
    installed as pip would; one worker, not two) print the final-map table the README
    shows."""
    readme = block("README.md", "bomgraph import mrclam")
    env = _toy_plugin_env(tmp_path)
    lines = readme.splitlines()
    assert lines[1] == "pip install ./docs/examples/toy_plugin" and "--jobs 2" in lines[2]
    script = "\n".join([lines[0].replace("../shared/data", str(DATA)),
                        lines[2].replace("--jobs 2", "--jobs 1")])
    out = shell(script, tmp_path, env).stdout
    assert (tmp_path / "mine" / "final_by_run.csv").is_file()  # what `column` shows
    shown = block("README.md", "== streams, final map per run ==").splitlines()
    printed = out.split("== streams, final map per run ==")[1].splitlines()
    rows = [r.split() for r in printed[1:len(shown)]]
    assert rows == [r.split() for r in shown[1:]], out


def test_sweep_file_block_plans_and_its_quoted_mistakes(tmp_path: Path) -> None:
    """docs/USAGE.md, "Sweep files": the sweep file plans its runs, and its three quoted
    mistakes are
    the messages given (no data needed: a simulated stream stands in for MRCLAM6's robot 3,
    which the file names but a plan does not read)."""
    for name, seed in (("sim7.jsonl", 7), ("m6r3.jsonl", 3)):
        shell(f"{BOMGRAPH} simulate --seed {seed} --out {name}", tmp_path)
    env = _toy_plugin_env(tmp_path)
    (tmp_path / "sweep.toml").write_text(block("docs/USAGE.md", 'name = "mine"'))
    (tmp_path / "runs").mkdir()
    shutil.copy(tmp_path / "sim7.jsonl", tmp_path / "runs" / "a.jsonl")
    out = shell(f"{BOMGRAPH} compare --config sweep.toml --dry-run --out plan", tmp_path,
                env).stdout
    assert re.search(r"mine +first-sight +5 runs", out), out
    assert re.search(r"mine +stmds-smacof@real +5 runs", out), out

    text = " ".join(read_docs().split())
    quoted = re.findall(r"`(sweep\.toml: [^`]+)`", text)
    mistakes = ['methods = ["triangulate", "stmds-cs@fast"]\nstreams = ["sim7.jsonl"]\n',
                'methods = ["triangulate"]\n[[worlds]]\nname = "w"\nn_steps = "many"\n',
                'methods = ["triangulate"]\nstreams = ["runs/*.jsonl"]\n']
    shutil.rmtree(tmp_path / "runs")
    assert len(quoted) == len(mistakes)
    for message, toml in zip(quoted, mistakes):
        (tmp_path / "sweep.toml").write_text(toml)
        proc = subprocess.run([sys.executable, "-m", "bomgraph", "compare", "--config",
                               "sweep.toml", "--dry-run"], cwd=tmp_path, env=env,
                              capture_output=True, text=True)
        assert proc.returncode == 2 and proc.stderr.startswith(f"bomgraph: error: {message}"), (
            message, proc.stderr)


def test_formats_stream_blocks(tmp_path: Path) -> None:
    """docs/FORMATS.md: the example stream reads and runs; the writer for your own recording
    writes a stream that reads back as its steps."""
    from bomgraph.stream_file import read_stream

    (tmp_path / "ex.jsonl").write_text(block("docs/FORMATS.md", '{"format": "bomgraph-stream"'))
    ex = read_stream(tmp_path / "ex.jsonl")
    assert len(ex.steps) == 2 and list(ex.truth.landmark_ids) == [0, 1]
    shell(f"{BOMGRAPH} run ex.jsonl --method triangulate --out ex.est", tmp_path)
    writer = block("docs/FORMATS.md", "import numpy as np\nfrom bomgraph.stream import")
    (tmp_path / "writer.py").write_text(writer)
    shell(f'"{sys.executable}" writer.py', tmp_path)
    mine = read_stream(tmp_path / "mine.jsonl")
    assert [list(s.landmark_ids) for s in mine.steps] == [[4, 7], [4]]
    assert mine.header.meta == {"robot": "mine"} and mine.steps[1].time_s == 0.5


def test_measurement_sweep_block_plans(tmp_path: Path) -> None:
    """The measurements' one sweep file (window-ba-long's min_count, in
    docs/measurements-early.md) is still one that compare reads: 5 runs each of its two arms
    (its numbers are history, of the code then)."""
    (tmp_path / "lw.toml").write_text(block("docs/measurements-early.md",
                                            "checkpoint_every = 10\n"))
    out = shell(f"{BOMGRAPH} compare --config lw.toml --dry-run --out lw", tmp_path).stdout
    assert re.search(r"lw1 +long-mc3 +5 runs", out) and re.search(r"lw1 +oracle +5 runs", out)


@pytest.mark.parametrize("added, says", [
    ("```\npython scripts/bench_speed.py --quick\n```\n", "a new one?); " + HOW),
    ('```text title="x"\nhello\n```\n', "a new one?); " + HOW),
    ("```toml\ncheckpoint_every = 10\n[[experiments]]\nname = \"lw1\"\nx = 1\n```\n",
     "2 code blocks start with 'checkpoint_every = 10\\n[[experiments]]\\nname = \"lw1\"'"),
    ("```\nnever closed\n", "a code fence is opened and never closed")])
def test_a_block_added_to_the_docs_fails_saying_what_to_do(
        added: str, says: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A block added to docs/measurements.md failed with ``assert 0 == 1`` under "a block
    neither run nor left out", or, starting as a listed one, with a bare tuple; one whose
    fence has more than a word after it (```` ```text title="x" ````) went unseen (h41)."""
    for doc in DOCS:
        (tmp_path / doc).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / doc, tmp_path / doc)
    with open(tmp_path / "docs" / "measurements-early.md", "a") as fh:
        fh.write(f"\nMore text.\n\n{added}\nThe end.\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    with pytest.raises(AssertionError) as caught:
        test_every_block_is_run_or_left_out_with_a_reason()
    assert says in str(caught.value), str(caught.value)


def test_gtsam_helpers_seed_start_recipe_runs_as_written(tmp_path: Path) -> None:
    """docs/USAGE.md, "GTSAM helpers": the prose recipe after ``seed_landmarks`` raises (three
    calls
    in backticks, not a block) runs as written on run 0 of ``paper_design(0)``, where the text
    says all 50 landmarks then enter and LM converges (h123)."""
    text = " ".join(read_docs().split())
    m = re.search(r"with the hybrid's own seeding, and seed again: `([^`]+)`, `([^`]+)` \(the "
                  r"rays on those poses intersect\), `([^`]+)` \(on run 0 of "
                  r"`paper_design\(0\)` all 50 landmarks then enter and LM converges", text)
    assert m, "docs/USAGE.md's seed_start recipe changed: update this test"
    script = "\n".join([
        "from baselines import gtsam_tools as gt",
        "from bomgraph.mapper import create_mapper, run",
        "from bomgraph.sim import paper_design, simulate_run",
        "stream = simulate_run(paper_design(0)[0])",
        'stmds_map = run(create_mapper("stmds-smacof", stream.header), stream.steps).final',
        "state = gt.build_graph(stream.header, stream.steps)",
        *m.groups(),
        "values, report = gt.checked_solve(state.graph, state.values, state.config)",
        "print(len(state.to_estimate(values, report.as_info())), report.converged)", ""])
    (tmp_path / "recipe.py").write_text(script)
    assert shell(f'"{sys.executable}" recipe.py', tmp_path).stdout.split() == ["50", "True"]
