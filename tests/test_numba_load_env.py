"""The array helpers' environments of a cached kernel rebuilt without importing
``numba.np.arrayobj`` (:func:`mitld_lp.util.numba_narrow._stand_in_environments`):
only while a kernel is loaded from the cache, only for that module not imported yet and
only for an environment without constants; numba's own rebuild everywhere else; and a
kernel that allocates arrays gives the answer worked out by hand here.  Each case runs in
a fresh process (numba's environments are memoised a process)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("numba")

ROOT = Path(__file__).resolve().parent.parent

REBUILD = r"""
import json, sys
from mitld_lp.util import numba_narrow
numba_narrow.import_numba()
assert numba_narrow.install()
from numba.core import environment, serialize
out = {"before": "numba.np.arrayobj" in sys.modules,
       "numba_own_outside": environment._rebuild_env.__module__ == "numba.core.environment"}
rebuild = numba_narrow._rebuild_env  # what a cached kernel's load unpickles with
numba_narrow._loading.active = True  # as while numba's cache loads a kernel
env = rebuild("numba.np.arrayobj", [], "test_env_a")
out["stand_in"] = dict(env.globals) == {"__name__": "numba.np.arrayobj"}
out["memo"] = environment.lookup_environment("test_env_a") is env
out["same_again"] = rebuild("numba.np.arrayobj", [], "test_env_a") is env
out["imported_while_loading"] = "numba.np.arrayobj" in sys.modules
# pickled as numba pickles it (a cache save): by numba's rebuild, no name of ours
out["pickle_clean"] = b"mitld_lp" not in serialize.dumps(env)
other = rebuild("numba.np.arrayobj", [7], "test_env_b")  # constants: numba's rebuild
out["with_consts_full"] = (other.globals is sys.modules["numba.np.arrayobj"].__dict__
                           and list(other.consts) == [7])
numba_narrow._loading.active = False
env_c = rebuild("numba.np.arrayobj", [], "test_env_c")
out["outside_full"] = env_c.globals is sys.modules["numba.np.arrayobj"].__dict__
print(json.dumps(out))
"""

GRAPH = r"""
import json, sys
import numpy as np, scipy.sparse as sp
from mitld_lp.util import numba_narrow
numba_narrow.import_numba()
from mitld_lp.solvers import compiled_graph
# choices: state 0 a -> 1; state 0 b -> 3 (1/2), 0 (1/2); state 1 -> 0; state 2 -> 2, 3;
# state 3 -> 3
rows = np.array([[0, 1, 0, 0], [0.5, 0, 0, 0.5], [1, 0, 0, 0], [0, 0, 0.5, 0.5],
                 [0, 0, 0, 1.0]])
m = sp.csr_array(rows)
alive, allowed, label = compiled_graph.end_components_among(
    m.indptr, m.indices, m.data > 0, np.array([0, 2, 3, 4, 5]), np.array([0, 1, 2]))
print(json.dumps({"alive": alive.tolist(), "allowed": allowed.tolist(),
                  "label": label.tolist(),
                  "arrayobj": "numba.np.arrayobj" in sys.modules}))
"""


def _run(code: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=env, timeout=600)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_stand_in_only_while_loading_without_constants() -> None:
    out = _run(REBUILD)
    assert out["before"] is False  # numba's import alone does not bring it
    assert out["numba_own_outside"]  # swapped in only for a cached kernel's load
    assert out["stand_in"] and out["memo"] and out["same_again"]
    assert out["imported_while_loading"] is False
    assert out["pickle_clean"]
    assert out["with_consts_full"]  # constants: numba's rebuild, the module's globals
    assert out["outside_full"]


def test_allocating_kernel_answers_as_by_hand_in_two_processes() -> None:
    """Candidates 0, 1, 2: state 2's only choice leaves to 3 (not a candidate), so 2 is
    dropped; state 0's choice b leaves to 3 too; {0, 1} by choice a and 1's choice is an
    end component.  The first process may compile (a cold cache), the second loads."""
    for _ in range(2):
        out = _run(GRAPH)
        assert out["alive"] == [True, True, False]
        assert out["allowed"] == [True, False, True, False]
        assert out["label"][0] == out["label"][1]
