""":func:`mitld_lp.solvers.rounding.support_extreme` by one ``reduceat`` a batch: each
row's extreme over its stored entries, against a brute force over the rows' entries."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers import rounding


def test_support_extreme_over_stored_entries_any_order_and_empty_rows(monkeypatch) -> None:
    rng = np.random.default_rng(11)
    n_rows, n_cols = 300, 50
    rows_entries = []
    for r in range(n_rows):
        k = 0 if r % 7 == 3 else int(rng.integers(1, 6))  # some rows empty
        cols = rng.choice(n_cols, size=k, replace=False)  # stored in no order
        rows_entries.append(cols)
    indptr = np.concatenate([[0], np.cumsum([c.size for c in rows_entries])]).astype(np.int32)
    indices = np.concatenate(rows_entries).astype(np.int32)
    data = rng.random(indices.size)
    data[::9] = 0.0  # an explicit zero is still in the support
    matrix = sp.csr_array((data, indices, indptr), shape=(n_rows, n_cols))
    x = rng.random(n_cols) - 0.5
    pick = rng.integers(0, n_rows, 500)  # repeated, unsorted rows
    monkeypatch.setattr(rounding, "BATCH", 64)
    for largest in (True, False):
        got = rounding.support_extreme(matrix, pick, x, largest)
        for i, r in enumerate(pick.tolist()):
            support = [float(x[c]) for c in rows_entries[r].tolist()]
            want = ((max(support) if largest else min(support)) if support
                    else (-np.inf if largest else np.inf))
            assert got[i] == want
