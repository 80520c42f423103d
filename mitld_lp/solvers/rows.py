"""Rows of a CSR matrix read straight from its arrays: the entries of chosen rows
(:func:`row_entries`), their products with a vector (:func:`rows_dot`) and the
concatenated index ranges both are made of (:func:`gather_ranges`).  No matrix is made
for the rows (scipy's row indexing costs ~0.2 ms a call).  This module imports no solver
module: :mod:`~mitld_lp.solvers.graph` and the solvers build on it."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["gather_ranges", "off_diagonal_entries", "row_entries", "rows_dot"]

#: rows read at a time by :func:`off_diagonal_entries` (its temporaries: a batch's)
BATCH = 1 << 16


def gather_ranges(starts: np.ndarray, stops: np.ndarray) -> np.ndarray:
    """The concatenation of ``arange(starts[i], stops[i])`` over ``i``, vectorised."""
    starts = np.asarray(starts, dtype=np.int64)
    counts = np.asarray(stops, dtype=np.int64) - starts
    total = int(counts.sum())
    offsets = np.repeat(starts - (np.cumsum(counts) - counts), counts)
    return offsets + np.arange(total, dtype=np.int64)


def row_entries(matrix: sp.csr_array, rows: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The stored entries of ``matrix``'s ``rows`` as ``(local row, column, value)``
    arrays (``local row``: the position in ``rows``), read straight from its CSR arrays:
    no matrix is made for them (scipy's row indexing costs ~0.2 ms a call, which on a
    product of thousands of levels -- a deadline clock -- was most of the solve)."""
    rows = np.asarray(rows, dtype=np.int64)
    lo, hi = matrix.indptr[rows], matrix.indptr[rows + 1]
    entries = gather_ranges(lo, hi)
    local = np.repeat(np.arange(rows.size, dtype=np.int64), hi - lo)
    return local, matrix.indices[entries], matrix.data[entries]


def off_diagonal_entries(matrix: sp.csr_array, rows: np.ndarray, row_state: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`row_entries` of ``rows`` without each row's entry in column
    ``row_state[i]`` (its self-loop), in the same order, read :data:`BATCH` rows at a
    time: the whole gather (an int64 index and an int64 local row per entry, then the
    filtered copies) was the solve stage's memory peak on QVBS ``zeroconf_dl`` and
    ``csma``.  ``local`` is int32 when the rows' count fits (4 bytes an entry, not 8)."""
    rows = np.asarray(rows, dtype=np.int64)
    row_state = np.asarray(row_state)
    small = np.int32 if rows.size < np.iinfo(np.int32).max else np.int64
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    for a in range(0, rows.size, BATCH):
        local, cols, vals = row_entries(matrix, rows[a:a + BATCH])
        keep = cols != row_state[a:a + BATCH][local]
        parts.append(((local[keep] + a).astype(small), cols[keep], vals[keep]))
    if not parts:
        return (np.zeros(0, dtype=small), matrix.indices[:0].copy(),
                matrix.data[:0].copy())
    return tuple(np.concatenate([p[k] for p in parts]) for k in range(3))  # type: ignore[return-value]


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
