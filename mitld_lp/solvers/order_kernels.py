"""The compiled sweeps' value order and the block renumbered in it, each in one compiled
pass (numba, through :mod:`mitld_lp.util.kernel_loader`; imported only by
:mod:`mitld_lp.solvers.sweep_order` once the compiled kernels' load is paid and these
kernels' machine code is cached: ``mitld-lp warm`` compiles their signatures, listed in
:data:`mitld_lp.util.warm_kernels.SIGNATURES`, so a solve never compiles them).

NumPy's route (:func:`~mitld_lp.solvers.sweep_order.value_order`,
:func:`~mitld_lp.solvers.sweep_order.for_sweeps`) transposes the block's moves with
SciPy, runs SciPy's breadth-first search twice and sorts the states by distance, then
gathers the rows with SciPy's row gather and renames every column: 0.14-0.18 s on QVBS
``zeroconf`` 1000-6-false's block of 550,097 states (iter-85).  Here the distances come
from a queue over the moves reversed (a counting sort of the entries by column), the
states at one distance in the default order (the last first) by a counting sort by
distance read from the last state down, and the rows are copied in the new order with
their columns renamed, each row's entries in their stored order: the same permutation,
and the same renumbered block to the bit and in the same types.
"""

from __future__ import annotations

import numpy as np

from mitld_lp.util import kernel_loader

numba = kernel_loader.lazy_numba(globals())

__all__ = ["KERNELS", "reach_order", "renumber", "renumber_kernel", "value_order_kernel",
           "value_order_of"]

KERNELS = ("value_order_kernel", "renumber_kernel")
"""The kernels a solve calls (each a cache file of its own: :func:`reach_order` is
compiled into its caller, and has none)."""


@numba.njit(cache=True, nogil=True)
def reach_order(back_ptr, back_idx, seeds, seen, order, k):  # pragma: no cover
    """Append to ``order`` (from place ``k``) the states not ``seen`` from which a move
    inside the block reaches one of ``seeds`` (a seed at distance 0), by that distance
    and at one distance the last state first; mark them seen; the new ``k``."""
    n = seen.shape[0]
    dist = np.full(n, -1, dtype=np.int32)  # a block's states fit 31 bits: half the
    queue = np.empty(n, dtype=np.int32)  # memory traffic of int64 on a random walk
    tail = 0
    for s in seeds:
        if dist[s] < 0:
            dist[s] = 0
            queue[tail] = s
            tail += 1
    head = 0
    while head < tail:
        t = queue[head]
        head += 1
        d = dist[t] + 1
        for e in range(back_ptr[t], back_ptr[t + 1]):
            s = back_idx[e]
            if dist[s] < 0:
                dist[s] = d
                queue[tail] = s
                tail += 1
    depth = 0
    for i in range(tail):
        depth = max(depth, dist[queue[i]])
    at = np.zeros(depth + 2, dtype=np.int64)
    for s in range(n):
        if dist[s] >= 0 and not seen[s]:
            at[dist[s] + 1] += 1
    at[0] = k
    for d in range(1, depth + 2):
        at[d] += at[d - 1]
    for s in range(n - 1, -1, -1):
        if dist[s] >= 0 and not seen[s]:
            order[at[dist[s]]] = s
            at[dist[s]] += 1
            seen[s] = True
    return at[depth + 1]


@numba.njit(cache=True, nogil=True)
def value_order_kernel(groups, indptr, indices, to_target, out_ptr):  # pragma: no cover
    """:func:`~mitld_lp.solvers.sweep_order.value_order` of the block whose row groups
    are ``groups`` (int64), moves inside it the CSR ``indptr``/``indices`` (a row a
    choice), target probabilities ``to_target`` and moves out of it the row pointers
    ``out_ptr``: by distance to a state with a choice that reaches the target, then by
    distance to a state with an exit, then the rest, the last state first at each."""
    n = groups.shape[0] - 1
    target = np.zeros(n, dtype=np.bool_)
    leaving = np.zeros(n, dtype=np.bool_)
    n_target = 0
    n_leaving = 0
    count = np.zeros(n + 1, dtype=np.int64)  # the moves into each state, then starts
    for s in range(n):
        for c in range(groups[s], groups[s + 1]):
            if to_target[c] > 0 and not target[s]:
                target[s] = True
                n_target += 1
            if out_ptr[c + 1] > out_ptr[c] and not leaving[s]:
                leaving[s] = True
                n_leaving += 1
            for e in range(indptr[c], indptr[c + 1]):
                count[indices[e] + 1] += 1
    for t in range(n):
        count[t + 1] += count[t]
    back_idx = np.empty(count[n], dtype=np.int32)
    fill = count[:n].copy()
    for s in range(n):
        for e in range(indptr[groups[s]], indptr[groups[s + 1]]):
            t = indices[e]
            back_idx[fill[t]] = s
            fill[t] += 1
    seen = np.zeros(n, dtype=np.bool_)
    order = np.empty(n, dtype=np.int64)
    k = 0
    if n_target > 0:
        k = reach_order(count, back_idx, np.flatnonzero(target), seen, order, k)
    if n_leaving > 0 and k < n:
        k = reach_order(count, back_idx, np.flatnonzero(leaving), seen, order, k)
    for s in range(n - 1, -1, -1):
        if not seen[s]:
            order[k] = s
            k += 1
    return order


@numba.njit(cache=True, nogil=True)
def renumber_kernel(groups, order, indptr, indices, data, picked_like):  # pragma: no cover
    """The block of row groups ``groups`` and moves inside it ``indptr``/``indices``/
    ``data`` renumbered in ``order`` (a permutation of its states: every row is
    written once, at its new place): the old places of the new choices (in the type of
    ``picked_like``), each state's first choice (int64), and the rows taken in that
    order with their columns renamed to the new places (each row's entries in their
    stored order, the index types kept)."""
    n = order.shape[0]
    place = np.empty(n, dtype=indices.dtype)
    for i in range(n):
        place[order[i]] = i
    m = groups[n]
    picked = np.empty(m, dtype=picked_like.dtype)
    starts = np.empty(n, dtype=np.int64)
    new_ptr = np.empty(m + 1, dtype=indptr.dtype)
    c = 0
    total = 0
    new_ptr[0] = 0
    for i in range(n):
        s = order[i]
        starts[i] = c
        for r in range(groups[s], groups[s + 1]):
            picked[c] = r
            total += indptr[r + 1] - indptr[r]
            c += 1
            new_ptr[c] = total
    new_idx = np.empty(total, dtype=indices.dtype)
    new_val = np.empty(total, dtype=data.dtype)
    # the rows read in their stored order and each written to its new place: read in
    # the new order they are scattered (QVBS zeroconf 1000-6-false's block of 550,097
    # states, 1.25 million entries: 44 against 31 ms)
    for s in range(n):
        c = starts[place[s]]
        for r in range(groups[s], groups[s + 1]):
            a = new_ptr[c]
            for e in range(indptr[r], indptr[r + 1]):
                new_idx[a] = place[indices[e]]
                new_val[a] = data[e]
                a += 1
            c += 1
    return picked, starts, new_ptr, new_idx, new_val


def value_order_of(groups: np.ndarray, inner, to_target: np.ndarray,
                   outer_ptr: np.ndarray) -> np.ndarray:
    """:func:`value_order_kernel` on a block's arrays (``inner``: its CSR moves inside)."""
    return value_order_kernel(np.ascontiguousarray(groups, dtype=np.int64),
                              np.ascontiguousarray(inner.indptr),
                              np.ascontiguousarray(inner.indices),
                              np.ascontiguousarray(to_target, dtype=np.float64),
                              np.ascontiguousarray(outer_ptr))


def renumber(groups: np.ndarray, order: np.ndarray, inner,
             picked_type: type) -> tuple[np.ndarray, ...]:
    """:func:`renumber_kernel` on a block's arrays, the choices' old places in
    ``picked_type``."""
    return renumber_kernel(np.ascontiguousarray(groups, dtype=np.int64),
                           np.ascontiguousarray(order, dtype=np.int64),
                           np.ascontiguousarray(inner.indptr),
                           np.ascontiguousarray(inner.indices),
                           np.ascontiguousarray(inner.data),
                           np.empty(0, dtype=picked_type))
