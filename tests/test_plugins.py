"""Method plugins (issue 16): a package installed with pip adds a method through the
entry-point group ``bomgraph.methods``; ``bomgraph methods`` lists it, ``compare`` runs it in
worker processes and on Dask, and editing its source makes the next run miss the cache. A
method registered at run time is refused where workers cannot see it.

The plugin is ``docs/examples/toy_plugin`` installed offline into a temporary folder
(``pip install --no-build-isolation --no-deps --no-index --target``). It is built by a
twenty-line in-tree PEP 517 backend written here, so the test needs neither network nor the
``wheel`` package (setuptools < 70 cannot build a wheel without it).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from bomgraph import mapper
from bomgraph.bench import Executor, execute, task_key
from bomgraph.cli import main
from bomgraph.errors import ConfigError
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.method_code import method_fingerprint

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "docs" / "examples" / "toy_plugin"

PYPROJECT = """\
[build-system]
requires = []
build-backend = "_build"
backend-path = ["."]

[project]
name = "mine-plugin"
version = "0.3"
"""

BACKEND = '''\
"""The smallest PEP 517 backend: a pure-Python wheel of toy_plugin with one entry point."""
import base64, hashlib, os, zipfile

DIST = "mine_plugin-0.3.dist-info"


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    files = {}
    for root, _, names in os.walk("toy_plugin"):
        for n in sorted(names):
            if n.endswith(".py"):
                path = os.path.join(root, n)
                with open(path, "rb") as fh:
                    files[path.replace(os.sep, "/")] = fh.read()
    files[DIST + "/METADATA"] = b"Metadata-Version: 2.1\\nName: mine-plugin\\nVersion: 0.3\\n"
    files[DIST + "/WHEEL"] = (b"Wheel-Version: 1.0\\nGenerator: test\\nRoot-Is-Purelib: true\\n"
                              b"Tag: py3-none-any\\n")
    files[DIST + "/entry_points.txt"] = (
        b"[bomgraph.methods]\\nmine = toy_plugin.mapper:FirstSightMapper\\n")
    digest = lambda d: base64.urlsafe_b64encode(hashlib.sha256(d).digest()).rstrip(b"=")
    record = [f"{p},sha256={digest(d).decode()},{len(d)}" for p, d in files.items()]
    files[DIST + "/RECORD"] = ("\\n".join(record + [DIST + "/RECORD,,"]) + "\\n").encode()
    name = "mine_plugin-0.3-py3-none-any.whl"
    with zipfile.ZipFile(os.path.join(wheel_directory, name), "w") as z:
        for p, d in files.items():
            z.writestr(p, d)
    return name
'''


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The toy plugin pip-installed into a temporary folder, an environment that sees it
    (PYTHONPATH: this tree, then that folder) and two small streams."""
    root = tmp_path_factory.mktemp("plugin")
    pkg = root / "pkg"
    shutil.copytree(EXAMPLE / "toy_plugin", pkg / "toy_plugin")
    (pkg / "pyproject.toml").write_text(PYPROJECT)
    (pkg / "_build.py").write_text(BACKEND)
    site = root / "site"
    # --isolated: no pip.conf or PIP_* of the machine (PIP_USER, PIP_REQUIRE_VIRTUALENV...);
    # no cache in $HOME
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "--isolated",
                           "--no-cache-dir", "--no-build-isolation", "--no-deps", "--no-index",
                           "--quiet", "--target", str(site), str(pkg)], capture_output=True,
                          text=True, cwd=root)
    assert proc.returncode == 0, proc.stderr
    assert (site / "toy_plugin" / "mapper.py").is_file()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(site)]),
           "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    streams = []
    for seed in (1, 2):
        path = root / f"s{seed}.jsonl"
        assert main(["simulate", "--seed", str(seed), "--steps", "30", "--landmarks", "20",
                     "--out", str(path)]) == 0
        streams.append(str(path))
    return {"root": root, "site": site, "env": env, "streams": streams}


def _bomgraph(env: dict, *args: str) -> subprocess.CompletedProcess:
    proc = subprocess.run([sys.executable, "-m", "bomgraph", *args], env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc


def _results(out: Path) -> dict[tuple[str, str], dict]:
    data = json.loads((out / "results.json").read_text())
    return {(r["arm"], r["run"]): r for r in data["results"]}


def _scores(res: dict) -> list:
    return [{k: v for k, v in c.items() if k != "estimate_s"} for c in res["checkpoints"]]


def test_methods_lists_the_installed_plugin(installed: dict) -> None:
    described = _bomgraph(installed["env"], "methods", "mine").stdout
    assert "options (the factory's keyword parameters; --option KEY=VALUE):" in described
    assert "depth_m  float, default 1.0" in described  # no config class: its signature
    out = _bomgraph(installed["env"], "methods").stdout
    line = next(ln for ln in out.splitlines() if ln.startswith("mine "))
    assert "each landmark depth_m along its first bearing" in line
    assert "(plugin: mine-plugin 0.3)" in line
    rows = json.loads(_bomgraph(installed["env"], "methods", "--json").stdout)
    mine = next(r for r in rows if r["name"] == "mine")
    assert mine["origin"] == "plugin" and mine["version"] == "0.3"
    assert next(r for r in rows if r["name"] == "stmds-smacof")["presets"]["real"]


def test_compare_runs_the_plugin_in_processes_and_on_dask_and_an_edit_misses_the_cache(
        installed: dict) -> None:
    env, streams, root = installed["env"], installed["streams"], installed["root"]
    args = ["compare", "--streams", *streams, "--methods", "mine,triangulate",
            "--no-figures", "--no-progress"]
    out = root / "procs"
    _bomgraph(env, *args, "--jobs", "2", "--out", str(out))
    first = _results(out)
    assert len(first) == 4 and all(r["ok"] for r in first.values()), first
    cache = set((out / "cache").glob("*.json"))
    assert len(cache) == 4

    dask_out = root / "dask"  # the workers of a local Dask cluster find the plugin too
    _bomgraph(env, *args, "--dask-local", "2", "--out", str(dask_out))
    on_dask = _results(dask_out)
    assert all(r["ok"] for r in on_dask.values())
    assert {k: _scores(r) for k, r in on_dask.items()} == {k: _scores(r)
                                                          for k, r in first.items()}

    _bomgraph(env, *args, "--jobs", "2", "--out", str(out))  # unchanged: every run cached
    assert set((out / "cache").glob("*.json")) == cache

    source = installed["site"] / "toy_plugin" / "mapper.py"  # edit the installed plugin
    text = source.read_text()
    assert "depth_m: float = 1.0" in text
    source.write_text(text.replace("depth_m: float = 1.0", "depth_m: float = 0.5"))
    try:  # the module's other tests use the plugin as installed (they failed run after it)
        _bomgraph(env, *args, "--jobs", "2", "--out", str(out))
    finally:
        source.write_text(text)
    edited = _results(out)
    assert len(set((out / "cache").glob("*.json")) - cache) == 2  # the two runs of mine
    for run in ("s1", "s2"):
        assert edited[("mine", run)]["key"] != first[("mine", run)]["key"]
        assert _scores(edited[("mine", run)]) != _scores(first[("mine", run)])
        assert edited[("triangulate", run)]["key"] == first[("triangulate", run)]["key"]


def test_a_method_registered_at_run_time_runs_serially_and_is_refused_by_workers(
        installed: dict, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(str(EXAMPLE))
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    mapper.register_method("first-sight-rt", "toy_plugin.mapper:FirstSightMapper",
                           "the toy, registered at run time")
    exp = Experiment("rt", "run time", (Arm("first-sight-rt", "first-sight-rt"),),
                     sources=(FileSource(installed["streams"][0]),))
    for executor in (Executor("processes", n_jobs=2), Executor("dask", dask_local=1)):
        with pytest.raises(ConfigError, match=r'entry-points\."bomgraph.methods"\] '
                                              r'first-sight-rt = "toy_plugin.mapper:'):
            execute(exp.tasks(), executor)
    (res,) = execute(exp.tasks(), Executor("serial"))
    assert res["ok"] and res["checkpoints"][-1]["n_mapped"] > 0
    # its code is in the cache key (a built-in method's is covered by the package hash)
    assert method_fingerprint("first-sight-rt") is not None
    assert method_fingerprint("triangulate") is None
    assert task_key(exp.tasks()[0]) == res["key"]


TYPED_PLUGIN = '''\
"""A plugin whose options are a plain dataclass (no presets)."""
from dataclasses import dataclass

import numpy as np

from bomgraph.mapper import MapEstimate


@dataclass(frozen=True)
class TypedConfig:
    min_parallax_rad: float = 0.05
    max_rays: int = 50


class TypedMapper:
    """a plugin with typed options"""

    config_class = TypedConfig

    def __init__(self, header, *, min_parallax_rad: float = 0.05, max_rays: int = 50,
                 label: str = "x") -> None:
        self.cfg = TypedConfig(float(min_parallax_rad), int(max_rays))

    def step(self, step) -> None:
        pass

    def estimate(self) -> MapEstimate:
        return MapEstimate(np.zeros(0, np.int64), np.zeros((0, 2)))
'''


def test_a_plugin_without_presets_has_its_options_checked_before_anything_runs(
        installed: dict, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture) -> None:
    """A plain-dataclass ``config_class`` (or the factory's annotated parameters) checks option
    names and types in one line, exit 2, as a built-in method's preset dataclass does: before,
    ``min_parallax_rad=abc`` was a ValueError traceback from the plugin's constructor in
    ``run``, and ``typed@paper`` or a typo failed every run of ``compare`` with exit 0."""
    (tmp_path / "typed_plugin.py").write_text(TYPED_PLUGIN)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    mapper.register_method("typed", "typed_plugin:TypedMapper", "typed options")
    mapper.check_method_options("typed", {"min_parallax_rad": 0.1, "max_rays": 3,
                                          "label": "y"})
    for opts, match in (({"min_parallax_rad": "abc"}, r"min_parallax_rad='abc': must be a "
                                                      r"number"),
                        ({"max_rays": 2.5}, r"max_rays=2.5: must be an integer"),
                        ({"label": 3}, r"label=3: must be a string"),
                        ({"min_paralax_rad": 0.1}, r"unknown option 'min_paralax_rad'"),
                        ({"preset": "paper"}, r"unknown option 'preset' \(it has no presets")):
        with pytest.raises(ConfigError, match=match):
            mapper.check_method_options("typed", opts)
    capsys.readouterr()
    assert main(["methods", "typed"]) == 0
    listing = capsys.readouterr().out
    assert "min_parallax_rad  float, default 0.05" in listing
    assert listing.rstrip().endswith("presets: none (NAME@PRESET is refused)")
    stream = installed["streams"][0]
    assert main(["run", stream, "--method", "typed", "--option", "min_parallax_rad=abc",
                 "--out", str(tmp_path / "e.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "min_parallax_rad='abc'" in err[0]
    assert not (tmp_path / "e.json").exists()
    for extra in (["--methods", "typed@paper"],
                  ["--methods", "typed", "--option", "typed:max_rays=many"]):
        assert main(["compare", "--streams", stream, *extra, "--jobs", "1", "--no-figures",
                     "--no-progress", "--out", str(tmp_path / "cmp")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "typed" in err[0], err
    assert not (tmp_path / "cmp" / "results.json").exists()


def test_a_dask_worker_holding_an_older_plugin_is_caught_not_trusted(
        installed: dict, monkeypatch: pytest.MonkeyPatch) -> None:
    """A worker of a cluster that outlives one compare (``--scheduler ADDR``) keeps the plugin
    module it imported; after an edit the client keys the task with the new source, the
    worker runs the old code (before: reported as the edited plugin's result). The worker
    sees that the plugin's source changed since it imported it and reports a failed run,
    uncached, saying to restart the workers."""
    from distributed import LocalCluster

    from bomgraph.cluster import LOCAL_SCHEDULER_HTTP

    from bomgraph import plugins

    for mod in [m for m in sys.modules if m.split(".")[0] == "toy_plugin"]:
        monkeypatch.delitem(sys.modules, mod)  # an earlier test imported docs/examples' copy
    monkeypatch.syspath_prepend(str(installed["site"]))
    monkeypatch.setenv("PYTHONPATH", installed["env"]["PYTHONPATH"])
    plugins.refresh()
    exp = Experiment("d", "dask", (Arm("mine", "mine"),),
                     sources=(FileSource(installed["streams"][0]),))
    source = installed["site"] / "toy_plugin" / "mapper.py"
    text = source.read_text()
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None,
                      scheduler_kwargs=LOCAL_SCHEDULER_HTTP) as cluster:  # not port 8787
        executor = Executor("dask", scheduler=cluster.scheduler_address)
        (first,) = execute(exp.tasks(), executor)
        assert first["ok"] and first["key"] == task_key(exp.tasks()[0])
        try:
            source.write_text(text + "\n# edited while the cluster runs\n")
            plugins.refresh()
            cache = installed["root"] / "stale-cache"
            (second,) = execute(exp.tasks(), executor, cache_dir=cache)
        finally:
            source.write_text(text)
            plugins.refresh()
    assert not second["ok"] and "restart the workers" in second["error"]
    assert "'mine' was edited since this worker imported it" in second["error"]
    assert list(cache.glob("*.json")) == []
