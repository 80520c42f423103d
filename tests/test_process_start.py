"""The PRISM route's start and the product's thin batches (branch ``process-start``).

* A process that solves a PRISM model imports none of the modules the route does not
  use (checked in ``sys.modules`` of a fresh interpreter), started as a program and as
  the command line starts (``mitld_lp.startup.lean_start``); its bracket holds Storm's
  value, found by stormpy on the same PRISM file.
* A deterministic controller makes its generator on first use, the very stream a
  generator made at the start gives.
* The benchmark's worker processes import neither the package, NumPy nor lark before
  their route (Storm's process would pay them).
* The product built in thin batches (many batches, absorbing states among them) is the
  state-at-a-time build's (``mitld_lp.testing.reference_product``), bit for bit.
"""

from __future__ import annotations

import importlib
import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_product import assert_same_mdp  # equal state for state, bit for bit

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"
needs_stormpy = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                   reason="needs stormpy: pip install -e '.[prism]'")

# From x = 0..2: ``a`` moves on with 0.6 and falls into the sink (4) with 0.4; ``b``
# reaches the goal (3) with 0.3, the sink with 0.2, stays with 0.5.  By hand: b alone
# gives 0.3 / 0.5 = 0.6 everywhere; a from 2 gives 0.6 too, so the optimum is 0.6.
TINY = """mdp
module m
  x : [0..4] init 0;
  [a] x < 3 -> 0.6 : (x'=x+1) + 0.4 : (x'=4);
  [b] x < 3 -> 0.3 : (x'=3) + 0.2 : (x'=4) + 0.5 : (x'=x);
  [stay] x >= 3 -> true;
endmodule
label "goal" = x = 3;
"""

SOLVE = """
import json, sys
from mitld_lp import startup
if sys.argv[2] == "command":
    startup.hold_collector()
    startup.lean_start()
from mitld_lp import load_model, synthesize
startup.collect_from_here()
r = synthesize(load_model(sys.argv[1]))
print(json.dumps({"lower": r.lower, "upper": r.upper, "modules": sorted(sys.modules)}))
"""

# what a plain PRISM solve never needs: other solvers, the command line, the sweeps,
# the DRN writer, the simulator, exact arithmetic, plots, the trade-off curves, a saved
# controller's reader, numba (a small product), lark and its regex (the task's formula
# is plain: mitld_lp.logic.plain_parse reads it)
NEVER = ("cvxpy", "pandas", "matplotlib", "numba", "highspy", "mitld_lp.cli",
         "mitld_lp.sweep", "mitld_lp.files.drn", "mitld_lp.running",
         "mitld_lp.controllers.reader", "mitld_lp.plot", "mitld_lp.exact",
         "mitld_lp.tradeoff", "lark", "regex")
# ... and, started as the command line starts, what SciPy would import for nothing
# (numpy.random is not among them: SciPy's own ``_lib._util`` imports it)
NEVER_COMMAND = ("numpy.testing", "numpy.f2py", "numpy.polynomial")


def _tiny(tmp_path: Path) -> Path:
    (tmp_path / "tiny.prism").write_text(TINY, encoding="utf-8")
    path = tmp_path / "tiny.toml"
    path.write_text('name = "tiny"\nspec = "F goal"\n\n[prism]\nfile = "tiny.prism"\n',
                    encoding="utf-8")
    return path


def _storm_value(prism: Path) -> float:
    import stormpy

    program = stormpy.parse_prism_program(str(prism))
    prop = stormpy.parse_properties('Pmax=? [F "goal"]', program)[0]
    model = stormpy.build_model(program, [prop])
    result = stormpy.model_checking(model, prop)
    return float(result.get_value_vector()[model.initial_states[0]])


@needs_stormpy
@pytest.mark.parametrize("start", ["library", "command"])
def test_prism_solve_imports_only_what_it_uses(tmp_path, start):
    model = _tiny(tmp_path)
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "PYTHONDONTWRITEBYTECODE": "1"}
    out = subprocess.run([sys.executable, "-c", SOLVE, str(model), start], cwd=tmp_path,
                         capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    modules = set(got["modules"])
    never = NEVER + (NEVER_COMMAND if start == "command" else ())
    # a PRISM load without stormpy runs the own explorer's cached machine code, which needs
    # numba's runtime modules (not numba itself, nor its compiler)
    runtime = ("numba._dynfunc", "numba._helperlib", "numba.core.runtime._nrt_python")
    loaded = sorted(m for m in modules if any(m == n or m.startswith(n + ".") for n in never)
                    and m not in runtime)
    assert not loaded, f"imported by a plain PRISM solve ({start} start): {loaded}"
    assert "mitld_lp.product.build" in modules  # the route did run
    assert got["lower"] - 1e-9 <= 0.6 <= got["upper"] + 1e-9  # by hand (TINY)
    assert got["upper"] - got["lower"] <= 1e-6
    assert abs(_storm_value(tmp_path / "tiny.prism") - 0.6) <= 1e-6  # Storm agrees


# The command line's start with a formula the plain parser leaves to lark: lark is
# imported then, without regex (mitld_lp.library_start.lark_without_regex), and regex
# imports as usual after it.
MALFORMED = """
import json, sys
from mitld_lp import startup
startup.lean_start()
from mitld_lp.logic import ParseError, parse
try:
    parse(sys.argv[1])
except ParseError as err:
    said = str(err)
import lark.utils
had = "regex" in sys.modules
import regex
print(json.dumps({"said": said, "lark_regex": lark.utils._has_regex, "had": had,
                  "regex": regex.__name__}))
"""


def test_command_start_gets_lark_without_regex_only_when_a_formula_needs_it(tmp_path):
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "PYTHONDONTWRITEBYTECODE": "1"}
    out = subprocess.run([sys.executable, "-c", MALFORMED, "F[0,3] a &"], cwd=tmp_path,
                         capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    # lark's message, with the column of the end of input (by hand: after 10 characters)
    assert got["said"] == "1:11: unexpected end of input; expected a formula"
    assert got["lark_regex"] is False and got["had"] is False  # lark as without regex
    assert got["regex"] == "regex"  # ... and regex is anyone's after lark


@needs_stormpy
def test_controller_makes_its_generator_on_first_use(tmp_path):
    from mitld_lp import load_model, synthesize
    from mitld_lp.controllers.kinds import Controller

    r = synthesize(load_model(_tiny(tmp_path)))
    c = r.controller
    assert isinstance(c, Controller)
    assert c._rng is None  # never made by the solve
    assert np.array_equal(c.rng.random(6), np.random.default_rng(0).random(6))
    first = c.rng
    assert c.rng is first  # made once
    c.reset(seed=7)
    assert np.array_equal(c.rng.random(4), np.random.default_rng(7).random(4))
    c.reset()  # no seed: the generator runs on
    assert np.array_equal(c.rng.random(2), np.random.default_rng(7).random(6)[4:])


def test_bench_worker_imports_neither_the_package_nor_numpy():
    code = ("import sys; sys.path.insert(0, sys.argv[1]); import bench_qvbs; "
            "print(sorted(m for m in ('mitld_lp', 'numpy', 'lark', 'scipy', 'stormpy') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code, str(ROOT / "experiments")],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "[]"


def _cases(tmp_path: Path):
    """(game, sta) of: a PRISM table with a plain task (one outcome per situation, no
    events), the corridor (an event with a truncation point, several outcomes), and a
    grid with two events and bounded operators."""
    from mitld_lp.automata.sta import make_sta
    from mitld_lp.automata.translate import to_dta
    from mitld_lp.distributions import geometric, pmf
    from mitld_lp.logic import parse
    from mitld_lp.model import load_model
    from mitld_lp.worlds.grid import GridWorld

    for model in (load_model(_tiny(tmp_path)), load_model(MODELS / "corridor.toml")):
        yield model.game, make_sta(to_dta(model.spec), model.distributions, model.epsilon)
    game = GridWorld.make(3, 2, start=(0, 0), slip=0.1,
                          regions={"A": [(2, 0)], "B": [(0, 1)]})
    text = "(D[mu1] e1 & F(e1 & F[0,3] A)) | (D[mu2] e2 & F[1,4] (e2 & B))"
    dists = {"e1": geometric(0.4), "e2": pmf([0.1, 0.3, 0.2, 0.4])}
    yield game, make_sta(to_dta(parse(text)), dists, 0.01,
                         truncation=dict.fromkeys(dists, 3), clock_reduction=False)


@needs_stormpy
@pytest.mark.parametrize("entries", [1, 7, 1 << 18])
def test_thin_batches_give_the_state_at_a_time_product(tmp_path, monkeypatch, entries):
    from mitld_lp.product import product
    from mitld_lp.testing import reference_product

    build = importlib.import_module("mitld_lp.product.build")
    expand = build._expand
    batches = []

    def counted(f, keys, first_id, intern):
        batches.append((keys.size, bool((keys < 0).any())))
        return expand(f, keys, first_id, intern)

    monkeypatch.setattr(build, "BATCH_ENTRIES", entries)  # 1: batches of 16 states
    monkeypatch.setattr(build, "_expand", counted)
    for game, sta in _cases(tmp_path):
        batches.clear()
        mdp = product(game, sta)
        assert_same_mdp(mdp, reference_product(game, sta))
        if entries == 1 and mdp.n_states > 40:  # thin: several batches, some mixed
            assert len(batches) > 2
            assert any(absorbing for _, absorbing in batches)
