"""A policy's chain factorised and solved compiled, in its strong components' order
(:mod:`mitld_lp.solvers.topo_kernels`), for the policy jump's rounds
(:func:`mitld_lp.solvers.policy_jump.chain_factor`).

SuperLU on the chain permuted to its components' order (``NATURAL``: no fill across
components) already avoids a minimum-degree ordering of the whole; what it still
costs on chains of thousands of components, nearly all single states, is its set-up
per call and the permutation of every right-hand side in and out (each policy
evaluation solves three times: once, then twice in its refinement).  The kernels lay
the states out once and walk the components downstream first, a single state by one
division, a component of more by a dense LU of its size (at most
:data:`~mitld_lp.solvers.policy_jump.TOPO_MAX_COMPONENT` states).  Used only where a
compiled kernel's load is paid already and both kernels are in the loader's cache, so
it never costs a compile or numba's import.  Its answers are those of a direct solve
up to rounding, as SuperLU's are, and every policy evaluation refines them twice in
extended precision after.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.util import kernel_loader

__all__ = ["COMPILED", "CompiledTopoLU", "KERNELS", "compile_kernels", "factor", "kernels"]

COMPILED = True
"""Whether :func:`factor` may use the compiled kernels (the tests turn it off to reach
SciPy's route)."""

KERNELS = ("topo_factor", "topo_solve")

MAX_COMPONENT = 4096
"""The largest strong component a chain :func:`factor` takes may have (its work row
and its elimination's scan are of that size; SciPy's route factorises in component
order only up to :data:`~mitld_lp.solvers.policy_jump.TOPO_MAX_COMPONENT`, 256).
QVBS ``consensus`` 4-4 ``disagree``: policies' chains of 8,302 states whose largest
component has 984-1,246 states, factorised whole by SuperLU in 9-11 ms."""

ROOM_PER_ENTRY = 4
"""The factors' first room: this many entries per entry of the chain (plus one per
state); past it, every entry the components could fill (at most :data:`MAX_ROOM`)."""

MAX_ROOM = 1 << 25
"""The most factor entries :func:`factor` makes room for (16 bytes each)."""

REFILL = 1024
"""A chain that fills past its first room is factorised again with all its components
could fill only where that is at most this many entries (16 KB) a state of the chain;
else by SciPy's route.  A 2,000-state component that fills densely (4e6 entries, 64 MB
for a 2,000-state chain) would otherwise hold many times the chain's own bytes for one
policy's factors (``tests/test_peak_mem.py::test_jump_holds_no_long_double_copy_of_the_block``);
consensus 4-4's 8,302-state chains with components of 984-1,246 states stay compiled."""

_KERNELS: list[Any] = []  # the kernel module if it is usable, None if not (once)


def kernels(force: bool = False) -> Any:
    """The kernel module, or ``None``: :data:`COMPILED` off, numba not installed, a
    kernel's load not paid in this process, or a kernel not in the loader's cache
    (looked up once a process).  ``force``: whatever the load and the cache (the
    tests; a cold cache compiles)."""
    if not COMPILED:
        return None
    if force or not _KERNELS:
        try:
            from mitld_lp.solvers import topo_kernels
        except ImportError:
            topo_kernels = None
        if force:
            return topo_kernels
        warm = topo_kernels is not None and all(
            kernel_loader.module_cached("mitld_lp.solvers.topo_kernels", k)
            for k in KERNELS)
        _KERNELS.append(topo_kernels if warm else None)
    if _KERNELS[0] is None or not kernel_loader.compiled_paid():
        return None
    return _KERNELS[0]


class CompiledTopoLU:
    """The factors :func:`factor` made; ``solve`` answers as SciPy's ``SuperLU`` does
    (``trans='N'`` only), ``rhs`` of one or more columns."""

    __slots__ = ("arrays", "run")

    def __init__(self, run: Any, arrays: tuple) -> None:
        self.run, self.arrays = run, arrays

    def solve(self, rhs: np.ndarray, trans: str = "N") -> np.ndarray:
        if trans != "N":
            raise ValueError("CompiledTopoLU.solve: only trans='N' (the chain's own solve)")
        rhs = np.asarray(rhs, dtype=np.float64)
        flat = rhs.ndim == 1
        b = np.ascontiguousarray(rhs.reshape(rhs.shape[0], -1))
        x = np.empty_like(b)
        self.run.topo_solve(*self.arrays, b, x, np.empty_like(b))
        return x[:, 0] if flat else x


def factor(chain: sp.csr_array, label: np.ndarray, n_comp: int,
           force: bool = False) -> CompiledTopoLU | None:
    """The compiled factors of ``I - chain`` in the order of its strong components
    ``label`` (``n_comp`` of them, SciPy's labels: every move between two goes the same
    way along them), or ``None`` where the kernels are not to be used (:func:`kernels`)
    or refuse (the labels do not order the components, or a pivot is not positive):
    the caller factorises by SciPy then."""
    run = kernels(force)
    if run is None:
        return None
    k = chain.shape[0]
    sizes = np.bincount(label, minlength=n_comp)
    largest = int(sizes.max()) if n_comp else 0
    indptr = chain.indptr.astype(np.int64, copy=False)
    indices = chain.indices.astype(np.int64, copy=False)
    data = np.asarray(chain.data, dtype=np.float64)
    # room for the factors: a few times the chain's entries first (the components are
    # rings that fill little), every entry a component could fill (its square less its
    # pivots) if that is short
    full = int(np.dot(sizes.astype(np.int64), sizes - 1))
    room = min(full, ROOM_PER_ENTRY * chain.nnz + k)
    # the labels' two directions, SciPy's first (its labels number the components
    # downstream first); the stable order of the labels, a radix sort on 16-bit keys
    for flip in (False, True):
        key = (n_comp - 1 - label) if flip else label
        order = np.argsort(key.astype(np.uint16) if n_comp <= 1 << 16 else key,
                           kind="stable").astype(np.int64)
        at = np.empty(k, dtype=np.int64)
        at[order] = np.arange(k, dtype=np.int64)
        bounds = np.zeros(n_comp + 1, dtype=np.int64)
        np.cumsum(sizes[::-1] if flip else sizes, out=bounds[1:])
        start = np.empty(3 * k, dtype=np.int64)
        diag = np.empty(k)
        while True:
            fidx = np.empty(room, dtype=np.int64)
            fval = np.empty(room)
            status = int(run.topo_factor(order, bounds, at, indptr, indices, data, start,
                                         diag, fidx, fval, np.zeros(largest),
                                         np.zeros(largest, dtype=np.bool_)))
            if status != -3 or room >= full or full > min(MAX_ROOM, REFILL * k):
                break
            room = full  # filled past the first room: once more with all of it
        if status == -1:
            used = int(start[-1]) if k else 0
            return CompiledTopoLU(run, (order, bounds, at, indptr, indices, data, start,
                                        diag, fidx[:used].copy(), fval[:used].copy()))
        if status != -2:  # a pivot not positive, or too much fill: SciPy's then
            return None
    return None


def compile_kernels() -> bool:
    """Compile both kernels into the loader's cache (``mitld-lp warm``) by factorising
    and solving a small chain (a ring of two and a state below it) with the argument
    types :func:`factor` passes; ``False`` if they were cached already or numba is not
    installed (nothing to do)."""
    if not COMPILED or all(kernel_loader.module_cached("mitld_lp.solvers.topo_kernels",
                                                       k) for k in KERNELS):
        return False
    if kernels(force=True) is None:
        return False
    from scipy.sparse import csgraph

    chain = sp.csr_array(np.array([[0.25, 0.5, 0.0], [0.5, 0.0, 0.25], [0.0, 0.0, 0.5]]))
    n_comp, label = csgraph.connected_components(chain, directed=True, connection="strong")
    lu = factor(chain, label, n_comp, force=True)
    if lu is not None:
        lu.solve(np.ones((3, 2)))
    _KERNELS.clear()  # looked up again: warm now
    return True
