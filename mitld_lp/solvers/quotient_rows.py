"""The quotient's rows read from the product a slice at a time
(:func:`quotient_rows`), for :func:`~mitld_lp.solvers.analysis.analyse`.

The analysis copied the kept choices' rows of the product whole (``m[kept]``: each
entry's probability and its column in the product's index type, 16 bytes an entry
where the product's indices are int64), then mapped each column to a reduced state (4
more bytes), and kept the arrays, entries to removed states zeroed, under the final
matrix (SciPy's ``eliminate_zeros`` keeps a view where more than half the entries
stay).  On the sensed case (1.08 million transitions, 1.0 million of them in kept
rows, 725,036 left in the quotient) those were the analysis's peak and 4 MB it kept.

Here each slice of rows is gathered, its columns mapped, its one-step sums taken, and
its surviving entries written into arrays of the final size and dtype.  A removed
state's column is not one extra column but one of :data:`CLASSES` (``n_red +`` its
*class*: which of the sums' sets it belongs to), so the sums are read off the mapped
slice itself: each row's sum runs over its entries in stored order with the same
factors (1 for an entry into a set's state, 0 otherwise) as over the product, by the
same SciPy kernel, so every sum is the same to the bit.

Where a compiled kernel's load is paid and the kept rows hold at least
:data:`COMPILED_MIN_ENTRIES` entries, one call of
:func:`~mitld_lp.solvers.quotient_kernels.quotient_entries` reads them instead, the
sums made in the same order from the same operands (the same bits; ``bus_scaled`` n64
d3, 1.77 million entries: the slices' dozen NumPy and SciPy calls each were 20 ms).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.rows import gather_ranges
from mitld_lp.util import kernel_loader
from mitld_lp.util.sparsetools import sparsetools

__all__ = ["CLASSES", "COMPILED_MIN_ENTRIES", "QuotientRows", "quotient_rows", "row_columns",
           "take_ranges"]

COMPILED_MIN_ENTRIES = 100_000
"""Entries of the kept rows from which they are read by the compiled kernel once a
kernel's load is paid (its link, 1-3 ms once a process, against the slices' 10-20 ns
an entry)."""

SLICE = 1 << 15
"""Entries of the product gathered at a time (their temporaries: some 22 bytes an
entry, 0.7 MB a slice: small beside a product of 1e5 entries, few slices on one of 1e6)."""

CLASSES = 1 << 5
"""Columns past the reduced states: a removed state's class, a bit a set (at most five
sets: the goal, the extra target, the value-1 states, each model's prob-0 states)."""


@dataclass(frozen=True, slots=True)
class QuotientRows:
    """The kept rows: ``data``, ``indices`` (reduced states), ``indptr`` of the
    quotient's matrix (entries into removed states dropped, or kept as explicit zeros
    in column 0 with ``drop`` False), and each group's sums: ``sums[g]`` is
    ``(n_rows, len(groups[g]))`` float64 (or ``(n_rows,)`` for a group given as one
    mask rather than a list: SciPy's 1-d product; bool, the sums above 0, for the
    ``positive`` groups)."""

    data: np.ndarray
    indices: np.ndarray
    indptr: np.ndarray
    sums: list[np.ndarray]


def quotient_rows(m: sp.csr_array, kept: np.ndarray, state_map: np.ndarray, n_red: int,
                  groups: list[np.ndarray | list[np.ndarray]], index: type,
                  drop: bool = True, positive: tuple[int, ...] = ()) -> QuotientRows:
    """The rows ``kept`` of the product ``m`` (no stored zero) as the quotient's:
    each entry's column ``state_map`` of it (a reduced state, or -1: removed), and for
    each group of state masks (each false on every state ``state_map`` keeps) the rows'
    products with them, as ``m[kept] @ stack(group)`` gives them (a 1-d mask: ``m[kept]
    @ mask``), or for the groups numbered in ``positive`` whether those are above 0
    (bool).  At most :data:`CLASSES`'s five masks in all."""
    masks = [g for group in groups for g in (group if isinstance(group, list) else [group])]
    if len(masks) > 5:
        raise ValueError(f"quotient_rows: {len(masks)} masks, at most 5")
    # each state's column: its reduced state, or n_red + its class (a byte a state)
    col_type = index if n_red + CLASSES <= np.iinfo(index).max else np.int64
    removed = state_map < 0
    code = np.zeros(state_map.size, dtype=np.uint8)
    for bit, mask in enumerate(masks):
        code |= np.asarray(mask, dtype=bool).view(np.uint8) << np.uint8(bit)
    if bool(np.any((code != 0) & ~removed)):
        raise ValueError("quotient_rows: a mask holds a kept state")
    column = np.where(removed, code.astype(col_type) + col_type(n_red),
                      state_map).astype(col_type, copy=False)
    del code, removed
    width = n_red + CLASSES
    vectors = []  # each group's factors over the mapped columns
    at = 0
    for group in groups:
        k = len(group) if isinstance(group, list) else 0
        x = np.zeros((width, max(k, 1)), dtype=np.float64)
        for j in range(max(k, 1)):
            x[n_red:, j] = (np.arange(CLASSES) >> (at + j)) & 1
        vectors.append(x if k else x[:, 0].copy())
        at += max(k, 1)
    kept = np.asarray(kept)
    if kernel_loader.compiled_paid():
        got = _compiled(m, kept, column, n_red, len(masks), groups, index, drop, positive)
        if got is not None:
            return got
    starts = np.zeros(kept.size + 1, dtype=np.int32 if m.nnz < 2**31 else np.int64)
    np.cumsum(m.indptr[kept + 1] - m.indptr[kept], out=starts[1:])
    cuts = _slices(starts[1:])  # (starts: each kept row's first entry)
    # the arrays at the kept rows' size, each slice's surviving entries written on,
    # then cut to their count in place (a shrinking realloc: no second array, no
    # second pass over the entries to count them first)
    data = np.empty(int(starts[-1]), dtype=m.data.dtype)
    indices = np.empty(int(starts[-1]), dtype=index)
    indptr = np.zeros(kept.size + 1, dtype=index)
    sums = [np.empty((kept.size,) + x.shape[1:], dtype=bool if g in positive else np.float64)
            for g, x in enumerate(vectors)]
    at = 0
    for a, b in cuts:
        cols, d = _entries(m, kept[a:b])
        cols = column[cols]
        local = (starts[a:b + 1] - starts[a]).astype(index)
        part = sp.csr_array((d, cols, local), shape=(b - a, width), copy=False)
        for g, (s, x) in enumerate(zip(sums, vectors, strict=True)):
            s[a:b] = (part @ x) > 0 if g in positive else part @ x
        del part
        gone = cols >= n_red
        if drop:
            keep = ~gone
            stay = np.zeros(keep.size + 1, dtype=np.int32)
            np.cumsum(keep, out=stay[1:])
            indptr[a + 1:b + 1] = at + stay[local[1:]]
            q = at + int(stay[-1])
            np.compress(keep, d, out=data[at:q])  # no copy of the slice's survivors
            np.compress(keep, cols, out=indices[at:q])
            del keep, stay
        else:
            d[gone] = 0.0
            cols[gone] = 0
            q = at + d.size
            indptr[a + 1:b + 1] = at + local[1:]
            data[at:q], indices[at:q] = d, cols
        at = q
        del d, cols, gone, local
    if at < data.size:
        data.resize(at, refcheck=False)  # no view of them exists
        indices.resize(at, refcheck=False)
    return QuotientRows(data, indices, indptr, sums)


def _compiled(m: sp.csr_array, kept: np.ndarray, column: np.ndarray, n_red: int,
              n_masks: int, groups: list, index: type, drop: bool,
              positive: tuple[int, ...]) -> QuotientRows | None:
    """:func:`quotient_rows` by one call of the compiled kernel (module docs), or None
    below :data:`COMPILED_MIN_ENTRIES` kept entries."""
    size = int((m.indptr[kept + 1] - m.indptr[kept]).sum())
    if size < COMPILED_MIN_ENTRIES:
        return None
    from mitld_lp.solvers.quotient_kernels import quotient_entries

    factors = ((np.arange(CLASSES)[:, None] >> np.arange(max(n_masks, 1))) & 1
               ).astype(np.float64)
    data = np.empty(size, dtype=m.data.dtype)
    indices = np.empty(size, dtype=index)
    indptr = np.empty(kept.size + 1, dtype=index)
    raw = np.empty((kept.size, factors.shape[1]), dtype=np.float64)
    at = int(quotient_entries(m.indptr, m.indices, m.data, kept, column, n_red, factors,
                              bool(drop), data, indices, indptr, raw))
    if at < size:
        data.resize(at, refcheck=False)  # no view of them exists
        indices.resize(at, refcheck=False)
    # each group's sums a view of ``raw``'s columns (not a copy: the copies and
    # ``raw`` were held at once, 5 bytes a transition on the sensed case; the
    # analysis reads each column into an array of its own)
    sums, j = [], 0
    for g, group in enumerate(groups):
        k = len(group) if isinstance(group, list) else 0
        s = raw[:, j:j + k] if k else raw[:, j]
        sums.append(s > 0 if g in positive else s)
        j += max(k, 1)
    return QuotientRows(data, indices, indptr, sums)


def _entries(m: sp.csr_array, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The columns and values of ``m``'s ``rows``, concatenated in order, by SciPy's
    compiled row gather (as ``m[rows]`` makes them, without the matrix)."""
    idx = m.indptr.dtype
    if sparsetools is None or m.indices.dtype != idx:  # pragma: no cover - NumPy's gathers
        sel = gather_ranges(m.indptr[rows], m.indptr[rows + 1])
        return m.indices[sel], m.data[sel]
    rows = np.asarray(rows, dtype=idx)
    count = int((m.indptr[rows + 1] - m.indptr[rows]).sum())
    cols, data = np.empty(count, dtype=idx), np.empty(count, dtype=m.data.dtype)
    sparsetools.csr_row_index(rows.size, rows, m.indptr, m.indices, m.data, cols, data)
    return cols, data


def row_columns(m: sp.csr_array, rows: np.ndarray) -> np.ndarray:
    """The columns of ``m``'s ``rows`` concatenated (``m[rows].indices``), gathered
    :data:`SLICE` entries at a time (no per-entry index array, nor the values)."""
    rows = np.asarray(rows)
    ends = np.cumsum(np.asarray(m.indptr[rows + 1] - m.indptr[rows], dtype=np.int64))
    out = np.empty(int(ends[-1]) if ends.size else 0, dtype=m.indices.dtype)
    for a, b in _slices(ends):
        out[int(ends[a - 1]) if a else 0:int(ends[b - 1])] = _entries(m, rows[a:b])[0]
    return out


def take_ranges(values: np.ndarray, starts: np.ndarray, stops: np.ndarray) -> np.ndarray:
    """``values[gather_ranges(starts, stops)]`` (the concatenated ranges, in ``values``'s
    dtype), taken :data:`SLICE` entries at a time: no index array of every entry (the
    gather's three, 24 bytes an entry, were the sensed case's analysis peak)."""
    starts = np.asarray(starts, dtype=np.int64)
    lens = np.asarray(stops, dtype=np.int64) - starts
    ends = np.cumsum(lens)
    out = np.empty(int(ends[-1]) if ends.size else 0, dtype=values.dtype)
    for a, b in _slices(ends):
        p = int(ends[a - 1]) if a else 0
        out[p:int(ends[b - 1])] = values[gather_ranges(starts[a:b], starts[a:b] + lens[a:b])]
    return out


def _slices(ends: np.ndarray) -> list[tuple[int, int]]:
    """Consecutive row ranges ``[a, b)`` of about :data:`SLICE` entries each (a row
    whole), ``ends`` each row's cumulative entry count."""
    n = ends.size
    cuts, a = [], 0
    while a < n:
        base = int(ends[a - 1]) if a else 0
        b = int(np.searchsorted(ends, base + SLICE, side="right"))
        b = max(b, a + 1)
        cuts.append((a, min(b, n)))
        a = min(b, n)
    return cuts
