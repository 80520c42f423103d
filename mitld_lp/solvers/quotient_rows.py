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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.rows import gather_ranges

__all__ = ["CLASSES", "QuotientRows", "quotient_rows", "take_ranges"]

SLICE = 1 << 16
"""Entries of the product gathered at a time (their temporaries: some 30 bytes an
entry, 2 MB a slice)."""

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
    # each state's column: its reduced state, or n_red + its class (a byte a state,
    # then written into the removed states' places: no int64 array a state)
    if n_red + CLASSES > np.iinfo(index).max:  # the classes' columns past the type
        index = np.int64
    column = state_map.astype(index)
    removed = column < 0
    code = np.zeros(state_map.size, dtype=np.uint8)
    for bit, mask in enumerate(masks):
        if bool(np.any(mask & ~removed)):
            raise ValueError(f"quotient_rows: mask {bit} holds a kept state")
        code[mask] |= np.uint8(1 << bit)
    column[removed] = code[removed]
    column[removed] += index(n_red)
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
    ptr = m.indptr
    lo = np.asarray(ptr[kept], dtype=np.int64)
    counts = np.asarray(ptr[np.asarray(kept, dtype=np.int64) + 1], dtype=np.int64)
    counts -= lo  # each row's entries (then those that stay)
    cuts = _slices(np.cumsum(counts))
    lens = counts.astype(index) if drop else counts
    if drop:  # each row's surviving entries first (the final arrays' size)
        for a, b in cuts:
            cols = column[m.indices[gather_ranges(lo[a:b], lo[a:b] + lens[a:b])]]
            stay = np.concatenate([[0], np.cumsum(cols < n_red)])
            local = np.concatenate([[0], np.cumsum(lens[a:b])])
            counts[a:b] = stay[local[1:]] - stay[local[:-1]]
            del cols, stay, local
    indptr = np.zeros(kept.size + 1, dtype=index)
    np.cumsum(counts, out=indptr[1:])
    del counts
    total = int(indptr[-1])
    data = np.empty(total, dtype=m.data.dtype)
    indices = np.empty(total, dtype=index)
    sums = [np.empty((kept.size,) + x.shape[1:], dtype=bool if g in positive else np.float64)
            for g, x in enumerate(vectors)]
    for a, b in cuts:
        sel = gather_ranges(lo[a:b], lo[a:b] + lens[a:b])
        d, cols = m.data[sel], column[m.indices[sel]]
        del sel
        local = np.zeros(b - a + 1, dtype=index)
        np.cumsum(lens[a:b], out=local[1:])
        part = sp.csr_array((d, cols, local), shape=(b - a, width), copy=False)
        for g, (s, x) in enumerate(zip(sums, vectors, strict=True)):
            s[a:b] = (part @ x) > 0 if g in positive else part @ x
        del part
        gone = cols >= n_red
        p, q = int(indptr[a]), int(indptr[b])
        if drop:
            keep = ~gone
            data[p:q], indices[p:q] = d[keep], cols[keep]
        else:
            d[gone] = 0.0
            cols[gone] = 0
            data[p:q], indices[p:q] = d, cols
        del d, cols, gone
    return QuotientRows(data, indices, indptr, sums)


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
