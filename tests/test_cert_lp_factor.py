"""A walked chain's level factorisation made from the chain's arrays
(:meth:`mitld_lp.solvers.chain_levels.ChainLevels._level_factor`): the same rows and
the same ``I - Q`` as SciPy's indexing and ``eye - inner``, so the same LU and bits."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers import chain_levels as cl


def _chain(n: int, seed: int) -> sp.csr_array:
    """Cycles of random length 1-40 (a self-loop on some states, an explicit zero on
    some entries), each state also leaving to a lower cycle: many cyclic levels."""
    rng = np.random.default_rng(seed)
    r, c, v = [], [], []
    start = 0
    while start < n:
        size = min(int(rng.integers(1, 41)), n - start)
        for i in range(start, start + size):
            nxt = start + (i - start + 1) % size
            if size > 1:
                r.append(i), c.append(nxt), v.append(0.4)
            if rng.random() < 0.3:  # a self-loop
                r.append(i), c.append(i), v.append(0.2)
            if rng.random() < 0.1 and size > 2:  # a stored zero inside the cycle
                far = start + (i - start + 2) % size
                r.append(i), c.append(far), v.append(0.0)
            if start > 0:
                r.append(i), c.append(int(rng.integers(0, start))), v.append(0.3)
        start += size
    order = rng.permutation(len(r))  # entries in no order: the walk makes it canonical
    return sp.csr_array(sp.coo_array((np.array(v)[order], (np.array(r)[order],
                                                           np.array(c)[order])),
                                     shape=(n, n)))


def test_level_factor_is_scipys_rows_and_matrix(monkeypatch) -> None:
    monkeypatch.setattr(cl, "WALK_MIN_STATES", 2)  # walked whatever its size
    walk = cl.ChainLevels(_chain(2_000, 5))
    blk = walk.blocks
    assert blk is not None and walk.chain.has_canonical_format
    rng = np.random.default_rng(0)
    levels = np.unique(blk.level[blk.size > 1]).tolist()
    assert len(levels) > 3
    for lv in levels:
        states = blk.states_at(lv)
        states = states[~blk.single(states)]
        rows, lu = walk._level_factor(states)
        want_rows = sp.csr_array(walk.chain[states])
        assert np.array_equal(rows.indptr, want_rows.indptr)
        assert np.array_equal(rows.indices, want_rows.indices)
        assert np.array_equal(rows.data, want_rows.data)
        inner = sp.csc_array(want_rows[:, states])
        want = sp.csc_array(sp.eye_array(states.size, format="csc") - inner)
        want.sum_duplicates()
        want_lu = cl.chain_lu(want, dense=False)
        b = rng.random(states.size)
        assert np.array_equal(lu.solve(b), want_lu.solve(b))  # the same bits
        assert np.array_equal(lu.solve(b, trans="T"), want_lu.solve(b, trans="T"))
        assert np.array_equal(lu.perm_c, want_lu.perm_c)
        assert np.allclose(want @ lu.solve(b), b, rtol=1e-12, atol=1e-12)


def test_walk_solves_against_the_iteration(monkeypatch) -> None:
    monkeypatch.setattr(cl, "WALK_MIN_STATES", 2)
    n = 3_000
    q = _chain(n, 9)
    b = np.random.default_rng(2).random(n)
    walk = cl.ChainLevels(q.copy())
    x = walk.solve(b)
    y = b.copy()  # rows sum to 0.9 at most: 400 rounds leave 0.9^400
    for _ in range(400):
        y = b + q @ y
    assert np.allclose(x, y, rtol=1e-11, atol=1e-11)
    t = walk.solve_transposed(b)
    z = b.copy()
    for _ in range(400):
        z = b + q.T @ z
    assert np.allclose(t, z, rtol=1e-11, atol=1e-11)
