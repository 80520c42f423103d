"""A PRISM property's route in a fresh program imports only what it uses.

A program that imports the package and solves a PRISM model past the small-graph walks
(SciPy's csgraph searches it, the chain solves factorise) runs in a fresh interpreter;
after its answer, ``sys.modules`` says what was imported: neither ``scipy.linalg`` nor
``scipy.sparse.linalg`` has run its ``__init__`` (the package's csgraph and direct
solvers come without them), ``regex`` (lark's optional package) is not imported, nor
cvxpy, pandas or HiGHS.  The answer is checked against Storm's own sound check of the
same PRISM file and property (stormpy, interval iteration to 1e-9), an independent
route.  Then, in the same process, what other routes read of those modules loads them
whole, as SciPy's and lark's own.
"""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

N = 12_000  # a walk of N cells: past traversal.SMALL, one cyclic component

PRISM = f"""mdp
const int N = {N};
module walk
  x : [0..N+1] init 1;
  // x = 0: lost; x = N+1: reached
  [fast] x>0 & x<N+1 -> 0.5:(x'=min(x+1, N+1)) + 0.499:(x'=x-1) + 0.001:(x'=N+1);
  [safe] x>0 & x<N+1 -> 0.6:(x'=min(x+1, N+1)) + 0.3999:(x'=max(x-1, 1)) + 0.0001:(x'=0);
  [] x=0 | x=N+1 -> true;
endmodule
label "goal" = x=N+1;
"""

PROBE = r"""
import json, sys, types
from mitld_lp import load_model, synthesize
r = synthesize(load_model(sys.argv[1]))

def state(name):
    m = sys.modules.get(name)
    return "absent" if m is None else "run" if type(m) is types.ModuleType else "later"

out = dict(lower=r.lower, upper=r.upper, certified=r.certified,
           states=int(r.mdp.n_states), linalg=state("scipy.linalg"),
           sparse_linalg=state("scipy.sparse.linalg"), csgraph=state("scipy.sparse.csgraph"),
           imported=sorted(m for m in ("regex", "cvxpy", "pandas", "highspy", "numba")
                           if m in sys.modules))
# what another route reads: SciPy's whole module, its own names
import numpy as np, scipy.sparse as sp
spla = sys.modules["scipy.sparse.linalg"]
out["expm"] = float(spla.expm_multiply(sp.csr_array(np.zeros((1, 1))), np.ones(1))[0])
out["after"] = [state("scipy.linalg"), state("scipy.sparse.linalg")]
out["lu"] = sys.modules["scipy.linalg"].lu_factor is getattr(
    __import__("scipy.linalg._decomp_lu", fromlist=["lu_factor"]), "lu_factor")
# lark's regex, asked for by a grammar: the real package, then the program's own import
from lark import Lark
g = Lark("start: W\nW: /\\p{Lu}+/\n", parser="lalr", regex=True)
out["unicode"] = str(g.parse("ÄB").children[0])
import regex
out["regex"] = type(regex).__name__ + ":" + str(type(regex) is types.ModuleType
                                                and regex.match(r"\p{Lu}", "Ä") is not None)
print(json.dumps(out))
"""


def _storm(prism: Path) -> float:
    pytest.importorskip("stormpy")
    from storm_exact import storm_sound

    return storm_sound(prism, 'Pmax=? [F "goal"]')


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, float]:
    pytest.importorskip("stormpy")
    work = tmp_path_factory.mktemp("walk")
    prism = work / "walk.prism"
    prism.write_text(PRISM, encoding="utf-8")
    model = work / "walk.toml"
    model.write_text('name = "walk"\nspec = "F reached"\n\n[prism]\nfile = "walk.prism"\n\n'
                     '[labels]\nreached = "x = N + 1"\n', encoding="utf-8")
    from fresh_child import run_fresh

    return run_fresh(PROBE, str(model)), _storm(prism)


def test_the_prism_route_leaves_scipys_linear_algebra_and_regex_unimported(run) -> None:
    got, _ = run
    assert got["states"] > 10_000  # past the small-graph walks: csgraph searched it
    assert got["csgraph"] == "run"
    assert got["linalg"] in ("later", "absent")
    assert got["sparse_linalg"] == "later"
    assert got["imported"] == []


def test_the_answer_is_storms(run) -> None:
    got, storm = run
    assert got["certified"] is True
    assert got["lower"] <= got["upper"]
    # Storm's sound value within 1e-9 of the optimum: inside our bracket, widened by it
    assert got["lower"] - 2e-9 <= storm <= got["upper"] + 2e-9
    assert 0.5 < storm < 0.999  # a value the numbers decide, not the graph (0 or 1)


def test_other_routes_get_scipys_and_larks_own_modules_on_first_use(run) -> None:
    got, _ = run
    # expm_multiply of the zero matrix is the identity's action: exp(0) * 1 = 1
    assert got["expm"] == 1.0
    assert got["after"] == ["run", "run"]
    assert got["lu"] is True
    assert got["unicode"] == "ÄB"
    assert got["regex"] == "module:True"
