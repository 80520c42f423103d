"""The command line imports only what its route needs, and the dataclass ``__init__``
methods it takes from :mod:`mitld_lp.init_cache` are the ones ``exec`` makes."""

from __future__ import annotations

import json
import marshal
import os
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import pytest

from mitld_lp import init_cache

ROOT = Path(__file__).resolve().parent.parent

#: Run the bundled case's command as ``python -m mitld_lp`` does, and print, after its
#: answer, which modules the process imported (a marker line on stdout).
PROBE = r"""
import atexit, json, runpy, sys
watched = json.loads(sys.argv[1])
sys.argv = ["-m", *sys.argv[2:]]
def report():
    sys.stdout.write("\nMODULES " + json.dumps({m: m in sys.modules for m in watched}) + "\n")
    sys.stdout.flush()
atexit.register(report)
runpy.run_module("mitld_lp", run_name="__main__")
"""

#: Not needed by a grid world's plain solve: the sweep package, the batch verb, the
#: PRISM reader, the compiled kernels, the other LP back-ends, plots and SciPy's
#: heavier parts, and lark (the task's formula is plain: mitld_lp.logic.plain_parse).
NOT_NEEDED = ("mitld_lp.sweep", "mitld_lp.sweep.spec", "mitld_lp.cli.runs", "stormpy",
              "numba", "cvxpy", "highspy", "matplotlib", "scipy.stats", "scipy.optimize",
              "scipy.sparse.linalg", "numpy.f2py", "numpy.testing", "lark",
              "regex")


def _solve(env: dict[str, str]) -> tuple[dict, dict]:
    done = subprocess.run(
        [sys.executable, "-c", PROBE, json.dumps(NOT_NEEDED + ("clarabel",)),
         "solve", "models/bus_grid.toml", "--json", "-q"],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    answer_text, _, modules = done.stdout.rpartition("\nMODULES ")
    return json.loads(answer_text), json.loads(modules)


@pytest.fixture(scope="module")
def bundled() -> tuple[dict, dict]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    return _solve(env)


def test_bundled_case_imports_only_its_route(bundled: tuple[dict, dict]) -> None:
    answer, modules = bundled
    assert answer["certified"] is True
    # what the route does need was seen, so the probe saw the route's imports
    assert modules["clarabel"]
    assert [m for m in NOT_NEEDED if modules[m]] == []


def test_bundled_case_answer(bundled: tuple[dict, dict]) -> None:
    # Storm's sound value iteration on the case's PRISM encoding gives 0.9244053
    # (experiments/bench_startup.py); the certified bracket holds it to its precision
    answer, _ = bundled
    assert answer["lower"] <= answer["upper"]
    assert answer["lower"] - 1e-6 <= 0.9244053 <= answer["upper"] + 1e-6


#: Dataclasses of every kind of ``__init__`` the generator writes, made and used in a
#: fresh interpreter, with ``init_cache`` installed or not (argv[1]); prints their reprs.
DATACLASSES = r"""
import sys
if sys.argv[1] == "cached":
    from mitld_lp import init_cache
    assert init_cache.install()
import dataclasses
from dataclasses import InitVar, dataclass, field

@dataclass(frozen=True)
class Point:
    x: int
    y: int = 2

@dataclass
class Bag:
    items: list = field(default_factory=list)
    scale: InitVar[int] = 3
    total: int = field(init=False, default=0)
    def __post_init__(self, scale):
        self.total = scale * len(self.items)

@dataclass(kw_only=True, slots=True)
class Options:
    name: str
    level: float = 0.5

b = Bag([1, 2], 5)
print(repr(Point(1)), Point(1) == Point(1, 2), repr(b), b.total, repr(Options(name="n")))
try:
    Point()
except TypeError as err:
    print("TypeError", err)
print(Bag.__init__.__code__.co_filename, Bag.__init__.__code__.co_varnames)
"""


def test_cached_inits_are_execs(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    outs = []
    for mode in ("plain", "cached", "cached"):  # the second cached run reads the table
        done = subprocess.run([sys.executable, "-c", DATACLASSES, mode], cwd=tmp_path,
                              env=env, capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr[-2000:]
        outs.append(done.stdout)
    assert "Bag(items=[1, 2], total=10) 10" in outs[0]
    assert "TypeError" in outs[0]
    assert outs[1] == outs[0] and outs[2] == outs[0]


def test_code_is_the_compilers(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(init_cache, "_codes", {})
    monkeypatch.setattr(init_cache, "_new", [])
    text = "def __create_fn__(x):\n def f(a):\n  return a + x\n return f"
    code = init_cache._code(text)
    assert code == compile(text, "<string>", "exec")
    assert init_cache._code(text) is code and init_cache._new == [text]  # compiled once
    ns: dict = {}
    exec(code, {}, ns)
    assert ns["__create_fn__"](Fraction(1, 3))(Fraction(1, 6)) == Fraction(1, 2)


def test_table_round_trip_and_bad_tables(tmp_path: Path,
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    path = str(tmp_path / "sub" / "table.marshal")
    text = "def __create_fn__():\n def g():\n  return 7\n return g"
    monkeypatch.setattr(init_cache, "_codes", {})
    monkeypatch.setattr(init_cache, "_new", [])
    init_cache._code(text)
    init_cache._write(path)
    table = init_cache._read(path)
    assert list(table) == [text] and table[text] == compile(text, "<string>", "exec")
    assert init_cache._new == []
    # another interpreter's table (another magic number), a damaged one, a missing one
    Path(path).write_bytes(b"\0\0\0\0" + marshal.dumps({text: table[text]}))
    assert init_cache._read(path) == {}
    Path(path).write_bytes(init_cache._magic() + b"\xff\x00garbage")
    assert init_cache._read(path) == {}
    assert init_cache._read(str(tmp_path / "none.marshal")) == {}


#: The bundled case and the puddle case solved with the block sweeps by NumPy (the gate's
#: default on these small products), by the compiled kernel loaded narrowly
#: (:mod:`mitld_lp.util.numba_narrow`, what every compiled module does), or by the
#: compiled kernel with numba's whole registries (argv[1]); then, in the compiled modes,
#: a function compiled afresh (a cache miss, NumPy's linear algebra) after the kernel's
#: load.
GATE = r"""
import json, sys
import numpy as np
from mitld_lp import load_model, synthesize
from mitld_lp.solvers import kernels
mode = sys.argv[1]
if mode != "numpy":
    kernels.COMPILED_MIN_ENTRIES = kernels.COMPILED_MIN_BLOCK_ENTRIES = 0
if mode == "full":
    from mitld_lp.util import numba_narrow
    numba_narrow.ENABLED = False  # every compiled module would put the narrow load in place
    from mitld_lp.solvers import compiled_kernels
    kernels._KERNEL = compiled_kernels.gauss_seidel
out = {}
for name in ("bus_grid", "bus_puddle"):
    r = synthesize(load_model(f"models/{name}.toml"))
    out[name] = [r.lower.hex(), r.upper.hex(), r.certified,
                 max(m.iteration.iterations for m in (r.lower_model, r.upper_model) if m)]
from mitld_lp.util import numba_narrow
out["narrow"] = numba_narrow.installed()
out["numba"] = "numba" in sys.modules
if mode != "numpy":
    import numba
    @numba.njit
    def norm_plus(x):
        return np.linalg.norm(x) + np.sum(x)
    out["fresh"] = float(norm_plus(np.array([3.0, 4.0])))
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def gate_runs() -> dict[str, dict]:
    pytest.importorskip("numba")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["MITLD_LP_KERNEL_LOADER"] = "0"  # numba's own load of its cache (kernel_loader)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    runs = {}
    for mode in ("numpy", "narrow", "full"):
        done = subprocess.run([sys.executable, "-c", GATE, mode], cwd=ROOT, env=env,
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr[-2000:]
        runs[mode] = json.loads(done.stdout.strip().splitlines()[-1])
    return runs


def test_gate_paths_give_equal_brackets(gate_runs: dict[str, dict]) -> None:
    numpy_run, narrow = gate_runs["numpy"], gate_runs["narrow"]
    assert numpy_run["numba"] is False and narrow["numba"] is True
    for name in ("bus_grid", "bus_puddle"):
        assert numpy_run[name][2] is True
        # Jacobi and Gauss-Seidel take different sweeps to the same certified bracket
        assert narrow[name][:3] == numpy_run[name][:3]
        assert narrow[name][3] > 0 and numpy_run[name][3] > 0


def test_narrow_load_is_the_same_kernel(gate_runs: dict[str, dict]) -> None:
    narrow, full = gate_runs["narrow"], gate_runs["full"]
    assert narrow["narrow"] is True and full["narrow"] is False
    for name in ("bus_grid", "bus_puddle"):
        assert narrow[name] == full[name]  # the same sweeps, the same bits
    # compiling after a narrow load gets the whole registries: |(3, 4)| + 7
    assert narrow["fresh"] == full["fresh"] == 12.0
