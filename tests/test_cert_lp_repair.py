"""A later candidate's repair reads the pattern by column (and the end components'
members) the first repair made (``certify._optimum_side``): the same bounds moved as
by a repair that makes its own, and the repaired candidate checked against value
iteration."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import certify as C
from mitld_lp.solvers import certify_repair as R
from mitld_lp.solvers.certify_chain import support_layers
from mitld_lp.solvers.rounding import rounding
from mitld_lp.testing import random_mdp


def _pmax(mdp, target: np.ndarray) -> np.ndarray:
    m = sp.csr_array(mdp.matrix)
    starts = np.asarray(mdp.row_groups[:-1])
    v = target.astype(float)
    for _ in range(20_000):
        nxt = np.where(target, 1.0, np.maximum.reduceat(m @ v, starts))
        if np.max(np.abs(nxt - v)) < 1e-15:
            break
        v = nxt
    return v


@pytest.mark.parametrize("seed", range(3))
def test_a_repair_on_the_last_ones_pattern_moves_the_same_bounds(seed: int,
                                                                  monkeypatch) -> None:
    monkeypatch.setattr(R, "SPARSE_LEVEL", 1)  # every level state by state: the pattern
    mdp = random_mdp(300, seed=seed, locality=8, self_loop_fraction=0.0, max_choices=3)
    target = np.asarray(mdp.target, dtype=bool)
    v = _pmax(mdp, target)
    st = C.Rows(sp.csr_array(mdp.matrix), np.asarray(mdp.row_groups, dtype=np.int64))
    rnd = rounding(st.matrix)
    comp, level = support_layers(mdp)
    level_of = np.asarray(level)[np.asarray(comp)]
    mec_of = np.full(mdp.n_states, -1, dtype=np.int64)
    mec_of[:6] = [0, 0, 1, 1, 1, 2]  # end components' members moved together
    free = target.copy()
    rng = np.random.default_rng(seed)
    first = R.Repair(st, rnd, free, level_of, mec_of, True)
    for k in range(2):  # two candidates below the optimum in a third of the states
        x0 = np.where(rng.random(mdp.n_states) < 0.3, v * (0.8 + 0.1 * k), v)
        x0 = np.clip(np.where(target, 1.0, x0), 0.0, 1.0)
        failing = C._fails(st, rnd, x0, free, True)
        assert failing.any()
        fresh = R.Repair(st, rnd, free, level_of, mec_of, True)
        shared = R.Repair(st, rnd, free, level_of, mec_of, True, members=first.members,
                           readers_of=first.readers_of)
        a, b = x0.copy(), x0.copy()
        ok_a, ok_b = fresh.run(a, failing), shared.run(b, failing)
        assert np.array_equal(a, b) and ok_a == ok_b and fresh.moved == shared.moved > 0
        if k == 0:
            first = fresh  # its pattern made, for the next candidate
            assert first.readers_of is not None
        if ok_a and not C._fails(st, rnd, a, free, True).any():
            assert np.all(a >= v - 1e-12)  # a checked pre-fixed point is above Pmax
