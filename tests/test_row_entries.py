"""Rows of a CSR matrix read from its arrays (the per-level products of the topological
solvers) against scipy's own row indexing and product."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.rows import row_entries, rows_dot


def _matrix(seed: int) -> sp.csr_array:
    rng = np.random.default_rng(seed)
    dense = rng.random((40, 30)) * (rng.random((40, 30)) < 0.15)
    dense[[3, 17, 39]] = 0.0  # empty rows
    return sp.csr_array(dense)


def test_rows_dot_is_scipys_row_product_for_vectors_and_columns() -> None:
    m = _matrix(0)
    rng = np.random.default_rng(1)
    rows = np.array([5, 3, 5, 39, 0, 17, 22, 22, 11])  # repeats, empty rows, any order
    x = rng.random(30)
    np.testing.assert_allclose(rows_dot(m, rows, x), m[rows] @ x, rtol=1e-15, atol=0)
    xs = rng.random((30, 3))
    got = rows_dot(m, rows, xs)
    assert got.shape == (rows.size, 3)
    np.testing.assert_allclose(got, m[rows] @ xs, rtol=1e-15, atol=0)
    assert rows_dot(m, np.zeros(0, dtype=np.int64), x).shape == (0,)


def test_row_entries_are_the_coordinates_of_the_selected_rows() -> None:
    m = _matrix(2)
    rows = np.array([8, 3, 8, 1])
    local, cols, vals = row_entries(m, rows)
    coo = sp.coo_array(m[rows])
    assert sorted(zip(local.tolist(), cols.tolist(), vals.tolist(), strict=True)) == sorted(
        zip(coo.row.tolist(), coo.col.tolist(), coo.data.tolist(), strict=True))
