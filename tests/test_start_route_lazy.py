"""The command line's stand-ins (:mod:`mitld_lp.stand_ins`): what they keep out of the
bundled case's process, that the answer is the same to the bit as a process without them,
and that a module put off is the real module once used (its names, its state)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from mitld_lp import stand_ins
from mitld_lp.cli import _VERBS, _build_parser

ROOT = Path(__file__).resolve().parent.parent

#: The bundled case's command as ``python -m mitld_lp`` runs it; after its answer, a
#: marker line with, for each watched module, whether the process holds it and whether
#: what it holds is the real module (a file of its own) or a stand-in.
PROBE = r"""
import atexit, json, runpy, sys
watched = json.loads(sys.argv[1])
sys.argv = ["-m", *sys.argv[2:]]
def report():
    seen = {m: [m in sys.modules, getattr(sys.modules.get(m), "__file__", None) is not None]
            for m in watched}
    sys.stdout.write("\nMODULES " + json.dumps(seen) + "\n")
    sys.stdout.flush()
atexit.register(report)
runpy.run_module("mitld_lp", run_name="__main__")
"""

#: A program solving the bundled case through the library (no stand-ins): its bracket.
LIBRARY = r"""
import json
from mitld_lp import load_model, synthesize
r = synthesize(load_model("models/bus_grid.toml"))
print(json.dumps({"lower": r.lower, "upper": r.upper, "certified": r.certified}))
"""

#: Kept out of the bundled case's process altogether.
ABSENT = ("sysconfig", "_posixsubprocess", "numpy.f2py")


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    return env


@pytest.fixture(scope="module")
def bundled() -> tuple[dict, dict]:
    watched = (*stand_ins.LATER_MODULES, stand_ins.SCIPY_TESTS, *ABSENT,
               *stand_ins.NUMPY_DOC_MODULES, "numpy", "lark")
    done = subprocess.run(
        [sys.executable, "-c", PROBE, json.dumps(watched), "solve", "models/bus_grid.toml",
         "--json", "-q"], cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    answer, _, modules = done.stdout.rpartition("\nMODULES ")
    return json.loads(answer), json.loads(modules)


def test_put_off_modules_stay_stand_ins_in_the_bundled_case(bundled):
    answer, modules = bundled
    assert answer["certified"] is True
    assert modules["numpy"] == [True, True]
    assert modules["lark"] == [False, False]  # a plain formula: no lark (plain_parse)
    # each put-off module is in the process as its stand-in (no file), never run
    put_off = (*stand_ins.LATER_MODULES, stand_ins.SCIPY_TESTS)
    assert {m: modules[m] for m in put_off} == {m: [True, False] for m in put_off}
    # NumPy's docstring modules were the empty ones, and these were never imported
    assert all(modules[m] == [True, False] for m in stand_ins.NUMPY_DOC_MODULES)
    assert [m for m in ABSENT if modules[m][0]] == []


def test_bundled_case_answer_is_the_library_s_to_the_bit(bundled):
    answer, _ = bundled
    done = subprocess.run([sys.executable, "-c", LIBRARY], cwd=ROOT, env=_env(),
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    library = json.loads(done.stdout)
    assert (answer["lower"], answer["upper"]) == (library["lower"], library["upper"])
    # Storm's sound value iteration on the case's PRISM encoding: 0.9244053
    # (experiments/bench_startup.py); the bracket holds it to Storm's precision
    assert answer["lower"] - 1e-6 <= 0.9244053 <= answer["upper"] + 1e-6


@pytest.fixture
def fresh_module(tmp_path, monkeypatch):
    """A module ``sr_later_probe`` on the path, not imported yet: a counter of its runs
    (in the environment, which outlives the module) and a global state."""
    (tmp_path / "sr_later_probe.py").write_text(textwrap.dedent("""
        import os
        os.environ["SR_LATER_RUNS"] = str(int(os.environ.get("SR_LATER_RUNS", "0")) + 1)
        level = 1
        def current():
            return level
    """), encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("SR_LATER_RUNS", "0")
    monkeypatch.setattr(stand_ins, "LATER_MODULES", ("sr_later_probe", "sr_no_such_module"))
    monkeypatch.delitem(sys.modules, "sr_later_probe", raising=False)
    yield "sr_later_probe"
    sys.modules.pop("sr_later_probe", None)


def test_a_put_off_module_runs_when_a_name_is_read(fresh_module):
    stand_ins.modules_when_used()
    import sr_later_probe as bound  # the stand-in: nothing run yet

    assert os.environ["SR_LATER_RUNS"] == "0"
    assert "sr_no_such_module" not in sys.modules  # a missing module is left alone
    assert bound.current() == 1  # the real module, run once
    assert os.environ["SR_LATER_RUNS"] == "1"
    real = sys.modules[fresh_module]
    assert real is not bound and real.__file__.endswith("sr_later_probe.py")
    # the importer's binding and the real module are one state
    bound.level = 5
    assert real.level == 5 and bound.current() == 5 and real.current() == 5
    del bound.level
    assert not hasattr(real, "level")
    assert "current" in dir(bound)
    assert os.environ["SR_LATER_RUNS"] == "1"


def test_a_from_import_gets_the_real_name(fresh_module):
    stand_ins.modules_when_used()
    from sr_later_probe import current

    assert current() == 1 and os.environ["SR_LATER_RUNS"] == "1"
    assert current is sys.modules[fresh_module].current


#: SciPy imported with its test runner put off: the runner is there, its module is not,
#: until a name of it is read.
SCIPY_TESTS = r"""
import json, sys
from mitld_lp import stand_ins
stand_ins.scipy_tests_when_used()
import scipy.sparse
tester = scipy.sparse.test
before = getattr(sys.modules[stand_ins.SCIPY_TESTS], "__file__", None)
real = sys.modules[stand_ins.SCIPY_TESTS]
warning = real.FPUModeChangeWarning  # a name read: the real module
after = sys.modules[stand_ins.SCIPY_TESTS]
print(json.dumps(dict(name=tester.module_name, before=before, real=after.__file__,
                      warning=issubclass(warning, RuntimeWarning),
                      runner=after.PytestTester("scipy.sparse").module_name)))
"""


def test_scipy_test_runner_is_imported_when_used():
    done = subprocess.run([sys.executable, "-c", SCIPY_TESTS], cwd=ROOT, env=_env(),
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    got = json.loads(done.stdout)
    assert got["name"] == "scipy.sparse"
    assert got["before"] is None  # the stand-in until then
    assert got["real"].endswith("_testutils.py") and got["warning"] is True
    assert got["runner"] == "scipy.sparse"


def test_a_verb_s_parser_has_only_that_verb():
    words = ["solve", "models/bus_grid.toml", "--json"]
    sub = next(a for a in _build_parser(words)._actions if a.dest == "verb")
    assert list(sub.choices) == ["solve"]
    # no verb, or a misspelt one: every verb, for the help and the error's list
    for words in ([], ["--help"], ["solv", "x"]):
        sub = next(a for a in _build_parser(words)._actions if a.dest == "verb")
        assert list(sub.choices) == [verb for verb, *_ in _VERBS]


def test_flatten_tells_constants_apart_as_the_dataclass_comparison_does():
    from mitld_lp.logic.syntax import FALSE, TRUE, And, Const, Or, Prop, flatten

    a, b = Prop("a"), Prop("b")
    # fresh constants (not the module's TRUE/FALSE objects): the unit is dropped, the
    # zero decides, nested operands of the same kind are flattened, duplicates dropped
    assert flatten(And, [a, Const(True), And((a, b)), b]) == [a, b]
    assert flatten(And, [a, Const(False), b]) is FALSE
    assert flatten(Or, [Const(False), a, Or((b, a))]) == [a, b]
    assert flatten(Or, [a, Const(True)]) is TRUE
    assert flatten(And, [Const(True), Const(True)]) == []
    # operands of the other kind stay whole, in order of first occurrence
    assert flatten(Or, [And((a, b)), a, And((a, b))]) == [And((a, b)), a]


def test_a_submodule_of_a_put_off_package_imports(tmp_path, monkeypatch):
    package = tmp_path / "sr_later_package"
    package.mkdir()
    (package / "__init__.py").write_text("name = 'package'\n", encoding="utf-8")
    (package / "part.py").write_text("name = 'part'\n", encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(stand_ins, "LATER_MODULES", ("sr_later_package",))
    try:
        stand_ins.modules_when_used()
        import sr_later_package.part as part  # the package's __path__: the real package's

        assert part.name == "part"
        assert sys.modules["sr_later_package"].name == "package"
        assert sys.modules["sr_later_package"].__file__.endswith("__init__.py")
    finally:
        for name in ("sr_later_package.part", "sr_later_package"):
            sys.modules.pop(name, None)
