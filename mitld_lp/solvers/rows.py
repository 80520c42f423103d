"""Rows of a CSR matrix read straight from its arrays: the entries of chosen rows
(:func:`row_entries`), their products with a vector (:func:`rows_dot`) and the
concatenated index ranges both are made of (:func:`gather_ranges`).  No matrix is made
for the rows (scipy's row indexing costs ~0.2 ms a call).  This module imports no solver
module: :mod:`~mitld_lp.solvers.graph` and the solvers build on it."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["gather_ranges", "row_entries", "rows_dot"]


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
