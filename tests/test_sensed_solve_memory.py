"""What the sensed build leaves to the solve: the arrays only the build needs are
freed when ``belief_product`` returns (the builder lives on in reference cycles until
the collector's next full pass), and a process whose kernel cache is warm
builds with the compiled kernels without importing numba (they are linked by
:mod:`mitld_lp.util.kernel_loader`), the same product to the bit as the NumPy lines."""

from __future__ import annotations

import gc
import hashlib
import json
import os
import subprocess
import sys
import weakref
from pathlib import Path

import numpy as np
import pytest
from test_sensing_build import CASES

from mitld_lp.automata.translate import to_dta
from mitld_lp.sensing import frontier, rows
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


@pytest.mark.parametrize("kernels", [False, True])
def test_build_arrays_freed_without_the_collector(monkeypatch, kernels: bool) -> None:
    """With the cyclic collector off, the arrays only the build needs (the rows' pages,
    the information states' keys) do not outlive it: only reference counting frees
    them, so no cycle through the builder holds them into the solve."""
    if kernels:
        pytest.importorskip("numba")
    held: list[weakref.ref] = []
    build = frontier.FrontierBuilder.build

    def recorded(self, *args, **kwargs):
        out = build(self, *args, **kwargs)
        arrays = (*self.row_work, self.keys.slots, self.keys.keys)
        assert all(isinstance(a, np.ndarray) for a in arrays)
        held.extend(weakref.ref(a) for a in arrays)
        return out

    model = CASES["two cameras"]()
    with rows.running_kernels(kernels):  # a kernel compiled in the build (a cold cache)
        _build(model)  # leaves numba's own cycles behind: compiled here, before the count
    monkeypatch.setattr(frontier.FrontierBuilder, "build", recorded)
    collecting = gc.isenabled()
    gc.disable()
    try:
        with rows.running_kernels(kernels):
            belief = _build(model)
        assert belief.mdp.n_states > 1
        assert len(held) == 4
        alive = [i for i, ref in enumerate(held) if ref() is not None]
        assert not alive, f"the build's arrays {alive} outlived it"
    finally:
        if collecting:
            gc.enable()


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
