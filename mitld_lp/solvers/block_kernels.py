"""A block of the quotient (:class:`~mitld_lp.solvers.topological.Block`) cut out of
its rows in one compiled pass (numba, through :mod:`mitld_lp.util.kernel_loader`;
imported only by :func:`mitld_lp.solvers.topological.Block.of`, once the compiled
kernels' load is paid and this kernel's machine code is cached: ``mitld-lp warm``
compiles it, so a solve never compiles it).

``Block.of`` with NumPy gathers the block's choices, copies their rows (SciPy's row
gather), maps every entry's column to its place in the block and splits the rows
twice (the entries inside, those outside), each split a cumulative sum over every
entry: 28 ms on QVBS ``zeroconf`` 1000-4-false's block of 163,751 states (368k
entries), which the iteration cuts twice (once in the quotient's order, once in its
sweep order) and the LP stage once more.  The kernel reads each chosen row once and
writes each entry to the one matrix it goes to, in its stored order: the same
entries, columns and row pointers, so every row's product sums as before, to the bit.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mitld_lp.util import kernel_loader

numba = kernel_loader.lazy_numba(globals())

__all__ = ["KERNEL", "split_rows", "warm_up"]

KERNEL = "split_rows_kernel"


@numba.njit(cache=True, nogil=True)
def split_rows_kernel(row_groups, indptr, indices, data, states, at):  # pragma: no cover
    """The choices of ``states`` (each state's rows ``row_groups[s]`` to
    ``row_groups[s + 1] - 1``, in order) and their entries split by ``at`` (a column's
    place in the block, -1 outside): the inner entries (columns renamed to their place)
    and the outer ones (columns kept), each with its row pointers, in the index type of
    ``indices``; and each state's first choice among the block's."""
    k = states.shape[0]
    m = 0
    for i in range(k):
        s = states[i]
        m += row_groups[s + 1] - row_groups[s]
    choices = np.empty(m, dtype=np.int64)
    starts = np.empty(k, dtype=np.int64)
    in_ptr = np.zeros(m + 1, dtype=indptr.dtype)
    out_ptr = np.zeros(m + 1, dtype=indptr.dtype)
    c = 0
    n_in = 0
    n_out = 0
    for i in range(k):
        s = states[i]
        starts[i] = c
        for r in range(row_groups[s], row_groups[s + 1]):
            choices[c] = r
            for e in range(indptr[r], indptr[r + 1]):
                if at[indices[e]] >= 0:
                    n_in += 1
                else:
                    n_out += 1
            c += 1
            in_ptr[c] = n_in
            out_ptr[c] = n_out
    in_idx = np.empty(n_in, dtype=indices.dtype)
    in_val = np.empty(n_in, dtype=np.float64)
    out_idx = np.empty(n_out, dtype=indices.dtype)
    out_val = np.empty(n_out, dtype=np.float64)
    a = 0
    b = 0
    for c in range(m):
        r = choices[c]
        for e in range(indptr[r], indptr[r + 1]):
            t = indices[e]
            p = at[t]
            if p >= 0:
                in_idx[a] = p
                in_val[a] = data[e]
                a += 1
            else:
                out_idx[b] = t
                out_val[b] = data[e]
                b += 1
    return choices, starts, in_ptr, in_idx, in_val, out_ptr, out_idx, out_val


def split_rows(row_groups: np.ndarray, matrix: Any, states: np.ndarray,
               n_states: int) -> tuple[np.ndarray, ...]:
    """:func:`split_rows_kernel` on a CSR ``matrix`` (rows: choices) with the states'
    ``row_groups``: the kernel's arrays, the index arrays in one width (int32 where
    both of ``matrix``'s are, else int64: SciPy's row gather keeps that width)."""
    indptr, indices = np.asarray(matrix.indptr), np.asarray(matrix.indices)
    index = np.int32 if indptr.dtype == np.int32 and indices.dtype == np.int32 else np.int64
    indptr = np.asarray(indptr, dtype=index)
    indices = np.asarray(indices, dtype=index)
    states = np.asarray(states, dtype=np.int64)
    at = np.full(n_states, -1, dtype=index)
    at[states] = np.arange(states.size, dtype=index)
    return split_rows_kernel(np.asarray(row_groups, dtype=np.int64), indptr, indices,
                             np.asarray(matrix.data, dtype=np.float64), states, at)


def warm_up() -> None:
    """Compile (or load) the kernel for both index widths a quotient's matrix has and
    for writable and read-only row groups (a solve passes the model's, read-only: the
    first benchmark run after ``warm`` compiled that signature), on a two-state model:
    ``mitld-lp warm``'s part for the blocks' cut."""
    import scipy.sparse as sp

    for writeable in (True, False):
        groups = np.array([0, 2, 3], dtype=np.int64)
        groups.flags.writeable = writeable
        for index in (np.int32, np.int64):
            m = sp.csr_array((np.array([0.5, 0.5, 1.0, 1.0]),
                              np.array([0, 1, 1, 0], dtype=index),
                              np.array([0, 2, 3, 4], dtype=index)), shape=(3, 2))
            got = split_rows(groups, m, np.array([0]), 2)
            assert got[0].tolist() == [0, 1] and got[3].tolist() == [0], got
