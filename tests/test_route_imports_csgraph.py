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
#: command line's start), "plain" (import mitld_lp alone: no hook).  A strongly
#: connected ring past the small-graph walks, searched by the package; then csgraph's
#: Laplacian as an operator; then a factorisation.
PROBE = r"""
import json, sys
way = sys.argv[1]
import mitld_lp
from mitld_lp import library_start, startup
if way == "program":
    library_start.install()
if way == "command":
    startup.lean_start()
import numpy as np, scipy.sparse as sp
from mitld_lp.util import traversal
n = traversal.SMALL + 1
ring = sp.csr_array((np.ones(n), (np.arange(n), (np.arange(n) + 1) % n)))
out = dict(components=int(traversal.strong_components(ring)[0]))
out["after_walk"] = "scipy.linalg" in sys.modules
from scipy.sparse import csgraph
lo = csgraph.laplacian(np.array([[0.0, 1.0], [1.0, 0.0]]), form="lo")
out["laplacian"] = (lo @ np.array([[1.0], [2.0]])).ravel().tolist()
out["after_operator"] = "scipy.linalg" in sys.modules
from scipy.sparse.linalg import splu
a = sp.csc_array(np.array([[4.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 2.0]]))
out["solved"] = splu(a).solve(np.array([1.0, 2.0, 3.0])).tolist()
out["after_splu"] = "scipy.linalg" in sys.modules
spla = sys.modules["scipy.sparse.linalg"]
out["kind"] = type(spla).__name__
out["names"] = sorted(vars(spla))
out["bound"] = sp.linalg is spla and spla.LinearOperator is sys.modules[
    "scipy.sparse.linalg._interface"].LinearOperator
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
    plain = _run("plain")
    # without the stand-in, csgraph's import loads it: the probe can see it
    assert plain["after_walk"] is True
    for way in ("program", "command"):
        run = _run(way)
        assert run["components"] == plain["components"] == 1  # one ring
        assert run["after_walk"] is False and run["after_operator"] is False
        assert run["after_splu"] is True
        # L = D - A of the 2-cycle: [[1, -1], [-1, 1]] @ [1, 2] = [-1, 1]
        assert run["laplacian"] == plain["laplacian"] == [-1.0, 1.0]
        # the factorisation solves the system: A x gives back the right-hand side
        a = [[4.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 2.0]]
        back = [sum(a[i][j] * run["solved"][j] for j in range(3)) for i in range(3)]
        assert max(abs(b - t) for b, t in zip(back, [1.0, 2.0, 3.0], strict=True)) < 1e-12
        assert run["solved"] == plain["solved"]
        # then SciPy's own module: a plain module, the same names, bound as a submodule
        assert run["kind"] == plain["kind"] == "module"
        assert run["names"] == plain["names"]
        assert run["bound"] is True and plain["bound"] is True
