"""What the sensed build leaves to the solve: a process whose kernel cache is warm
builds with the compiled kernels without importing numba (they are linked by
:mod:`mitld_lp.util.kernel_loader`), the same product to the bit as the NumPy lines.
(That the build's arrays are freed when ``belief_product`` returns, with the collector
off, is checked level by level in ``test_sensed_mem_chunks.py``.)"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_sensing_build import CASES

from mitld_lp.automata.translate import to_dta
from mitld_lp.sensing import rows
from mitld_lp.sensing.belief import belief_product

ROOT = Path(__file__).resolve().parent.parent


def _build(model):
    return belief_product(model.game, to_dta(model.spec), model.distributions,
                          dict(model.sensors), model.epsilon, max_states=10**6)


def _digest(mdp) -> str:
    h = hashlib.sha256()
    m = mdp.matrix
    for x in (m.data, m.indices, m.indptr, mdp.row_groups, mdp.choice_actions):
        h.update(np.ascontiguousarray(x).tobytes())
    return h.hexdigest()


_CHILD = """
import json, sys
from test_sensed_solve_memory import CASES, _build, _digest
from mitld_lp.sensing import rows
from mitld_lp.util import kernel_loader
with rows.running_kernels(True):
    belief = _build(CASES["two cameras"]())
print(json.dumps(dict(numba="numba" in sys.modules, linked=kernel_loader.loaded_count(),
                      digest=_digest(belief.mdp))))
"""


@pytest.mark.skipif(any(k.startswith("NUMBA_") and k != "NUMBA_CACHE_DIR"
                        for k in os.environ),
                    reason="a NUMBA_* setting leaves every kernel to numba")
def test_warm_build_links_kernels_without_numba() -> None:
    """A second process (the first warms the caches) builds with the kernels, numba
    never imported, and gets the product the NumPy lines make here."""
    pytest.importorskip("numba")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), str(ROOT / "tests")]))
    runs = []
    for _ in range(2):
        out = subprocess.run([sys.executable, "-c", _CHILD], cwd=ROOT, env=env,
                             capture_output=True, text=True, check=True)
        runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    warm = runs[1]
    assert not warm["numba"], "the warm build imported numba"
    assert warm["linked"] > 0
    with rows.running_kernels(False):
        plain = _build(CASES["two cameras"]())
    assert warm["digest"] == runs[0]["digest"] == _digest(plain.mdp)
