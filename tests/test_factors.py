"""Reused factorisations of policy iteration (a few changed rows corrected by the
Sherman--Morrison--Woodbury formula) against scipy's sparse direct solve."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from mitld_lp.solvers.topological import Factors, transient_solve


def _chain(n: int, seed: int) -> sp.csr_array:
    rng = np.random.default_rng(seed)
    rows = np.repeat(np.arange(n), 3)
    cols = np.clip(rows + rng.integers(-5, 6, rows.size), 0, n - 1)
    q = sp.csr_array((rng.random(rows.size), (rows, cols)), shape=(n, n))
    q.sum_duplicates()
    return sp.csr_array(sp.diags_array(0.995 / np.asarray(q.sum(axis=1)).ravel()) @ q)


@pytest.mark.parametrize("changed", [0, 7, 40])
def test_a_few_changed_rows_reuse_the_factorisation(changed: int) -> None:
    n = 2000
    q = _chain(n, 1)
    rhs = np.column_stack([np.random.default_rng(2).random(n), np.ones(n)])
    factors = Factors()
    transient_solve(q, rhs, refine=2, factors=factors)
    other = _chain(n, 3)  # rows of another chain replace some of q's
    rows = np.random.default_rng(4).choice(n, changed, replace=False)
    q2 = sp.lil_array(q)
    for r in rows:
        q2[[r], :] = other[[r], :].toarray()
    q2 = sp.csr_array(q2)
    x = transient_solve(q2, rhs, refine=2, factors=factors)
    ref = spla.spsolve(sp.csc_array(sp.eye_array(n) - q2), rhs)
    np.testing.assert_allclose(np.asarray(x, dtype=np.float64), ref, rtol=1e-11)
    assert factors.factorised == 1 and factors.reused == 1
    assert x.dtype == np.longdouble


def test_many_changed_rows_factorise_again() -> None:
    n = 2000
    q, other = _chain(n, 1), _chain(n, 3)
    rhs = np.ones(n)
    factors = Factors()
    transient_solve(q, rhs, refine=2, factors=factors)
    x = transient_solve(other, rhs, refine=2, factors=factors)
    ref = spla.spsolve(sp.csc_array(sp.eye_array(n) - other), rhs)
    np.testing.assert_allclose(np.asarray(x, dtype=np.float64), ref, rtol=1e-11)
    assert factors.factorised == 2 and factors.reused == 0
