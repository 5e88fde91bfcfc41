"""Review of h64's values in a serial run's key (h69): what it did not see, and a gtsam
parameters object that made a method never cached.

- A value read from another module of the method's package (``config.PARAMS["depth"]``), a
  class attribute set on a subclass and read by its base class's code in another module
  (``m.Mine.GAIN = [3.0]``, ``self.GAIN`` in ``base.py``), one read by a name in a string
  (``getattr(self, "GAIN")``), and a module's function rebound to another one
  (``m.scale = lambda: 3.0``), a class's attribute in a class in its body
  (``Mine.Defaults.GAIN[0] = 3.0``): changed between two sweeps, the old result was served (MPE
  0.27 m for code that gives 2.14 m).
- ``PARAMS = gtsam.LevenbergMarquardtParams()`` at module level cannot be pickled: the
  method's serial runs were never cached though nothing changed; it is now hashed by its
  printed form and gtsam getters, so it is cached, and a change (``setMaxIterations``) keyed.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path
from typing import Callable

import numpy as np
import pytest
from _depth_mapper import depth_mapper
from _plugin_site import write

from bomgraph import mapper
from bomgraph.bench import Executor, execute_counted, is_cached
from bomgraph.experiments import Arm, Experiment, FileSource
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import write_stream

GTSAM_PARAMS = "import gtsam\nPARAMS = gtsam.LevenbergMarquardtParams()\n"

#: package name -> (its files, the method's target, the change, the change undone)
CASES: dict[str, tuple[dict[str, str], str, Callable[[], None], Callable[[], None]]] = {}


def _case(pkg: str, files: dict[str, str], target: str, change: Callable, undo: Callable):
    CASES[pkg] = (files, f"{pkg}.{target}", change, undo)


_case("h69cfg", {"config.py": "PARAMS = {'depth': 1.0}\n",
                 "m.py": "from . import config\n" + depth_mapper("config.PARAMS['depth']", "Mine")},
      "m:Mine", lambda: sys.modules["h69cfg.config"].PARAMS.__setitem__("depth", 3.0),
      lambda: sys.modules["h69cfg.config"].PARAMS.__setitem__("depth", 1.0))
_case("h69sub", {"base.py": depth_mapper("self.GAIN[0]", "Base", attrs="GAIN = [1.0]"),
                 "m.py": "from .base import Base\n\nclass Mine(Base):\n    pass\n"},
      "m:Mine", lambda: setattr(sys.modules["h69sub.m"].Mine, "GAIN", [3.0]),
      lambda: delattr(sys.modules["h69sub.m"].Mine, "GAIN"))
_case("h69str", {"m.py": depth_mapper("getattr(self, 'GAIN')[0]", "Mine", attrs="GAIN = [1.0]")},
      "m:Mine", lambda: sys.modules["h69str.m"].Mine.GAIN.__setitem__(0, 3.0),
      lambda: sys.modules["h69str.m"].Mine.GAIN.__setitem__(0, 1.0))
_case("h69nest", {"m.py": depth_mapper("self.Defaults.GAIN[0]", "Mine",
                                         attrs="class Defaults:\n        GAIN = [1.0]")},
      "m:Mine", lambda: sys.modules["h69nest.m"].Mine.Defaults.GAIN.__setitem__(0, 3.0),
      lambda: sys.modules["h69nest.m"].Mine.Defaults.GAIN.__setitem__(0, 1.0))
# already keyed by the merge (checked in review, kept as cases): an array changed in
# place, a dict inside a list, a dataclass instance's field
_case("h69arr", {"m.py": depth_mapper("W[0]", "Mine") + "\nW = np.ones(1)\n"}, "m:Mine",
      lambda: sys.modules["h69arr.m"].W.__setitem__(0, 3.0),
      lambda: sys.modules["h69arr.m"].W.__setitem__(0, 1.0))
_case("h69lst", {"m.py": depth_mapper("T[0]['d']", "Mine") + "\nT = [{'d': 1.0}]\n"}, "m:Mine",
      lambda: sys.modules["h69lst.m"].T[0].__setitem__("d", 3.0),
      lambda: sys.modules["h69lst.m"].T[0].__setitem__("d", 1.0))
_case("h69dc", {"m.py": depth_mapper("CFG.depth", "Mine") + "\nimport dataclasses\n\n\n"
                "@dataclasses.dataclass\nclass Cfg:\n    depth: float = 1.0\n\n\nCFG = Cfg()\n"},
      "m:Mine", lambda: setattr(sys.modules["h69dc.m"].CFG, "depth", 3.0),
      lambda: setattr(sys.modules["h69dc.m"].CFG, "depth", 1.0))
_ORIGINAL: dict[str, object] = {}
_case("h69fn", {"m.py": depth_mapper("scale()", "Mine") + "\ndef scale():\n    return 1.0\n"},
      "m:Mine", lambda: (_ORIGINAL.__setitem__("scale", sys.modules["h69fn.m"].scale),
                         setattr(sys.modules["h69fn.m"], "scale", lambda: 3.0)),
      lambda: setattr(sys.modules["h69fn.m"], "scale", _ORIGINAL["scale"]))
_case("h69gt", {"m.py": GTSAM_PARAMS + depth_mapper("PARAMS.getMaxIterations() / 100.0", "Mine")},
      "m:Mine", lambda: sys.modules["h69gt.m"].PARAMS.setMaxIterations(300),
      lambda: sys.modules["h69gt.m"].PARAMS.setMaxIterations(100))


def _method(plugin_site: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, pkg: str,
            files: dict[str, str], target: str) -> tuple[Experiment, Path]:
    """The package written, imported by the user first (a notebook) and registered at run
    time; a one-run experiment of it and its cache folder."""
    write(plugin_site / pkg / "__init__.py", "")
    for rel, text in files.items():
        write(plugin_site / pkg / rel, text)
    monkeypatch.setattr(mapper, "_REGISTRY", dict(mapper._REGISTRY))
    importlib.import_module(target.split(":")[0])
    mapper.register_method("h69-val", target)
    stream = tmp_path / "s.jsonl"
    write_stream(simulate(SimConfig(n_steps=30), np.random.default_rng(3)), stream)
    exp = Experiment("e", "e", (Arm("h69-val", "h69-val"),), sources=(FileSource(str(stream)),))
    return exp, tmp_path / "cache"


def _sweep(exp: Experiment, cache: Path | None) -> tuple[float, int]:
    """The run's final MPE and how many runs came from the cache."""
    (res,), n_cached = execute_counted(exp.tasks(), Executor("serial"), cache_dir=cache)
    assert res["ok"], res.get("error")
    return res["checkpoints"][-1]["mpe_m"], n_cached


@pytest.mark.parametrize("pkg", list(CASES))
def test_a_value_changed_between_two_sweeps_runs_again_and_set_back_is_cached(
        plugin_site: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, pkg: str) -> None:
    """Fails before for each case: the old value's result was served (or, for gtsam's
    parameters, nothing was ever cached: the second sweep ran again)."""
    files, target, change, undo = CASES[pkg]
    exp, cache = _method(plugin_site, tmp_path, monkeypatch, pkg, files, target)
    first, _ = _sweep(exp, cache)
    assert _sweep(exp, cache) == (first, 1), "unchanged, the run is not served from the cache"
    change()
    second, n_cached = _sweep(exp, cache)
    fresh, _ = _sweep(exp, None)
    assert (second, n_cached) == (fresh, 0), "the old value's result was served"
    assert second != first
    undo()
    assert _sweep(exp, cache) == (first, 1)
    assert is_cached(exp.tasks()[0], cache, Executor("processes", n_jobs=2)), \
        "the workers' key (the files') is not the serial key of the file's values"


def test_gtsam_parameters_are_hashed_by_their_fields() -> None:
    """Two LevenbergMarquardtParams objects: equal settings hash equal, any setter changes
    the digest; a compiled object that tells nothing of its value is still unhashable."""
    import gtsam

    from bomgraph.loaded_values import Unhashable, _digest

    a, b = gtsam.LevenbergMarquardtParams(), gtsam.LevenbergMarquardtParams()
    assert _digest(a) == _digest(b)
    for setter, value in [("setMaxIterations", 7), ("setlambdaInitial", 1e-3),
                          ("setUseFixedLambdaFactor", False), ("setVerbosityLM", "SUMMARY"),
                          ("setRelativeErrorTol", 1e-9)]:
        c = gtsam.LevenbergMarquardtParams()
        getattr(c, setter)(value)
        assert _digest(c) != _digest(a), setter
    isam = gtsam.ISAM2Params()
    other = gtsam.ISAM2Params()
    other.relinearizeSkip = 1
    assert _digest(isam) == _digest(gtsam.ISAM2Params()) != _digest(other)
    with pytest.raises(Unhashable):
        _digest((i for i in range(3)))


def test_a_gtsam_object_other_than_parameters_is_not_printed() -> None:
    """Printing a default-made gtsam factor ends the process (SIGSEGV): only parameters
    objects are read by their printed form; this one is unhashable, as before."""
    import subprocess

    code = ("import gtsam\nfrom bomgraph.loaded_values import Unhashable, _digest\n"
            "try:\n    _digest(gtsam.ComponentDerivativeFactorChebyshev1Basis())\n"
            "except Unhashable:\n    print('unhashable')\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert (done.returncode, done.stdout.strip()) == (0, "unhashable"), done.stderr[-500:]


COUNTED = '''
N = [0]

class Counted:
    """pickled (hashed by bomgraph) once a call: N[0] counts"""
    def __reduce__(self):
        N[0] += 1
        return (Counted, ())
'''


def test_a_sweeps_runs_hash_the_methods_values_once_not_after_each_run(
        plugin_site: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Each run in this process hashed every value its method reads (to tell what the runs
    change themselves): a module's 200,000-item dict cost 0.5 s a run. Now once a sweep,
    at its end. 4 runs: 6 hashes (load, key, 4 runs) before, 3 after."""
    write(plugin_site / "h69count.py", COUNTED)  # another package: not among the method's
    exp, cache = _method(plugin_site, tmp_path, monkeypatch, "h69big", {
        "m.py": "from h69count import Counted\nBIG = Counted()\n"
                + depth_mapper("(1.0 + 0 * len(repr(BIG)))", "Mine")}, "h69big.m:Mine")
    streams = []
    for seed in range(4):
        streams.append(tmp_path / f"s{seed}.jsonl")
        write_stream(simulate(SimConfig(n_steps=10), np.random.default_rng(seed)), streams[-1])
    exp = Experiment("e", "e", exp.arms, sources=tuple(FileSource(str(s)) for s in streams))
    counter = sys.modules["h69count"].N
    results, n_cached = execute_counted(exp.tasks(), Executor("serial"), cache_dir=cache)
    assert all(r["ok"] for r in results) and n_cached == 0
    assert counter[0] == 3, f"{counter[0]} hashes of BIG for one sweep of 4 runs"
    results, n_cached = execute_counted(exp.tasks(), Executor("serial"), cache_dir=cache)
    assert n_cached == 4


def test_a_class_attribute_set_before_the_first_sweep_is_not_keyed_as_the_files(
        plugin_site: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``Mine.GAIN[0] = 3.0`` (``GAIN = [1.0]`` in the file) before the first sweep was taken
    for the value when loaded: the run of 3.0 was cached under the files' key, which worker
    processes (and this one after a restart) running the file's 1.0 are then served. Fails
    before (the workers' key was cached)."""
    files, target, change, _ = CASES["h69str"]
    exp, cache = _method(plugin_site, tmp_path, monkeypatch, "h69str", files, target)
    change()
    mpe, _ = _sweep(exp, cache)
    assert mpe == _sweep(exp, None)[0]
    assert not is_cached(exp.tasks()[0], cache, Executor("processes", n_jobs=2))


def test_a_helper_naming_vars_reads_only_its_own_module_whole(
        plugin_site: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A helper module whose code names ``vars`` (``vars(args)``) may read any of its own
    globals, not the method module's: a generator there that no code names keeps the
    method cached (the names of all modules are read together since h69)."""
    exp, cache = _method(plugin_site, tmp_path, monkeypatch, "h69vars", {
        "util.py": "def as_dict(obj):\n    return dict(vars(obj))\n",
        "m.py": "from .util import as_dict\n_GEN = (i for i in range(3))\n"
                + depth_mapper("(1.0 + 0 * len(as_dict(self)))", "Mine")}, "h69vars.m:Mine")
    first, _ = _sweep(exp, cache)
    assert _sweep(exp, cache) == (first, 1)
