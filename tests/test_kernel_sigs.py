"""Each compiled kernel is compiled for one signature a run (its entry point normalises
the index arrays it passes: int32 where the sizes fit, as
:func:`mitld_lp.util.arrays.index_dtype` decides), with the same answers to the bit; and
every module of compiled kernels puts numba's narrow cached load in place as it is
imported (:mod:`mitld_lp.solvers.numba_narrow`)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import kernels
from mitld_lp.solvers.graph import Sense

numba = pytest.importorskip("numba")

ROOT = Path(__file__).resolve().parent.parent

COMPILED_MODULES = ("mitld_lp.solvers.compiled_kernels", "mitld_lp.solvers.level_kernels",
                    "mitld_lp.solvers.compiled_graph", "mitld_lp.solvers.compiled_elimination",
                    "mitld_lp.sensing.kernels", "mitld_lp.sensing.group_kernels")


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    return env


def _with_index(matrix: sp.csr_array, dtype: type) -> sp.csr_array:
    """``matrix`` with its ``indptr`` and ``indices`` in ``dtype`` (set after building:
    SciPy's constructor may pick its own index type)."""
    out = sp.csr_array(matrix, copy=True)
    out.indptr = out.indptr.astype(dtype)
    out.indices = out.indices.astype(dtype)
    assert out.indptr.dtype == dtype and out.indices.dtype == dtype
    return out


# ------------------------------------------------------------------ the block kernel
def _block() -> tuple[sp.csr_array, np.ndarray, np.ndarray, dict]:
    """A ring of 5 states, two choices each, two models (goal, fail: lower and upper
    columns each).  A: on to the next state 1/2, goal 3/8, fail 1/8; B: stay 3/4, goal
    1/8, fail 1/8 (its self-loop solved: 1/2 for either).  Goal, max: x = max(3/8 +
    x/2, 1/2) = 3/4; min: min(3/8 + x/2, 1/2) = 1/2.  Fail, max: max(1/8 + x/2, 1/2) =
    1/2; min: min(1/8 + x/2, 1/2) = 1/4.  The exact values by sense, per model."""
    n = 5
    rows, cols, vals, exits = [], [], [], []
    for s in range(n):
        rows.append(2 * s), cols.append((s + 1) % n), vals.append(0.5)
        exits.append((0.375, 0.375, 0.125, 0.125))
        rows.append(2 * s + 1), cols.append(s), vals.append(0.75)
        exits.append((0.125, 0.125, 0.125, 0.125))
    inner = sp.csr_array((vals, (rows, cols)), shape=(2 * n, n))
    exact = {Sense.MAX: (0.75, 0.5), Sense.MIN: (0.5, 0.25)}
    return inner, np.arange(0, 2 * n + 1, 2), np.array(exits), exact


def _half_block() -> tuple[sp.csr_array, np.ndarray, np.ndarray, dict]:
    """Two states, one choice each: to the other state with 1/2, to the goal with 1/4,
    else lost: x = 1/4 + x/2, so x = 1/2 exactly at both, in either sense."""
    inner = sp.csr_array(np.array([[0.0, 0.5], [0.5, 0.0]]))
    return inner, np.array([0, 1, 2]), np.full((2, 2), 0.25), {s: (0.5,) for s in Sense}


SENSES = (Sense.MAX, Sense.MIN)


@pytest.fixture(scope="module")
def swept() -> dict:
    """Both blocks swept by the compiled kernel from int32 and from int64 index arrays,
    and by the NumPy sweeps; the kernel's signatures after."""
    if kernels.compiled_kernel() is None:
        pytest.skip("numba is not installed")
    from mitld_lp.solvers import compiled_kernels

    out: dict = {}
    for name, make in (("ring", _block), ("half", _half_block)):
        inner, groups, exits, exact = make()
        out[name, "exact"] = exact
        for sense in SENSES:
            for label, dtype in (("int32", np.int32), ("int64", np.int64)):
                prep = kernels.Prepared(_with_index(inner, dtype), groups)
                local = np.tile([0.0, 1.0], (groups.size - 1, exits.shape[1] // 2))
                done, over = kernels.compiled_sweeps(prep, exits, local, 1e-12, 10_000, sense)
                out[name, label, sense] = (local, done, over)
            prep = kernels.Prepared(inner, groups)
            local = np.tile([0.0, 1.0], (groups.size - 1, exits.shape[1] // 2))
            _, over = kernels.numpy_sweeps(prep, exits, local, 1e-12, 10_000, sense)
            out[name, "numpy", sense] = (local, None, over)
    out["signatures"] = list(compiled_kernels.gauss_seidel.signatures)
    return out


def test_block_kernel_compiled_for_one_index_type(swept: dict) -> None:
    sigs = swept["signatures"]
    assert len(sigs) == 1, sigs
    indptr, indices = sigs[0][:2]
    assert indptr.dtype == numba.int32 and indices.dtype == numba.int32


def test_block_kernel_same_bits_from_either_index_type(swept: dict) -> None:
    for name in ("ring", "half"):
        for sense in SENSES:
            a, b = swept[name, "int32", sense], swept[name, "int64", sense]
            assert a[1] == b[1] and a[2] == b[2] < 1.0
            assert np.array_equal(a[0], b[0])  # bit for bit (no NaN here)


def test_block_kernel_brackets_the_exact_values(swept: dict) -> None:
    """Against the fixed points worked out by hand (each block's docstring), and the
    NumPy sweeps' bracket around the same values."""
    for name in ("ring", "half"):
        for sense in SENSES:
            for route in ("int32", "numpy"):
                local, _, over = swept[name, route, sense]
                assert over < 1.0
                for j, value in enumerate(swept[name, "exact"][sense]):
                    lo, hi = local[:, 2 * j], local[:, 2 * j + 1]
                    assert np.all(lo <= value) and np.all(value <= hi), (name, sense, j)
                    assert np.all(hi - lo <= 1e-12)


def test_block_index_is_not_copied_when_it_has_the_type() -> None:
    inner, groups, _, _ = _half_block()
    inner32 = _with_index(inner, np.int32)
    indptr, indices = kernels.Prepared(inner32, groups).index
    assert indptr is inner32.indptr and indices is inner32.indices
    inner64 = _with_index(inner, np.int64)
    indptr, indices = kernels.Prepared(inner64, groups).index
    assert indptr.dtype == indices.dtype == np.int32
    assert np.array_equal(indptr, inner64.indptr) and np.array_equal(indices, inner64.indices)


def test_block_index_stays_wide_past_int32() -> None:
    """A block whose entries or columns pass 2**31 - 1 keeps int64 (never a wrapped
    index): a stand-in with the sizes of one, not its entries."""
    big = 2**31
    wide = SimpleNamespace(indptr=np.array([0, 2], dtype=np.int64),
                           indices=np.array([0, big], dtype=np.int64), shape=(1, big + 1))
    indptr, indices = kernels.kernel_index(wide)
    assert indptr is wide.indptr and indices is wide.indices
    many = SimpleNamespace(indptr=np.array([0, big], dtype=np.int64),
                           indices=np.array([0, 1], dtype=np.int32), shape=(1, 2))
    indptr, indices = kernels.kernel_index(many)
    assert indptr is many.indptr
    assert indices.dtype == np.int64 and indices.tolist() == [0, 1]


# ------------------------------------------------------------------ the narrow load
PROBE = r"""
import json, sys
from mitld_lp.solvers import numba_narrow
calls = []
real = numba_narrow.install
def install():
    calls.append(sys._getframe(1).f_globals["__name__"])
    return real()
numba_narrow.install = install
import importlib
for name in json.loads(sys.argv[1]):
    importlib.import_module(name)
print(json.dumps({"calls": calls, "installed": numba_narrow.installed()}))
"""


def test_every_compiled_module_puts_the_narrow_load_in_place() -> None:
    done = subprocess.run([sys.executable, "-c", PROBE, json.dumps(COMPILED_MODULES)],
                          cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert sorted(set(out["calls"])) == sorted(COMPILED_MODULES)
    assert out["installed"] is True


#: A graph kernel asked for first (as the analysis of a large product does): from the
#: disk cache (the second process), numba's linear algebra and typed containers are not
#: imported: the CPU target's whole registry was not loaded.
GRAPH_FIRST = r"""
import json, sys
import numpy as np, scipy.sparse as sp
from mitld_lp.solvers import compiled_graph, numba_narrow
inner = sp.csr_array(np.array([[0.0, 0.5, 0.5], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
alive, allowed, label = compiled_graph.end_components_among(
    inner.indptr, inner.indices, inner.data > 0, np.array([0, 1, 2, 3]), np.arange(3))
print(json.dumps({"alive": alive.tolist(), "label": label.tolist(),
                  "narrow": numba_narrow.installed(),
                  "whole": [m for m in ("numba.np.linalg", "numba.typed.typedlist")
                            if m in sys.modules]}))
"""


def test_a_graph_kernel_first_is_loaded_narrowly() -> None:
    runs = []
    for _ in range(2):  # the first may compile (a cold cache); the second loads
        done = subprocess.run([sys.executable, "-c", GRAPH_FIRST], cwd=ROOT, env=_env(),
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr[-2000:]
        runs.append(json.loads(done.stdout.strip().splitlines()[-1]))
    last = runs[-1]
    assert last["narrow"] is True and last["whole"] == []
    # states 0 -> {1, 2}, 1 -> 0, 2 -> 2: state 2 alone is an end component; 0 and 1
    # leave theirs with probability 1/2 from state 0 (no other choice), so not
    assert last["alive"] == [False, False, True]
    assert runs[0]["alive"] == last["alive"]
