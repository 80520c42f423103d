"""The reused factorisation of the policy jump against scipy's sparse direct solve."""

from __future__ import annotations

import numpy as np
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


def test_the_same_chain_reuses_its_factorisation_and_another_does_not() -> None:
    n = 2000
    q, other = _chain(n, 1), _chain(n, 3)
    rhs = np.column_stack([np.random.default_rng(2).random(n), np.ones(n)])
    factors = Factors()
    first = transient_solve(q, rhs, refine=2, factors=factors)
    again = transient_solve(sp.csr_array(q.copy()), rhs, refine=2, factors=factors)
    assert factors.factorised == 1 and factors.reused == 1
    np.testing.assert_array_equal(first, again)  # the same arithmetic, bit for bit
    ref = spla.spsolve(sp.csc_array(sp.eye_array(n) - q), rhs)
    np.testing.assert_allclose(np.asarray(first, dtype=np.float64), ref, rtol=1e-11)
    assert first.dtype == np.longdouble
    x = transient_solve(other, rhs, refine=2, factors=factors)
    assert factors.factorised == 2 and factors.reused == 1
    ref = spla.spsolve(sp.csc_array(sp.eye_array(n) - other), rhs)
    np.testing.assert_allclose(np.asarray(x, dtype=np.float64), ref, rtol=1e-11)
