"""The certificate's shortcuts of the solve-stage branch, against routes written
differently: the repair of a Bellman candidate read from level slices gathered once
(small levels) and state by state (large levels) moves the same bounds to the bit, and
what it hands back passes the check and lies above the optimum of value iteration; the
minimum's proof that no end component is left (an attractor over the states that may
hold one) agrees with the search for the components themselves."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import certify as C
from mitld_lp.solvers import certify_repair as R
from mitld_lp.solvers.certify_chain import support_layers
from mitld_lp.solvers.graph import maximal_end_components
from mitld_lp.solvers.rounding import rounding
from mitld_lp.testing import random_mdp


def _optimum(mdp, target: np.ndarray, sweeps: int = 20_000) -> np.ndarray:
    """Pmax by plain value iteration from 0 (a lower approximation of the least fixed
    point, converged far below the perturbations used here)."""
    m = sp.csr_array(mdp.matrix)
    starts = np.asarray(mdp.row_groups[:-1])
    has = np.diff(mdp.row_groups) > 0
    v = target.astype(float)
    for _ in range(sweeps):
        best = np.zeros_like(v)
        best[has] = np.maximum.reduceat(m @ v, starts[has])
        nxt = np.where(target, 1.0, best)
        if np.max(np.abs(nxt - v)) < 1e-15:
            break
        v = nxt
    return v


def _repaired(mdp, x0: np.ndarray, free: np.ndarray, upper: bool, st: C.Rows | None = None,
              sparse_level: int = R.SPARSE_LEVEL):
    """The repair of ``x0`` on ``mdp``'s rows (or ``st``'s), its levels read from slices
    (``sparse_level`` above every level) or state by state (``sparse_level=1``)."""
    if st is None:
        st = C.Rows(sp.csr_array(mdp.matrix), np.asarray(mdp.row_groups, dtype=np.int64))
    rnd = rounding(st.matrix)
    comp, level = support_layers(mdp)
    level_of = np.asarray(level)[np.asarray(comp)]
    x = x0.copy()
    failing = C._fails(st, rnd, x, free, upper)
    assert failing.any()  # the repair has work to do
    old = R.SPARSE_LEVEL
    R.SPARSE_LEVEL = sparse_level
    try:
        rep = R.Repair(st, rnd, free, level_of, None, upper)
        ok = rep.run(x, failing)
    finally:
        R.SPARSE_LEVEL = old
    return x, ok, rep.moved, C._fails(st, rnd, x, free, upper)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("upper", [True, False])
def test_the_repair_moves_the_same_bounds_by_slices_and_state_by_state(
        seed: int, upper: bool) -> None:
    mdp = random_mdp(300, seed=seed, locality=8, self_loop_fraction=0.0, max_choices=3)
    target = np.asarray(mdp.target, dtype=bool)
    v = _optimum(mdp, target)
    rng = np.random.default_rng(seed)
    # a candidate off the optimum in a third of the states, each side's wrong way
    off = rng.random(mdp.n_states) < 0.3
    x0 = np.where(off, v * (0.9 if upper else 1.1) + (0.0 if upper else 0.01), v)
    x0 = np.clip(np.where(target, 1.0, x0), 0.0, 1.0)
    free = target.copy() if upper else target | (v == 0.0)
    slices = _repaired(mdp, x0, free, upper, sparse_level=10**9)
    single = _repaired(mdp, x0, free, upper, sparse_level=1)
    assert np.array_equal(slices[0], single[0])
    assert slices[1:3] == single[1:3]
    x, ok, moved, failing = slices
    assert moved > 0
    if ok and not failing.any() and upper:  # a checked pre-fixed point: above Pmax
        assert np.all(x >= v - 1e-12)


@pytest.mark.parametrize("seed", range(3))
def test_the_repair_reads_natures_rows_the_same_both_ways(seed: int) -> None:
    """A robust game's rows: each choice of the MDP split into two of nature's rows
    (the row and a copy shifted to its first successor), the bound on ``max_c
    min_rows``."""
    mdp = random_mdp(200, seed=seed, locality=6, self_loop_fraction=0.0, max_choices=3)
    m = sp.csr_array(mdp.matrix)
    first = m.indices[m.indptr[:-1]]
    shifted = sp.csr_array((np.ones(m.shape[0]), first, np.arange(m.shape[0] + 1)),
                           shape=m.shape)
    rows = sp.csr_array(sp.vstack([m, shifted]))
    order = np.ravel(np.column_stack([np.arange(m.shape[0]),
                                      m.shape[0] + np.arange(m.shape[0])]))
    rows = sp.csr_array(rows[order])
    nature = np.arange(0, rows.shape[0] + 1, 2)

    target = np.asarray(mdp.target, dtype=bool)
    x0 = np.where(target, 1.0, np.random.default_rng(seed).random(mdp.n_states) * 0.5)
    st = C.Rows(rows, np.asarray(mdp.row_groups, dtype=np.int64), nature)
    slices, single = (_repaired(mdp, x0, target.copy(), True, st, sparse_level=level)
                      for level in (10**9, 1))
    assert np.array_equal(slices[0], single[0]) and slices[1:3] == single[1:3]
    assert slices[2] > 0


@pytest.mark.parametrize("seed", range(6))
def test_no_end_component_proof_agrees_with_the_search(seed: int) -> None:
    mdp = random_mdp(250, seed=seed, locality=5 + seed, self_loop_fraction=0.02 * seed,
                     max_choices=3)
    comp, _ = support_layers(mdp)
    rng = np.random.default_rng(seed)
    for _ in range(5):
        left = rng.random(mdp.n_states) < rng.uniform(0.2, 0.9)
        proved = C._escapes(mdp, left, np.asarray(comp))
        truth = maximal_end_components(mdp, left).n_mecs == 0
        assert proved == truth
