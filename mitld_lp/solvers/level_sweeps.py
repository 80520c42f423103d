r"""Walks of :class:`~mitld_lp.solvers.topological.SingleLevels` done by ONE call of
SciPy's compiled sparse product over many levels, with the same bits (issue 45).

The NumPy walks (:mod:`~mitld_lp.solvers.level_batches`) pay some 20-40 microseconds
a level in NumPy calls, over the thousand levels and more of a product with a deadline
clock.  Where a walk is *linear* over a stretch of levels -- no maximum to take, no
division that is not by exactly 1, no clip that can bite -- its levels need no Python
between them: SciPy's compiled products read and write one array, so a product whose
input and output are the same vector (the stretch's states laid out in the order the
walk visits them, then a copy of the whole vector for the states outside) reads each
state's value after the rows before it have written it.  That is the walk itself, the
same multiplications and additions in the same order, so the same bits:

* :func:`flow`, the LP's policy flow, a group of levels a call (the walk's groups),
  where the policy is deterministic (each choice's weight exactly 0 or 1) and no chosen
  choice of a single state keeps a self-loop (so the walk's divisor is exactly 1):
  ``csc_matvec``, a column a state (its chosen choices' entries in their order),
  ``x[t] += P(c, t) x[s]`` in the walk's order (levels downstream from the top, a
  level's states and their choices in order).  A choice of weight 0 adds
  ``0 * x[s] = +0.0`` in the walk:
  nothing to a sum of non-negative terms.

Where the walk is not linear (a maximum, a randomised policy, a self-loop kept), the
level walks run.  The set-up (the walk's order, the chosen entries gathered, the
columns relabelled) is some fifteen passes over the states and entries, so the sweep
pays only on thin levels (:data:`THIN`).

Measured and left out (2026-11-30, QVBS deadline products): the same sweep for the
iteration's bounds and the LP's values over runs of single-choice levels (each state's
reward an entry of weight 1, the clip checked afterwards; the same bits) did not pay:
``firewire_dl`` 3-600's runs of 438 such levels are wide (60,530 states over 157 levels
in the longest), so their walk's calls are a small part of what it costs, and the set-up
took what the calls saved (bounds 24.5 -> 24.4 ms; 36-400 24.0 -> 25.7 ms).  SuperLU's
triangular solve of those runs (``gstrs``, 20 ns an entry, not the same bits) was slower
still with its set-up.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mitld_lp.solvers.rows import gather_ranges, row_columns
from mitld_lp.util.sparsetools import sparsetools

__all__ = ["flow"]

Run = tuple[int, int, int, int, int, int]

THIN = 256
"""At most this many single states a level on average for :func:`flow` to sweep: its
set-up costs about fifteen passes over the walk's states and entries, the walk about
twenty NumPy calls a level.  Measured (CPU ms, best of 9, the flow walk alone): QVBS
``zeroconf_dl`` 1000-1-30 (79 states a level) 26.0 -> 14.7, ``firewire_dl`` 3-600 (151)
15.7 -> 10.4, ``firewire_dl`` 36-400 (227) 13.8 -> 12.1; ``wlan_dl`` 0-80 (321) 8.1 ->
8.6 (swept whole, not by groups)."""


_IN_PLACE: bool | None = None


def _in_place() -> bool:
    """Whether SciPy's ``csc_matvec`` with one array as input and output reads a
    column's input after the columns before it have written it, as the sweep needs:
    probed once a process on a three-state chain (``1 -> 0.5 -> 0.25``), since a private
    routine's loop order is not a promise; if a SciPy reads its input otherwise, the
    level walks run."""
    global _IN_PLACE
    if _IN_PLACE is None:
        vec = np.array([1.0, 0.0, 0.0])
        ptr = np.array([0, 1, 2, 2], dtype=np.int32)
        sparsetools.csc_matvec(3, 3, ptr, np.array([1, 2], dtype=np.int32), np.array([0.5, 0.5]),
                       vec, vec)
        _IN_PLACE = vec.tolist() == [1.0, 0.5, 0.25]
    return _IN_PLACE


def _slots(n: int, inner: np.ndarray, cols: np.ndarray, index: np.dtype) -> np.ndarray:
    """The sweep's vector: ``inner`` (quotient states, in the sweep's order) at
    positions ``0..m-1``, then a copy of the whole vector (state ``t`` at ``m + t``).
    Returns each of ``cols``' position (in ``index``, the pointers' type): its slot in
    ``inner`` if it has one, else its place in the copy."""
    m = inner.size
    at = np.arange(m, m + n, dtype=index)
    at[inner] = np.arange(m, dtype=index)
    return at[cols]


def flow(sl: Any, groups: list[list[Run]], self_loop: np.ndarray, weights: np.ndarray,
         x: np.ndarray) -> bool:
    """:func:`~mitld_lp.solvers.level_batches.flow` over ``groups`` (consecutive groups
    of runs, in level order; walked the last group first) by one compiled product a
    group, if the walk is linear there (module docs): returns whether it was done (else
    ``x`` is untouched and the caller walks).  A group at a time, as the walk gathers
    (``level_batches.GROUP_ENTRIES``): the sweep's arrays are a group's, not the walk's."""
    if sparsetools is None or sl.ptr is None or not groups or x.dtype != np.float64 \
            or not x.flags.c_contiguous or not _in_place():
        return False
    first, last = groups[0][0], groups[-1][-1]
    if last[1] - first[0] > THIN * sum(len(g) for g in groups) \
            or last[1] - first[0] + x.shape[0] >= np.iinfo(sl.ptr.dtype).max:
        return False
    ch = sl.choices[first[2]:last[3]]
    w = weights[ch]
    one = w == 1.0
    if not (one | (w == 0.0)).all() or (self_loop[ch[one]] != 0.0).any():
        return False
    del ch, w
    for group in reversed(groups):  # upstream first
        _sweep(sl, group, one[group[0][2] - first[2]:group[-1][3] - first[2]], x)
    return True


def _sweep(sl: Any, runs: list[Run], one: np.ndarray, x: np.ndarray) -> None:
    """:func:`flow` on one group of runs (``one``: its choices of weight 1)."""
    ca0 = runs[0][2]
    back = runs[::-1]  # the walk's order: the top level first, in each its states
    a = np.array([r[0] for r in back], dtype=np.int64)
    z = np.array([r[1] for r in back], dtype=np.int64)
    seq = gather_ranges(a, z)  # positions in sl.states, in the walk's order
    counts = sl.state_choice[seq + 1] - sl.state_choice[seq]  # per state, its choices
    chosen = gather_ranges(np.array([r[2] for r in back], dtype=np.int64),
                           np.array([r[3] for r in back], dtype=np.int64))
    # per state its chosen choices' entries (a choice of weight 0 sends nothing)
    size = np.where(one[chosen - ca0], sl.ptr[chosen + 1] - sl.ptr[chosen], 0)
    chosen = chosen[size > 0]
    ptr = np.zeros(seq.size + 1, dtype=sl.ptr.dtype)
    np.cumsum(size, out=size)
    ptr[1:] = size[np.cumsum(counts) - 1]  # entries up to each state's last choice
    del size, counts
    cols, vals = row_columns(_Rows(sl.ptr, sl.cols, sl.vals), chosen)
    del chosen
    states = sl.states[seq]
    del seq
    rows = _slots(x.shape[0], states, cols, sl.ptr.dtype)
    del cols
    vec = np.concatenate([x[states], x])
    # a column a state: vec[t] += P(c, t) vec[s], the state's value read when its column
    # comes (after every column above it has added to it)
    sparsetools.csc_matvec(vec.size, states.size, ptr, rows, vals, vec, vec)
    x[:] = vec[states.size:]
    x[states] = vec[:states.size]


class _Rows:
    """A CSR's three arrays as :func:`~mitld_lp.solvers.rows.row_columns` reads them."""

    __slots__ = ("indptr", "indices", "data")

    def __init__(self, indptr: np.ndarray, indices: np.ndarray, data: np.ndarray) -> None:
        self.indptr, self.indices, self.data = indptr, indices, data
