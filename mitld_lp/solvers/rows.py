"""Rows of a CSR matrix read straight from its arrays: the entries of chosen rows
(:func:`row_entries`), their products with a vector (:func:`rows_dot`) and the
concatenated index ranges both are made of (:func:`gather_ranges`).  No matrix is made
for the rows (scipy's row indexing costs ~0.2 ms a call).  This module imports no solver
module: :mod:`~mitld_lp.solvers.graph` and the solvers build on it."""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from mitld_lp.util.sparsetools import sparsetools

__all__ = ["CSRRows", "gather_ranges", "off_diagonal_entries", "row_columns", "row_entries",
           "rows_dot"]

class CSRRows(NamedTuple):
    """A CSR matrix's three arrays, as the functions here read them (``indptr``,
    ``indices``, ``data``): held in place of the matrix where a holder must not keep the
    matrix object alive (:class:`~mitld_lp.solvers.topological.SingleLevels`, kept
    while a weak reference to the matrix lives)."""

    indptr: np.ndarray
    indices: np.ndarray
    data: np.ndarray


#: rows read at a time by :func:`off_diagonal_entries` (its temporaries: a batch's,
#: some 40 bytes an entry; 2**16 rows of two entries were 20 bytes a transition of
#: QVBS ``zeroconf_dl`` 1000-1-30 at the LP's set-up)
BATCH = 1 << 14


#: entries from which :func:`gather_ranges` sums in its output (below, the repeated
#: offset and the ``arange``: 0.08 against 0.11 ms at 65k entries, 10 against 16 us at
#: 600; a deadline's levels call it by the thousand)
IN_PLACE_FROM = 1 << 17


def gather_ranges(starts: np.ndarray, stops: np.ndarray) -> np.ndarray:
    """The concatenation of ``arange(starts[i], stops[i])`` over ``i``, vectorised.

    Made in its output alone: ones, each range's first entry its step from the previous
    range's last, summed in place (not a repeated offset and an ``arange`` of every
    entry beside the output: three int64 arrays of the entries at once)."""
    starts = np.asarray(starts, dtype=np.int64)
    counts = np.asarray(stops, dtype=np.int64) - starts
    if counts.size and int(counts.min()) < 0:
        raise ValueError("gather_ranges: a range ends before it starts")
    total = int(counts.sum())
    if total < IN_PLACE_FROM:  # the same entries; NumPy's two calls are quicker here
        offsets = np.repeat(starts - (np.cumsum(counts) - counts), counts)
        return offsets + np.arange(total, dtype=np.int64)
    out = np.ones(total, dtype=np.int64)
    full = counts > 0
    if total:
        first, size = starts[full], counts[full]
        at = np.cumsum(size)
        at -= size  # each range's first entry in the output
        out[0] = first[0]
        out[at[1:]] = first[1:] - first[:-1] - size[:-1] + 1
        np.cumsum(out, out=out)
    return out


def row_entries(matrix: sp.csr_array, rows: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The stored entries of ``matrix``'s ``rows`` as ``(local row, column, value)``
    arrays (``local row``: the position in ``rows``), read straight from its CSR arrays:
    no matrix is made for them (scipy's row indexing costs ~0.2 ms a call, which on a
    product of thousands of levels -- a deadline clock -- was most of the solve)."""
    rows = np.asarray(rows, dtype=np.int64)
    ptr = matrix.indptr
    local = np.repeat(np.arange(rows.size, dtype=np.int64), ptr[rows + 1] - ptr[rows])
    return (local, *row_columns(matrix, rows))


def row_columns(matrix: sp.csr_array, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The columns and values of ``matrix``'s ``rows``, row after row in their stored
    order (:func:`row_entries` without the local rows).  Copied by SciPy's compiled row
    gather (``csr_row_index``, what ``matrix[rows]`` calls: one pass) where the matrix's
    index arrays share a type, not through an index array of every entry and two
    fancy-indexed copies: the same entries in the same order either way."""
    rows = np.asarray(rows, dtype=np.int64)
    ptr, idx = matrix.indptr, matrix.indices
    lo, hi = ptr[rows], ptr[rows + 1]
    # (``ptr[rows + 1]`` refused a row past the last; a negative row, which NumPy's
    # indexing would wrap, is left to NumPy's gathers, not to the compiled loop)
    if (sparsetools is None or ptr.dtype != idx.dtype or idx.dtype not in (np.int32, np.int64)
            or (rows.size and int(rows.min()) < 0)):
        entries = gather_ranges(lo, hi)
        return idx[entries], matrix.data[entries]
    total = int((hi - lo).sum())
    cols = np.empty(total, dtype=idx.dtype)
    vals = np.empty(total, dtype=matrix.data.dtype)
    sparsetools.csr_row_index(rows.size, rows.astype(idx.dtype, copy=False), ptr, idx,
                      matrix.data, cols, vals)
    return cols, vals


def off_diagonal_entries(matrix: sp.csr_array, rows: np.ndarray, row_state: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`row_entries` of ``rows`` without each row's entry in column
    ``row_state[i]`` (its self-loop), in the same order, read :data:`BATCH` rows at a
    time: the whole gather (an int64 index and an int64 local row per entry, then the
    filtered copies) was the solve stage's memory peak on QVBS ``zeroconf_dl`` and
    ``csma``.  Each batch's kept entries are written straight into the three outputs,
    made once for the rows' stored entries and shrunk in place to the kept ones at the
    end (the tail never written: no page of it is touched), so the peak is the result
    plus one batch, not the batches' parts and their concatenation.  ``local`` is
    int32 where the rows' count allows (:func:`~mitld_lp.util.arrays.index_dtype`)."""
    from mitld_lp.util.arrays import index_dtype

    rows = np.asarray(rows, dtype=np.int64)
    row_state = np.asarray(row_state)
    stored = int((matrix.indptr[rows + 1] - matrix.indptr[rows]).sum()) if rows.size else 0
    local_out = np.empty(stored, dtype=index_dtype(rows.size))
    cols_out = np.empty(stored, dtype=matrix.indices.dtype)
    vals_out = np.empty(stored, dtype=matrix.data.dtype)
    at = 0
    for a in range(0, rows.size, BATCH):
        local, cols, vals = row_entries(matrix, rows[a:a + BATCH])
        keep = cols != row_state[a:a + BATCH][local]
        n = int(np.count_nonzero(keep))
        np.add(local[keep], a, out=local_out[at:at + n], casting="unsafe")
        np.compress(keep, cols, out=cols_out[at:at + n])
        np.compress(keep, vals, out=vals_out[at:at + n])
        at += n
        del local, cols, vals, keep
    for out in (local_out, cols_out, vals_out):  # the kept entries only (in place:
        out.resize(at, refcheck=False)  # no view of them exists yet)
    return local_out, cols_out, vals_out


def rows_dot(matrix: sp.csr_array, rows: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``matrix[rows] @ x`` (``x``: a vector, or a column per right-hand side) from the
    CSR arrays (:func:`row_entries`), each row summed in its entries' order."""
    local, cols, vals = row_entries(matrix, rows)
    n = np.asarray(rows).shape[0]
    if x.ndim == 1:
        return np.bincount(local, weights=vals * x[cols], minlength=n)
    terms = vals[:, None] * x[cols]
    return np.column_stack([np.bincount(local, weights=terms[:, j], minlength=n)
                            for j in range(x.shape[1])]).reshape(n, x.shape[1])


#: Entries read at a time by :func:`first_choice_without` (its temporaries some 40
#: bytes an entry: 0.3 MB, where a whole slice of a minimum's prob-0 states on QVBS
#: consensus 4-4 raised the LP stage's traced peak by 10 bytes a transition)
ENTRY_CHUNK = 1 << 13


def first_choice_without(groups: np.ndarray, matrix: sp.csr_array, states: np.ndarray,
                         bad: Callable[[np.ndarray], np.ndarray],
                         allowed: Callable[[np.ndarray], np.ndarray] | None = None,
                         ) -> np.ndarray:
    """Per state of ``states`` (increasing; ``groups`` its choices, rows of
    ``matrix``), int64: its first choice that ``allowed`` passes (every choice where
    None) and none of whose stored entries is ``bad`` (``bad(entries)``: a bool per
    entry, by its position in ``matrix``'s arrays), else its first choice.  The states'
    choices and entries gathered :data:`ENTRY_CHUNK` entries at a time (a state whole),
    each choice's bad entries counted by a running sum (a choice with no entry has
    none), the least good choice of a state by a segmented minimum."""
    groups, ptr = np.asarray(groups), np.asarray(matrix.indptr)
    out = groups[states].astype(np.int64)
    if states.size == 0:
        return out
    size = (ptr[groups[states + 1]] - ptr[groups[states]]).astype(np.int64)
    cum = np.cumsum(size)
    big = np.iinfo(np.int64).max
    start = 0
    while start < states.size:
        stop = max(start + 1, int(np.searchsorted(cum, cum[start] - size[start] + ENTRY_CHUNK,
                                                  side="right")))
        part = states[start:stop]
        first, last = out[start:stop], groups[part + 1].astype(np.int64)
        choices = gather_ranges(first, last)
        lo = ptr[choices].astype(np.int64)
        n = ptr[choices + 1].astype(np.int64) - lo
        flagged = bad(gather_ranges(lo, lo + n))
        count = np.zeros(flagged.size + 1, dtype=np.int64)
        np.cumsum(flagged, out=count[1:])
        end = np.cumsum(n)
        good = count[end] == count[end - n]
        if allowed is not None:
            good &= allowed(choices)
        best = np.minimum.reduceat(np.where(good, choices, big),
                                   np.cumsum(last - first) - (last - first))
        np.copyto(best, first, where=best == big)
        out[start:stop] = best
        start = stop
    return out
