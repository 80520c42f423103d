"""The occupancy LP's optimum (:func:`mitld_lp.solvers.lp.solve_lp`, both layouts, with
and without the iteration's bounds) against scipy.optimize.linprog on the value LP of
small MDPs built here: for a maximum, the least ``v >= 0`` with ``v(s) >= P(c, .) v`` on
every choice (``v = 1`` on the target); for a minimum, the greatest ``v <= 1`` with
``v(s) <= P(c, .) v`` after the states that can avoid the target for ever (found here by
their own fixpoint) are fixed at 0.  Nothing of the package's analysis is used for the
reference."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog

from mitld_lp.mdp import MDP
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.quotient import reduce


def _mdp(seed: int, n: int = 30) -> MDP:
    """A random MDP with two targets, a sink (state 1, its one choice a self-loop),
    self-loops and cycles, every other state with 1-3 choices of 1-3 successors."""
    rng = np.random.default_rng(seed)
    rows, groups = [], [0]
    for s in range(n):
        if s == 1:
            rows.append({1: 1.0})
        for _ in range(int(rng.integers(1, 4)) if s != 1 else 0):
            succ = rng.choice(n, size=int(rng.integers(1, 4)), replace=False)
            if rng.random() < 0.05:
                succ = np.array([s])
            p = rng.random(succ.size) + 0.1
            rows.append(dict(zip(succ.tolist(), (p / p.sum()).tolist(), strict=True)))
        groups.append(len(rows))
    target = np.zeros(n, dtype=bool)
    target[rng.choice(np.arange(2, n), size=2, replace=False)] = True
    data, col, ptr = [], [], [0]
    for r in rows:
        col.extend(r.keys())
        data.extend(r.values())
        ptr.append(len(col))
    matrix = sp.csr_array((np.array(data), np.array(col), np.array(ptr)),
                          shape=(len(rows), n))
    groups = np.array(groups, dtype=np.int64)
    return MDP(matrix=matrix, row_groups=groups,
               choice_actions=(np.arange(len(rows)) - np.repeat(groups[:-1], np.diff(groups))
                               ).astype(np.int32),
               action_names=("a0", "a1", "a2"), initial=0, target=target,
               sink=np.zeros(n, dtype=bool), truncated=np.zeros(n, dtype=bool),
               states=tuple(range(n)))


def _avoiding(mdp: MDP) -> np.ndarray:
    """The states that can avoid the target for ever: the greatest set outside it where
    each state has a choice whose every successor is in it (a fixpoint by loops)."""
    dense = mdp.matrix.toarray()
    groups = np.asarray(mdp.row_groups)
    inside = ~np.asarray(mdp.target)
    while True:
        keep = inside.copy()
        for s in np.flatnonzero(inside):
            keep[s] = any(inside[dense[c] > 0].all()
                          for c in range(groups[s], groups[s + 1]))
        if (keep == inside).all():
            return inside
        inside = keep


def _by_linprog(mdp: MDP, sense: Sense) -> np.ndarray:
    dense = mdp.matrix.toarray()
    n = mdp.n_states
    groups = np.asarray(mdp.row_groups)
    target = np.asarray(mdp.target)
    fixed = target | (_avoiding(mdp) if sense is Sense.MIN else np.zeros(n, dtype=bool))
    a_ub, b_ub = [], []
    for s in range(n):
        if fixed[s]:
            continue
        for c in range(groups[s], groups[s + 1]):
            row = -dense[c].copy()
            row[s] += 1.0  # v(s) - P(c,.) v  >= 0 (max) or <= 0 (min)
            a_ub.append(-row if sense is Sense.MAX else row)
            b_ub.append(0.0)
    bounds = [(1.0, 1.0) if target[s] else (0.0, 0.0) if fixed[s] else (0.0, 1.0)
              for s in range(n)]
    cost = np.ones(n) if sense is Sense.MAX else -np.ones(n)
    res = linprog(cost, A_ub=np.array(a_ub) if a_ub else None,
                  b_ub=np.array(b_ub) if b_ub else None, bounds=bounds, method="highs")
    assert res.status == 0, res.message
    return res.x


@pytest.mark.parametrize("layout", ["blocks", "whole"])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", range(6))
def test_lp_optimum_matches_linprog(seed: int, sense: Sense, layout: str) -> None:
    mdp = _mdp(seed)
    want = _by_linprog(mdp, sense)
    q = reduce(mdp, mdp.target, sense=sense)
    it = interval_iteration(mdp, mdp.target, quotient=q, sense=sense, tol=1e-10,
                            precision=None, gap="max")
    for bounds in (None, (it.lower, it.upper)):
        got = solve_lp(mdp, mdp.target, quotient=q, sense=sense, everywhere=True,
                       layout=layout, bounds=bounds, progress=False)
        assert got.status.value == "optimal", got.message
        np.testing.assert_allclose(np.asarray(got.values), want, atol=1e-7)
        assert abs(got.value - want[mdp.initial]) <= 1e-7
