"""``import mitld_lp`` (and the command line's module) loads no solver stack -- cvxpy,
Clarabel, HiGHS, scipy's (sparse) linear algebra, ``mitld_lp.solvers`` -- until a solve
needs it.  Checked in fresh interpreters, where nothing was imported before."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
HEAVY = ("cvxpy", "clarabel", "highspy", "scipy.sparse.linalg", "scipy.linalg",
         "mitld_lp.solvers")


def _loaded_after(code: str) -> list[str]:
    probe = (f"import sys, json\n{code}\n"
             f"heavy = {HEAVY!r}\n"
             "print(json.dumps(sorted(m for m in sys.modules\n"
             "      if any(m == h or m.startswith(h + '.') for h in heavy))))")
    run = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         cwd=ROOT, timeout=120, check=True)
    return json.loads(run.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("module", ["mitld_lp", "mitld_lp.cli"])
def test_import_loads_no_solver_stack(module):
    assert _loaded_after(f"import {module}") == []


def test_the_probe_sees_the_stack_once_a_solve_needed_it():
    # the same probe after a solve: the check above could fail
    loaded = _loaded_after(
        "from mitld_lp import load_model, synthesize\n"
        "synthesize(load_model('models/bus_grid.toml'))")
    assert {"clarabel", "mitld_lp.solvers.lp"} <= set(loaded)
    # a product this small (371 states) is walked and factorised without SciPy's
    # csgraph and SuperLU, whose import (with scipy.linalg) costs 0.18 s of CPU
    assert not {"scipy.sparse.linalg", "scipy.linalg"} & set(loaded)


def test_a_large_graph_loads_scipys_linear_algebra():
    loaded = _loaded_after(
        "import numpy as np, scipy.sparse as sp\n"
        "from mitld_lp.util import traversal\n"
        "n = traversal.SMALL + 1\n"
        "ring = sp.csr_array((np.ones(n), (np.arange(n), (np.arange(n) + 1) % n)))\n"
        "assert traversal.strong_components(ring)[0] == 1")
    assert "scipy.sparse.linalg" in loaded
    # a program's csgraph (no hook asked for) is SciPy's as published: its linear
    # algebra comes with it; with the hook, tests/test_route_imports_csgraph.py


def test_a_solve_nobody_watches_imports_no_progress_bar():
    # standard error is a pipe here: no bar is shown, so tqdm (and asyncio) stay out
    solved = _loaded_after(
        "from mitld_lp import load_model, synthesize\n"
        "synthesize(load_model('models/bus_grid.toml'))\n"
        "heavy_seen = 'tqdm' in sys.modules or 'asyncio' in sys.modules\n"
        "assert not heavy_seen, sorted(m for m in sys.modules if 'tqdm' in m)")
    assert "mitld_lp.solvers.lp" in solved
    shown = subprocess.run(
        [sys.executable, "-c", "import sys\nfrom mitld_lp.util.progress import bar\n"
         "b = bar(True, total=2, disable=True)\nb.update(); b.close()\n"
         "print('tqdm' in sys.modules)"],
        capture_output=True, text=True, cwd=ROOT, timeout=120, check=True)
    assert shown.stdout.split()[-1] == "True"


def _blas(argv0: str, env: dict[str, str]) -> tuple[str, int]:
    """``OPENBLAS_NUM_THREADS`` and the process's thread count after importing the
    package and SciPy's linear algebra, with ``sys.argv[0]`` set as the command's."""
    probe = (f"import sys\nsys.argv[0] = {argv0!r}\n"
             "import os, mitld_lp, numpy, scipy.sparse.linalg\n"
             "print(os.environ.get('OPENBLAS_NUM_THREADS'), "
             "len(os.listdir('/proc/self/task')))")
    run = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         cwd=ROOT, timeout=120, check=True, env=env)
    value, threads = run.stdout.split()
    return value, int(threads)


def _openblas_pools() -> bool:
    """Whether NumPy's BLAS is OpenBLAS (which starts its pool at import) and this
    process may run on more than one core (OpenBLAS sizes the pool by the affinity)."""
    import os

    import numpy as np

    blas = np.show_config(mode="dicts")["Build Dependencies"]["blas"]["name"]
    return "openblas" in blas.lower() and len(os.sched_getaffinity(0)) > 1


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="needs Linux's /proc")
def test_the_command_line_starts_blas_with_one_thread_unless_told_otherwise():
    import os

    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS")}
    assert _blas("-m", env) == ("1", 1)  # the command: no BLAS thread pools
    library, threads = _blas("-c", env)  # a program importing the package: untouched
    assert library == "None"
    if _openblas_pools():  # the pools are there, so the probe can see them
        assert threads > 1
    assert _blas("-m", {**env, "OPENBLAS_NUM_THREADS": "2"})[0] == "2"  # the user's own


def test_progress_bars_follow_tqdms_rule(monkeypatch):
    # None: a bar where standard error is a terminal or in a notebook (tqdm's widget),
    # none in a pipe (here: pytest captures standard error)
    from mitld_lp.util import progress

    monkeypatch.delitem(sys.modules, "ipykernel", raising=False)
    assert isinstance(progress.bar(None, total=1), progress._Off)
    monkeypatch.setitem(sys.modules, "ipykernel", object())
    shown = progress.bar(None, total=1, disable=True)  # disable: tqdm draws nothing
    assert not isinstance(shown, progress._Off)
    shown.close()
    assert isinstance(progress.bar(False, total=1), progress._Off)


def test_every_public_name_resolves_to_what_its_module_defines() -> None:
    """Each name of ``mitld_lp.__all__`` loads on first use from its module, and is that
    module's object (not a submodule that happens to share the name, as ``simulate`` and
    ``pareto`` once were)."""
    import importlib
    import types

    import mitld_lp

    for name in mitld_lp.__all__:
        value = getattr(mitld_lp, name)
        assert not isinstance(value, types.ModuleType), name
        where = mitld_lp._WHERE.get(name)
        if where is not None:
            assert getattr(importlib.import_module(where), name) is value, name
    assert {"Result", "Constraint", "parse_constraint", "pareto", "fit_law", "run_sweep",
            "load_sweep", "pose", "solve"} <= set(mitld_lp.__all__)


#: What the command line's solve of a grid model never needs: the other LP solvers, SciPy's
#: factorisations, graphs, optimisers and laws, the compiler, the sweep, plot, Storm and
#: exact-arithmetic extras, the progress bar, the PRISM world, the exports' writers, the
#: other verbs' modules, the laws' fits, bands and SciPy families (the case's laws
#: are geometric), and the routes other than the plain one.
NOT_FOR_A_GRID_SOLVE = (
    "cvxpy", "highspy", "scipy.sparse.linalg", "scipy.linalg", "scipy.sparse.csgraph",
    "scipy.optimize", "scipy.stats", "numba", "pandas", "pyarrow", "matplotlib", "stormpy",
    "dask", "flint", "gymnasium", "tqdm", "asyncio", "mitld_lp.worlds.prism",
    "mitld_lp.solvers.export", "mitld_lp.files.drn", "mitld_lp.cli.export",
    "mitld_lp.cli.formulas", "mitld_lp.distributions.fit", "mitld_lp.distributions.band",
    "mitld_lp.distributions.scipy_laws",
    # NumPy's submodules SciPy's array-API layer would copy (mitld_lp.startup.lean_scipy),
    # the masked arrays np.unique would import (startup.numpy_ma_when_used) and the regex
    # package lark would take (mitld_lp.startup.lark_without_regex)
    "numpy.f2py", "numpy.testing", "numpy.polynomial", "numpy.ctypeslib", "numpy.rec",
    "numpy.char", "numpy.strings", "numpy.ma", "regex",
    # the sensed routes' information states, the controller file reader, a notebook's html
    "mitld_lp.sensing.belief", "mitld_lp.running", "mitld_lp.controllers.reader", "html",
    # the package files' reader where the package is not a folder (logic/tables.py)
    "importlib.resources", "importlib.readers",
    # the constrained LP's modules, which the routes claiming constraints load to solve
    "mitld_lp.solvers.constrained", "mitld_lp.solvers.constrained_model",
    # the other routes and the robust route's solvers (routes.precedence.Later)
    "mitld_lp.routes.constrained", "mitld_lp.routes.robust", "mitld_lp.routes.sensed",
    "mitld_lp.routes.robust_constrained", "mitld_lp.routes.sensed_constrained",
    "mitld_lp.routes.sensed_band_constrained", "mitld_lp.routes.sensed_optimistic",
    "mitld_lp.routes.sensed_optimistic_constrained", "mitld_lp.routes.sensed_reacting",
    "mitld_lp.solvers.robust", "mitld_lp.solvers.robust_graph", "mitld_lp.solvers.robust_lp")


def _command_modules(argv: list[str]) -> dict:
    """Run the console script's ``command`` with ``argv`` in a fresh interpreter started
    as the command (``sys.argv[0]`` is ``mitld-lp``); its exit code, the modules then
    loaded among :data:`NOT_FOR_A_GRID_SOLVE`, and the garbage collector's state."""
    probe = ("import sys, json, gc, io, contextlib, dataclasses\n"
             f"sys.argv = ['mitld-lp', *{argv!r}]\n"
             "from mitld_lp.startup import command\n"
             "out = io.StringIO()\n"
             "try:\n"
             "    with contextlib.redirect_stdout(out):\n"
             "        command()\n"
             "except SystemExit as stop:\n"
             "    code = stop.code\n"
             f"heavy = {NOT_FOR_A_GRID_SOLVE!r}\n"
             "print(json.dumps(dict(code=code, out=out.getvalue(),\n"
             "    loaded=sorted(m for m in sys.modules\n"
             "                  if any(m == h or m.startswith(h + '.') for h in heavy)),\n"
             "    collector=gc.isenabled(), frozen=gc.get_freeze_count(),\n"
             "    records=dataclasses._hash_fn.__module__,\n"
             "    cli='mitld_lp.cli' in sys.modules, numpy='numpy' in sys.modules)))")
    run = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         cwd=ROOT, timeout=120, check=True)
    return json.loads(run.stdout.strip().splitlines()[-1])


def test_the_command_solves_a_grid_model_without_what_it_does_not_need(tmp_path):
    solved = _command_modules(["solve", "models/bus_grid.toml", "--json", "-q"])
    assert solved["code"] == 0 and json.loads(solved["out"])["certified"]
    assert solved["loaded"] == []
    # the collector, off while the command line imported, is on again for the work,
    # the imported modules' objects out of its passes
    assert solved["collector"] and solved["frozen"] > 0
    # its dataclasses' methods are closures (mitld_lp.dataclass_closures)
    if sys.version_info[:2] in ((3, 11), (3, 12)):
        assert solved["records"] == "mitld_lp.dataclass_closures"
    # the probe sees a module once a command needs it: the DRN export's writer
    drn = tmp_path / "case.drn"
    exported = _command_modules(["export", "models/bus_grid.toml", "--drn", str(drn), "-q"])
    assert exported["code"] == 0 and drn.read_text().startswith("// Exported by mitld_lp")
    assert {"mitld_lp.solvers.export", "mitld_lp.files.drn"} <= set(exported["loaded"])


def test_the_version_is_answered_before_the_command_line_is_imported():
    from mitld_lp import __version__

    answered = _command_modules(["--version"])
    assert answered["code"] == 0 and answered["out"] == f"mitld-lp {__version__}\n"
    assert not answered["cli"] and not answered["numpy"]
    shown = subprocess.run(  # the same line as the command line's own --version
        [sys.executable, "-c", "from mitld_lp.cli import main\nmain(['--version'])"],
        capture_output=True, text=True, cwd=ROOT, timeout=120, check=True)
    assert shown.stdout == answered["out"]


def _array_api_copy(lean: bool) -> dict:
    """In a fresh interpreter, SciPy's copy of NumPy's namespace (the array-API layer),
    made by the command line's :func:`mitld_lp.startup.lean_scipy` or by SciPy itself:
    the names it lists, whether each of NumPy's later submodules it hands over is
    NumPy's own, NumPy's ``__all__`` and ``dir`` after, and what was imported."""
    from mitld_lp.library_start import NUMPY_EXTRAS, SCIPY_NUMPY_COPY

    probe = ("import sys, json, importlib\n"
             "sys.argv[0] = 'mitld-lp'\n"
             "import numpy\n"
             "from mitld_lp import startup\n"
             f"{'startup.lean_scipy()' if lean else ''}\n"
             f"copy = importlib.import_module({SCIPY_NUMPY_COPY!r})\n"
             "import scipy.sparse as sp\n"
             "m = sp.csr_array(numpy.array([[0.0, 2.0], [1.0, 0.0]]))\n"
             "loaded = sorted(m for m in sys.modules if m.startswith('numpy.'))\n"
             f"extras = {NUMPY_EXTRAS!r}\n"
             "print(json.dumps(dict(names=sorted(copy.__all__), dir=sorted(dir(copy)),\n"
             "    same=[getattr(copy, n) is getattr(numpy, n) for n in extras],\n"
             "    numpy_all=sorted(numpy.__all__), numpy_dir=sorted(dir(numpy)),\n"
             "    product=(m @ m).toarray().tolist(), loaded=loaded)))")
    run = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         cwd=ROOT, timeout=120, check=True)
    return json.loads(run.stdout.strip().splitlines()[-1])


def test_the_command_lines_scipy_copies_numpy_without_importing_what_it_never_uses():
    lean, full = _array_api_copy(True), _array_api_copy(False)
    # the same namespace as SciPy's own copy: every name, each NumPy's object
    assert lean["names"] == full["names"] and set(lean["dir"]) == set(full["dir"])
    assert all(lean["same"]) and all(full["same"])
    # NumPy itself as it was: its __all__ and dir put back
    assert lean["numpy_all"] == full["numpy_all"] and lean["numpy_dir"] == full["numpy_dir"]
    assert lean["product"] == full["product"] == [[2.0, 0.0], [0.0, 2.0]]
    # the copy and a sparse product imported none of them; SciPy's own copy does
    for extra in ("numpy.f2py", "numpy.testing", "numpy.ma", "numpy.polynomial"):
        assert extra not in lean["loaded"] and extra in full["loaded"]


def test_the_command_lines_lark_is_lark_without_regex():
    probe = ("import sys\nsys.argv[0] = 'mitld-lp'\nfrom mitld_lp import startup\n"
             "startup.lark_without_regex()\nimport lark.utils\n"
             "from mitld_lp.logic import parse\n"
             "f = parse('F[0,3] a & G b')\n"
             "had = 'regex' in sys.modules\nimport regex\n"
             "print(lark.utils._has_regex, had, regex.__name__, repr(f))")
    run = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         cwd=ROOT, timeout=120, check=True)
    # lark as without the package; the package importable for anyone after it
    assert run.stdout.split(maxsplit=3)[:3] == ["False", "False", "regex"]
    # the same formula as lark with regex parses here (this process imported it as usual)
    from mitld_lp.logic import parse

    assert run.stdout.split(maxsplit=3)[3].strip() == repr(parse("F[0,3] a & G b"))


#: Dataclasses of every shape the stdlib makes methods for, and what each method does
#: (run in a fresh interpreter, with the stdlib's methods or the command line's).
_RECORDS_PROBE = '''
import dataclasses, json, math, sys
from dataclasses import dataclass, field
if sys.argv[1] == "closures":
    from mitld_lp import startup
    startup.dataclass_methods_without_exec()

@dataclass(frozen=True)
class Empty:
    pass

@dataclass(frozen=True, slots=True)
class One:
    x: float

@dataclass(frozen=True)
class Three:
    a: int
    b: str = "b"
    c: tuple = field(default=(), compare=False, repr=False)

@dataclass(frozen=True)
class Four(Three):
    d: float = field(default=0.5, hash=False)

class Plain(Three):  # not a dataclass: names other than the fields may be set
    pass

@dataclass(order=True, unsafe_hash=True)
class Ordered:
    p: int
    q: list = field(default_factory=list, hash=False)

@dataclass(eq=False)
class Identity:
    r: int

def outcome(f):
    try:
        return repr(f())
    except Exception as err:
        return f"{type(err).__name__}: {err}"

nan = math.nan
loop = Ordered(1)
loop.q.append(loop)
plain = Plain(1)
cases = {
    "repr": [repr(r) for r in (Empty(), One(0.25), Three(1, "x", (2,)), Four(1), loop,
                                Identity(3))],
    "eq": [Empty() == Empty(), One(nan) == One(nan), One(1.0) == One(1.0), One(1) == 1,
           Three(1, "x", (1,)) == Three(1, "x", (2,)), Three(1) == Four(1),
           Four(1, d=1.0) == Four(1, d=2.0), Identity(1) == Identity(1)],
    "hash": [hash(Empty()), hash(One(2.0)), hash(Three(1, "x", (9,))),
             hash(Four(1, "y", d=3.0)), hash(Ordered(4, [1]))],
    "order": [Ordered(1) < Ordered(2), Ordered(2, [1]) <= Ordered(2, [0]),
              Ordered(3) > Ordered(2), Ordered(1) >= Ordered(1), outcome(lambda: Ordered(1) < 1)],
    "frozen": [outcome(lambda: setattr(One(1.0), "x", 2.0)),
               outcome(lambda: delattr(Three(1), "a")),
               outcome(lambda: setattr(Three(1), "new", 1)),
               outcome(lambda: setattr(plain, "new", 1)), getattr(plain, "new", None),
               outcome(lambda: setattr(plain, "a", 2))],
    "set": sorted(map(repr, {Three(i % 3, str(i)) for i in range(12)})),
    "names": [[getattr(getattr(cls, m), k) for k in ("__name__", "__qualname__", "__module__")]
              for cls, m in ((One, "__eq__"), (Three, "__hash__"), (Four, "__repr__"),
                             (Ordered, "__lt__"), (One, "__setattr__"))],
    "compiled": sorted({getattr(Four, m).__code__.co_filename == "<string>"
                        for m in ("__eq__", "__hash__", "__setattr__", "__delattr__")}),
}
print(json.dumps(cases))
'''


def _records(way: str) -> dict:
    env = {**__import__("os").environ, "PYTHONHASHSEED": "0"}  # the same string hashes
    run = subprocess.run([sys.executable, "-c", _RECORDS_PROBE, way], capture_output=True,
                         text=True, cwd=ROOT, timeout=120, check=True, env=env)
    return json.loads(run.stdout.strip().splitlines()[-1])


def test_the_command_lines_dataclass_methods_do_what_the_stdlibs_do():
    if sys.version_info[:2] not in ((3, 11), (3, 12)):
        pytest.skip("the stdlib's own methods on this Python (startup.DATACLASS_PYTHONS)")
    stdlib, closures = _records("stdlib"), _records("closures")
    # the stdlib's methods are compiled from source; the command line's are not
    assert stdlib.pop("compiled") == [True] and closures.pop("compiled") == [False]
    assert closures == stdlib
    # and what the stdlib's methods do, by hand (so both cannot be wrong the same way)
    assert stdlib["repr"][:4] == ["Empty()", "One(x=0.25)", "Three(a=1, b='x')",
                                  "Four(a=1, b='b', d=0.5)"]
    assert stdlib["repr"][4] == "Ordered(p=1, q=[...])"
    assert stdlib["eq"] == [True, True, True, False, True, False, False, False]
    assert stdlib["order"][:4] == [True, False, True, True]
    assert stdlib["frozen"][:2] == ["FrozenInstanceError: cannot assign to field 'x'",
                                    "FrozenInstanceError: cannot delete field 'a'"]
    assert stdlib["frozen"][3:5] == ["None", 1]


def test_the_command_lines_numpy_ma_is_imported_when_a_masked_array_is_asked_for():
    probe = ("import sys, json\nsys.argv[0] = 'mitld-lp'\nfrom mitld_lp import startup\n"
             "import numpy as np\n"
             "if sys.argv[1] == 'later':\n    startup.numpy_ma_when_used()\n"
             "plain = [np.ma.is_masked(np.arange(3.0)), np.ma.is_masked(np.array([])),\n"
             "         np.unique(np.array([3, 1, 3])).tolist()]\n"
             "before = 'numpy.ma' in sys.modules\n"
             "matrix = np.ma.is_masked(np.matrix([[1.0]]))  # not a plain array\n"
             "masked = np.ma.masked_array([1.0, 2.0], mask=[0, 1])\n"
             "view = np.ma.masked_array([1.0], mask=[0]).view(np.ndarray)\n"
             "rest = [np.ma.is_masked(masked), np.ma.is_masked(masked[:1]),\n"
             "        np.ma.is_masked(view), matrix,\n"
             "        np.unique(masked).tolist(), float(np.ma.mean(masked))]\n"
             "print(json.dumps(dict(before=before, answers=[plain, rest],\n"
             "    real=np.ma is sys.modules['numpy.ma'])))")
    runs = {way: json.loads(subprocess.run(
        [sys.executable, "-c", probe, way], capture_output=True, text=True, cwd=ROOT,
        timeout=120, check=True).stdout.strip().splitlines()[-1]) for way in ("now", "later")}
    # NumPy's own: numpy.ma imported by the first np.unique; the stand-in: not until a
    # masked array is made, then the real module in its place
    assert runs["now"]["before"] and not runs["later"]["before"]
    assert runs["now"]["real"] and runs["later"]["real"]
    # the same answers, and the ones NumPy's documentation gives
    assert runs["later"]["answers"] == runs["now"]["answers"] == [
        [False, False, [1, 3]], [True, False, False, False, [1.0, None], 1.0]]


def test_the_console_script_reads_its_words_once():
    # the words are parsed once (they were parsed for the time limit, then again for
    # the command): help is printed once, a usage error said once
    def command(*argv: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "mitld_lp", *argv], capture_output=True,
                              text=True, cwd=ROOT, timeout=120, check=False)

    shown = command("solve", "--help")
    assert shown.returncode == 0 and shown.stdout.count("usage: mitld-lp solve") == 1
    wrong = command("solve", "models/bus_grid.toml", "--no-such-flag")
    assert wrong.returncode == 2 and wrong.stdout == ""
    assert wrong.stderr.count("--no-such-flag") == 1, wrong.stderr


def test_the_routes_imported_later_claim_what_their_own_classes_claim():
    # the list's Later entries answer a plain problem without their module; asked of
    # the routes themselves (imported here), each would refuse it too, and a problem
    # with a band, constraints or a sensor reaches the route's own claims and name
    from mitld_lp import load_model
    from mitld_lp.routes import precedence
    from mitld_lp.synthesis import pose

    later = [r for r in precedence.ROUTES if isinstance(r, precedence.Later)]
    assert len(later) == len(precedence.ROUTES) - 1
    plain = pose(load_model(ROOT / "models" / "bus_grid.toml"))
    assert plain.route.name == "plain"
    assert not any(r.route().claims(plain) for r in later)
    constrained = pose(load_model(ROOT / "models" / "bus_grid.toml"), ["P(F A) >= 0.5"])
    assert constrained.route.name == "constrained" and constrained.route.takes_constraints
    # the constrained LP's routes claim a problem without constraints too
    assert any(r.claims(plain) for r in precedence.LP)
