"""The analysis's arrays over a product's entries made a slice at a time, in the index type
(for :func:`~mitld_lp.solvers.analysis.analyse`): the analysis's memory peak on products
of many entries a state (the bus family) was these arrays, one or two of 8 bytes an
entry of the whole product.

* :func:`largest_inside`: the most entries a strongly connected component holds inside
  it (the gate of the compiled sweeps, ``analysis._sweeps_compiled``);
* :func:`candidates_pattern`: the pattern of the end components' candidates, with one
  extra absorbing state for every other (the NumPy rounds' sub-MDP, ``analysis.
  end_components``)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.quotient_rows import row_columns

__all__ = ["CHUNK_ENTRIES", "candidates_pattern", "compact", "largest_inside"]


CHUNK_ENTRIES = 1 << 16
"""Entries of the product read at a time by :func:`largest_inside` (a chunk's owner, its
columns' components and their running count: about 2 MB, whatever the product's size;
1 << 18 was 8 MB, 7 bytes an entry of QVBS csma 4-2 at the analysis's peak)."""


def largest_inside(m: sp.csr_array, row_groups: np.ndarray, comp: np.ndarray) -> int:
    """The most entries any strongly connected component ``comp`` holds inside it (an
    entry whose state and column lie in the same component), counted a run of states at a
    time (about :data:`CHUNK_ENTRIES` entries a run): no array an entry of the whole
    product (the owner and column components of every entry were the analysis's peak on
    the bus family, 25 bytes an entry)."""
    n = row_groups.shape[0] - 1
    starts = np.asarray(m.indptr[row_groups], dtype=np.int64)
    per_state = np.zeros(n, dtype=np.int64)  # each state's entries inside its component
    cuts = np.searchsorted(starts, np.arange(0, int(starts[-1]), CHUNK_ENTRIES),
                           side="right") - 1
    cuts = np.unique(np.concatenate([cuts, [n]]))
    for a, b in zip(cuts[:-1].tolist(), cuts[1:].tolist(), strict=True):
        lo, hi = int(starts[a]), int(starts[b])
        if hi == lo:
            continue
        owner = np.repeat(comp[a:b], np.diff(starts[a:b + 1]))
        run = np.concatenate([[0], np.cumsum(owner == comp[m.indices[lo:hi]])])
        per_state[a:b] = run[starts[a + 1:b + 1] - lo] - run[starts[a:b] - lo]
    return int(np.bincount(comp, weights=per_state).max(initial=0))


def candidates_pattern(m: sp.csr_array, choices: np.ndarray, cand: np.ndarray, n: int,
                       ) -> sp.csr_array:
    """The pattern of the ``choices`` of the states ``cand`` (sorted), each column the
    candidate's position, every other state one extra column ``cand.size`` (absorbing:
    one more row, a self-loop), its values 1 (no stored zero in ``m``: the caller
    checked).  Made in one array a kind, in the index type (4 bytes an entry where the
    sizes allow), its columns read a slice at a time: not the candidates' rows copied
    with their values, renumbered in int64 and stacked again (the analysis's peak on
    bus n64, 14 bytes an entry above its start)."""
    total = int(np.sum(m.indptr[choices + 1] - m.indptr[choices]))
    index = np.int32 if max(total + 1, cand.size + 1, choices.size + 2) < 2**31 else np.int64
    local = np.full(n, cand.size, dtype=index)  # the extra state: "elsewhere"
    local[cand] = np.arange(cand.size, dtype=index)
    indices = np.empty(total + 1, dtype=index)
    indices[:total] = local[row_columns(m, choices)]
    indices[total] = cand.size
    del local
    indptr = np.empty(choices.size + 2, dtype=index)
    indptr[0] = 0
    np.cumsum(m.indptr[choices + 1] - m.indptr[choices], out=indptr[1:-1])
    indptr[-1] = total + 1
    return sp.csr_array((np.broadcast_to(np.float64(1.0), (total + 1,)), indices, indptr),
                        shape=(choices.size + 1, cand.size + 1), copy=False)


def compact(matrix: sp.csr_array) -> None:
    """``matrix``'s entries in arrays of their own size where ``eliminate_zeros`` left
    them views of larger ones (it copies only below half)."""
    for name in ("data", "indices"):
        a = getattr(matrix, name)
        if a.base is not None and a.size < a.base.size:
            setattr(matrix, name, a.copy())
