"""A minimum's value-1 states (``Prob1A``) found on the product's pattern before the
quotient is made (:func:`~mitld_lp.solvers.reach.reaching_through`, called by
:func:`~mitld_lp.solvers.analysis.analyse`), checked against plain-Python fixpoints on
list-of-sets graphs (no library):

* the search itself against the textbook least fixpoint "a seed, or a ``through`` state
  with an edge to a state already in", on random graphs;
* the quotient a minimum is left with, rebuilt by hand from the dense table: its states
  are the maybe states outside ``Prob1A`` (``Prob0E`` and ``Prob1A`` by the fixpoints of
  ``test_rare_solve``), its entries the table's among them in their order, and each
  choice's one-step probability of the target is the table's into the goal plus its
  move into a removed value-1 state (the two sums added, as the cut quotient added
  them), with truncated states or none."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from test_analysis_cut_one import _choices, _draw, _prob1a
from test_analysis_half_quotient import as_mdp
from test_rare_solve import prob0_e

from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.reach import reaching_through


def _fixpoint(choices: list[list[set[int]]], through: set[int], seeds: set[int]) -> set[int]:
    """The seeds, and every ``through`` state with a choice into the set, to a fixpoint."""
    inside = set(seeds)
    grew = True
    while grew:
        grew = False
        for s in through - inside:
            if any(c & inside for c in choices[s]):
                inside.add(s)
                grew = True
    return inside


@pytest.mark.parametrize("seed", range(30))
def test_reaching_through_is_the_fixpoint(seed: int) -> None:
    rng = np.random.default_rng(7100 + seed)
    n = int(rng.integers(2, 40))
    per_state = rng.integers(0, 4, n)  # some states have no choice
    groups = np.concatenate([[0], np.cumsum(per_state)]).astype(np.int64)
    rows, cols = [], []
    for c in range(int(groups[-1])):
        k = int(rng.integers(1, 4))
        for t in rng.choice(n, min(k, n), replace=False):
            rows.append(c)
            cols.append(int(t))
    m = sp.csr_array((np.ones(len(rows)), (rows, cols)), shape=(int(groups[-1]), n))
    through = rng.random(n) < 0.6
    seeds = rng.random(n) < 0.15
    choices: list[list[set[int]]] = [[] for _ in range(n)]
    for s in range(n):
        for c in range(groups[s], groups[s + 1]):
            choices[s].append(set(m.indices[m.indptr[c]:m.indptr[c + 1]].tolist()))
    want = _fixpoint(choices, set(np.flatnonzero(through).tolist()),
                     set(np.flatnonzero(seeds).tolist()))
    got = reaching_through(m, groups, through, seeds)
    assert set(np.flatnonzero(got).tolist()) == want


@pytest.mark.parametrize("truncated", [False, True])
def test_minimum_quotient_without_its_value_one_states(truncated: bool) -> None:
    removed = 0
    for seed in range(40):
        dense, owner = _draw(seed, truncated)
        mdp = as_mdp(dense, owner, truncated)
        n = dense.shape[1]
        goal = np.zeros(n, dtype=bool)
        goal[-1] = True
        extra = np.asarray(mdp.truncated)
        low, _ = analyse(mdp, goal, extra, sense=Sense.MIN)
        succ = _choices(dense, owner)
        g = set(np.flatnonzero(goal).tolist())
        wide = g | set(np.flatnonzero(extra).tolist())
        # the maybe states: every policy reaches the wider target with positive
        # probability, and none of it; the goal's Prob1A among them leaves
        maybe = set(range(n)) - prob0_e(succ, wide) - wide
        sure = _prob1a(succ, g) & maybe
        left = sorted(maybe - sure)
        removed += len(sure)
        state_map = np.asarray(low.state_map)
        assert sorted(np.flatnonzero(state_map >= 0).tolist()) == left, seed
        assert np.array_equal(state_map[left], np.arange(len(left))), seed
        kept = [c for c, s in enumerate(owner) if s in set(left)]
        assert np.asarray(low.choice_origin).tolist() == kept, seed
        q = low.matrix
        for r, c in enumerate(kept):
            row = dense[c]
            cols = [t for t in np.flatnonzero(row > 0) if t in set(left)]
            got = q.indices[q.indptr[r]:q.indptr[r + 1]]
            assert got.tolist() == [int(state_map[t]) for t in cols], (seed, c)
            assert q.data[q.indptr[r]:q.indptr[r + 1]].tolist() == row[cols].tolist()
            # two sums in the table's order, added: the goal's, then the move into a
            # removed value-1 state (0 where there is none)
            to_goal = 0.0
            for t in np.flatnonzero(row > 0):
                to_goal += row[t] * float(goal[t])
            into = 0.0
            for t in np.flatnonzero(row > 0):
                into += row[t] * float(t in sure)
            assert low.to_target[r] == (to_goal + into if sure else to_goal), (seed, c)
    assert removed > 0  # some value-1 states did leave the quotient
