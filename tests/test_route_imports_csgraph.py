"""SciPy's graph searches without its linear algebra (``library_start.sparse_linalg_later``):
csgraph imported through the package leaves ``scipy.linalg`` unloaded until a name of
``scipy.sparse.linalg`` other than ``LinearOperator`` is read; the module is then SciPy's
own, name for name."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: argv[1]: "program" (import mitld_lp, then library_start.install()), "command" (the
#: command line's start), "plain" (import mitld_lp alone: no hook, the package's own
#: import of csgraph), "scipy" (the program imports csgraph itself before the package:
#: SciPy's own imports, the reference).  A strongly connected ring past the small-graph
#: walks, searched by the package; then csgraph's Laplacian as an operator; then a
#: factorisation; then a name of ``scipy.sparse.linalg`` that is not served.
PROBE = r"""
import json, sys, types
way = sys.argv[1]
if way == "scipy":
    import scipy.sparse.csgraph
import mitld_lp
from mitld_lp import library_start, startup
if way == "program":
    library_start.install()
if way == "command":
    startup.lean_start()
import numpy as np, scipy.sparse as sp

def loaded(name):
    return type(sys.modules.get(name)) is types.ModuleType

from mitld_lp.util import traversal
n = traversal.SMALL + 1
ring = sp.csr_array((np.ones(n), (np.arange(n), (np.arange(n) + 1) % n)))
out = dict(components=int(traversal.strong_components(ring)[0]))
out["after_walk"] = loaded("scipy.linalg")
from scipy.sparse import csgraph
lo = csgraph.laplacian(np.array([[0.0, 1.0], [1.0, 0.0]]), form="lo")
out["laplacian"] = (lo @ np.array([[1.0], [2.0]])).ravel().tolist()
out["after_operator"] = loaded("scipy.linalg")
from scipy.sparse.linalg import splu
a = sp.csc_array(np.array([[4.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 2.0]]))
out["solved"] = splu(a).solve(np.array([1.0, 2.0, 3.0])).tolist()
try:
    splu(sp.csc_array(np.zeros((2, 2))))
except Exception as exc:  # SciPy's error for a singular matrix, as SciPy raises it
    out["singular"] = [type(exc).__name__, str(exc)]
out["after_splu"] = loaded("scipy.linalg")
spla = sys.modules["scipy.sparse.linalg"]
norm = spla.norm(sp.csr_array(np.array([[3.0, 4.0]])))  # not served: the whole module
out["norm"] = float(norm)
out["after_norm"] = loaded("scipy.linalg")
out["kind"] = type(spla).__name__
out["names"] = sorted(vars(spla))
out["linalg_names"] = sorted(vars(sys.modules["scipy.linalg"]))
out["bound"] = sp.linalg is spla and spla.LinearOperator is sys.modules[
    "scipy.sparse.linalg._interface"].LinearOperator
out["same_solver"] = splu is spla.splu is sys.modules["scipy.sparse.linalg._dsolve"].splu
out["same_error"] = sys.modules["scipy.linalg"].LinAlgError is np.linalg.LinAlgError
print(json.dumps(out))
"""


def _run(way: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    done = subprocess.run([sys.executable, "-c", PROBE, way], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_graph_searches_leave_scipys_linear_algebra_until_a_factorisation() -> None:
    scipy = _run("scipy")
    # the program's own import of csgraph loads it whole: the probe can see it
    assert scipy["after_walk"] is True
    for way in ("plain", "program", "command"):
        run = _run(way)
        assert run["components"] == scipy["components"] == 1  # one ring
        assert run["after_walk"] is False and run["after_operator"] is False
        # the direct solvers come without scipy.linalg's __init__ ...
        assert run["after_splu"] is False
        # ... and a name they do not serve loads both whole
        assert run["after_norm"] is True
        assert run["norm"] == scipy["norm"] == 5.0  # |(3, 4)| = 5
        # L = D - A of the 2-cycle: [[1, -1], [-1, 1]] @ [1, 2] = [-1, 1]
        assert run["laplacian"] == scipy["laplacian"] == [-1.0, 1.0]
        # the factorisation solves the system: A x gives back the right-hand side
        a = [[4.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 2.0]]
        back = [sum(a[i][j] * run["solved"][j] for j in range(3)) for i in range(3)]
        assert max(abs(b - t) for b, t in zip(back, [1.0, 2.0, 3.0], strict=True)) < 1e-12
        assert run["solved"] == scipy["solved"]
        # a singular matrix: SciPy's own error, before scipy.linalg is loaded too
        assert run["singular"] == scipy["singular"] and run["singular"][0] == "RuntimeError"
        # then SciPy's own modules: plain modules, the same names, bound as submodules
        assert run["kind"] == scipy["kind"] == "module"
        assert run["names"] == scipy["names"]
        assert run["linalg_names"] == scipy["linalg_names"]
        assert run["bound"] is True and scipy["bound"] is True
        assert run["same_solver"] is True and run["same_error"] is True
