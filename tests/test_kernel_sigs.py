"""Each compiled kernel is compiled for one signature a run (its entry point normalises
the index arrays it passes: int32 where the sizes fit, as
:func:`mitld_lp.util.arrays.index_dtype` decides), with the same answers to the bit; and
every module of compiled kernels puts numba's narrow cached load in place as it is
imported (:mod:`mitld_lp.util.numba_narrow`)."""

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
                    "mitld_lp.sensing.kernels", "mitld_lp.sensing.group_kernels",
                    "mitld_lp.sensing.fsum_kernels")
#: the modules whose kernels the kernel loader runs (numba imported on a miss only, by
#: kernel_loader.numba_module, which puts the narrow load in place then)
LAZY_MODULES = ("mitld_lp.solvers.compiled_kernels", "mitld_lp.solvers.level_kernels",
                "mitld_lp.solvers.compiled_graph", "mitld_lp.sensing.kernels",
                "mitld_lp.sensing.group_kernels", "mitld_lp.sensing.fsum_kernels")


@pytest.fixture(autouse=True)
def _numba_load(monkeypatch: pytest.MonkeyPatch) -> None:
    """These tests are about numba's load of its own cache: the kernel loader off."""
    from mitld_lp.util import kernel_loader
    monkeypatch.setattr(kernel_loader, "ENABLED", False)


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["MITLD_LP_KERNEL_LOADER"] = "0"  # numba's own load of its cache (kernel_loader)
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
    from mitld_lp.util import kernel_loader
    kernel_loader.ENABLED = False  # numba's dispatcher, its signatures (a module fixture)
    try:
        return _sweep_all(compiled_kernels)
    finally:
        kernel_loader.ENABLED = True


def _sweep_all(compiled_kernels) -> dict:
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
from mitld_lp.util import numba_narrow
calls = []
real = numba_narrow.install
def install():
    calls.append(sys._getframe(1).f_globals["__name__"])
    return real()
numba_narrow.install = install
import importlib
for name in json.loads(sys.argv[1]):
    importlib.import_module(name)
lazy_numba = "numba" in sys.modules  # the lazy modules are imported first
from mitld_lp.util import kernel_loader
kernel_loader.numba_module()  # what a kernel's miss calls
print(json.dumps({"calls": calls, "installed": numba_narrow.installed(),
                  "numba_at_import": lazy_numba}))
"""


def test_every_compiled_module_puts_the_narrow_load_in_place() -> None:
    for modules, numba_at_import in ((LAZY_MODULES, False), (COMPILED_MODULES, True)):
        done = subprocess.run([sys.executable, "-c", PROBE, json.dumps(modules)],
                              cwd=ROOT, env=_env(), capture_output=True, text=True,
                              timeout=300)
        assert done.returncode == 0, done.stderr[-2000:]
        out = json.loads(done.stdout.strip().splitlines()[-1])
        assert out["numba_at_import"] is numba_at_import
        want = {m for m in modules if m not in LAZY_MODULES} | {
            "mitld_lp.util.kernel_loader"}
        assert set(out["calls"]) == want
        assert out["installed"] is True


#: A graph kernel asked for first (as the analysis of a large product does): from the
#: disk cache (the second process), numba's linear algebra and typed containers are not
#: imported: the CPU target's whole registry was not loaded.
GRAPH_FIRST = r"""
import json, sys
import numpy as np, scipy.sparse as sp
from mitld_lp.solvers import compiled_graph
from mitld_lp.util import numba_narrow
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


# ------------------------------------------------------------------ the graph kernels
def _literal(sigs: list) -> list:
    """The signatures of ``sigs`` with an argument typed as a literal constant (each one
    compiled apart from the plain type's)."""
    return [sig for sig in sigs if any(isinstance(t, numba.types.Literal) for t in sig)]


def _random_choices(rng: np.random.Generator, n: int) -> tuple[sp.csr_array, np.ndarray]:
    """1-3 choices a state, 1-3 successors a choice, each 1/k."""
    rows, groups = [], [0]
    for _ in range(n):
        for _ in range(int(rng.integers(1, 4))):
            rows.append(sorted(set(rng.integers(0, n, int(rng.integers(1, 4))).tolist())))
        groups.append(len(rows))
    ptr = np.cumsum([0] + [len(r) for r in rows])
    data = np.concatenate([np.full(len(r), 1.0 / len(r)) for r in rows])
    matrix = sp.csr_array((data, np.concatenate(rows), ptr), shape=(len(rows), n))
    return matrix, np.array(groups, dtype=np.int64)


def _attractor(matrix: sp.csr_array, groups: np.ndarray, seeds: np.ndarray,
               every: bool) -> np.ndarray:
    """The least set holding ``seeds`` and each state with all (``every``) or one of its
    choices having an entry in it: iterated to the fixed point."""
    inside = seeds.copy()
    rows = [set(matrix.indices[matrix.indptr[c]:matrix.indptr[c + 1]].tolist())
            for c in range(matrix.shape[0])]
    grew = True
    while grew:
        grew = False
        for s in np.flatnonzero(~inside):
            hits = [any(inside[t] for t in rows[c]) for c in range(groups[s], groups[s + 1])]
            if (all if every else any)(hits):
                inside[s] = grew = True
    return inside


def test_graph_kernels_one_signature_and_fixed_point_answers() -> None:
    from mitld_lp.solvers import compiled_graph as cg

    rng = np.random.default_rng(7)
    for trial in range(12):
        n = int(rng.integers(2, 30))
        matrix, groups = _random_choices(rng, n)
        matrix = _with_index(matrix, np.int32)
        seeds = rng.random(n) < 0.2
        frozen = groups.copy()
        frozen.flags.writeable = False
        for every in (True, False):
            want = _attractor(matrix, groups, seeds, every)
            for rg in (groups, frozen):  # writable and read-only row groups
                got = cg.backward(matrix.indptr, matrix.indices, rg, seeds,
                                  np.zeros(matrix.shape[0], dtype=bool), every)
                assert np.array_equal(got, want), (trial, every)
        assert groups.flags.writeable  # the caller's array is left as it was
        # the components by the three entry points that reach components_and_levels
        label, _, _ = cg.state_levels(matrix.indptr, matrix.indices, groups,
                                      np.zeros((n, 1), dtype=bool), 10**9)
        ptr, succ = cg.state_graph(matrix.indptr, matrix.indices, groups, n)
        _, label2 = cg.strong_components(ptr, succ, False)
        assert np.array_equal(label, label2)
        cg.end_components_among(matrix.indptr, matrix.indices, matrix.data > 0, groups,
                                np.arange(n))
    sigs = list(cg._backward.signatures)
    assert sigs and all(not sig[2].mutable for sig in sigs)  # row groups read-only
    # a kernel called from another is compiled with it and not listed in this process
    # when that one is loaded from the cache: numba's index on disk lists them all
    stored = _cached_signatures(cg.components_and_levels)
    assert len(stored) == 1 and _literal(stored) == [], stored
    assert _literal(_cached_signatures(cg.strong_components)) == []


def _cached_signatures(kernel) -> list:
    """The signatures in ``kernel``'s index in numba's disk cache (every one compiled
    for its source as it is, by any process)."""
    return [key[0] for key in kernel._cache._cache_file._load_index()]


# ------------------------------------------------------------------ the sensing kernels
def test_pack_is_pack_words_with_one_signature_a_kernel() -> None:
    """The compiled packing a column at a time against
    :func:`mitld_lp.sensing.rows.pack_words` (NumPy), on 1-6 columns of small, wide
    (hash-like: kept whole) and constant values."""
    from mitld_lp.sensing import kernels as sk
    from mitld_lp.sensing.rows import pack_words

    rng = np.random.default_rng(11)
    top = np.iinfo(np.int64)
    for _ in range(60):
        n = int(rng.integers(1, 30))
        cols = []
        for _ in range(int(rng.integers(1, 7))):
            kind = int(rng.integers(0, 4))
            c = (rng.integers(-5, 5, n) if kind == 0 else rng.integers(0, 1 << 40, n)
                 if kind == 1 else rng.integers(top.min, top.max, n, dtype=np.int64)
                 if kind == 2 else np.full(n, int(rng.integers(-100, 100))))
            cols.append(np.ascontiguousarray(c, dtype=np.int64))
        words, span = sk.pack(tuple(cols))
        want, want_span = pack_words(tuple(cols))
        assert span == want_span and len(words) == len(want)
        for a, b in zip(words, want, strict=True):
            assert np.array_equal(a, b)
    for kernel in (sk._bounds, sk._fold, sk._shift):
        assert len(kernel.signatures) == 1


def test_dd_sums_of_integers_on_float64_same_bits() -> None:
    """Integer values summed by the float64 kernel: the sums as the int64 kernel's code
    gives them (run here as Python, exact integers) and as :func:`math.fsum` does."""
    import math

    from mitld_lp.sensing import kernels as sk

    rng = np.random.default_rng(5)
    count = np.array([3, 1, 6, 2, 4])
    starts = np.cumsum(count) - count
    for scale in (10, 10**9, 10**14):
        values = rng.integers(-scale, scale, int(count.sum()))
        high, low, size = sk.dd_sums(starts, count, values)
        exact = [math.fsum(values[a:a + k].tolist()) for a, k in zip(starts, count, strict=True)]
        assert high.tolist() == exact and not low.any() and not size.any()
        ref = sk._dd_sums.py_func(starts, count, values)
        assert all(np.array_equal(a, b) for a, b in zip((high, low, size), ref, strict=True))
    floats = rng.random(int(count.sum()))
    high, _, _ = sk.dd_sums(starts, count, floats)
    assert all(sig[2].dtype == numba.float64 for sig in sk._dd_sums.signatures)
