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
  them), with truncated states or none;
* a maximum's ``Prob1E`` (``prob1_e``) out of the quotient and the lift's strategy kept
  for it, which reaches the goal almost surely (a plain walk of the chain it plays)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from test_analysis_cut_one import _choices, _draw, _prob1a
from test_analysis_half_quotient import as_mdp
from test_rare_solve import prob0_e, prob1_e

from mitld_lp.solvers.analysis import ATTRACTOR_STRATEGY, analyse
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


def _almost_surely(choices: list[list[set[int]]], play: dict[int, int], target: set[int],
                   ) -> set[int]:
    """The states of ``play`` from which the chain playing it reaches ``target`` with
    probability 1, the other states stopping: every state it can reach has a path to
    the target (a finite chain)."""
    def succ(s: int) -> set[int]:
        return choices[s][play[s]] if s in play and s not in target else set()

    def reach(s: int) -> set[int]:
        seen, todo = {s}, [s]
        while todo:
            for t in succ(todo.pop()):
                if t not in seen:
                    seen.add(t)
                    todo.append(t)
        return seen

    return {s for s in play if all(reach(t) & target for t in reach(s))}


def _draw_acyclic(seed: int) -> tuple[np.ndarray, list[int]]:
    """A dense (choices x states) table without end components but the absorbing ones:
    10-30 states, each other one's 1-3 choices of 1-3 successors among the states after
    it; the last absorbing (the goal), the one before it absorbing (a sink)."""
    rng = np.random.default_rng(8300 + seed)
    n = int(rng.integers(10, 31))
    rows, owner = [], []
    for s in range(n):
        for _ in range(1 if s >= n - 2 else int(rng.integers(1, 4))):
            w = np.zeros(n)
            if s >= n - 2:
                w[s] = 1.0
            else:
                k = int(min(rng.integers(1, 4), n - 1 - s))
                w[rng.choice(np.arange(s + 1, n), k, replace=False)] = rng.integers(1, 5, k)
            rows.append(w / w.sum())
            owner.append(s)
    return np.array(rows), owner


@pytest.mark.parametrize("acyclic", [False, True])
def test_maximum_value_one_states_and_their_strategy(acyclic: bool) -> None:
    """A maximum's Prob1E of the goal (``prob1_e``) leaves the quotient, and the lifted
    strategy kept for those states reaches the goal almost surely: on draws with end
    components (their sets and strategy found on the quotient) and without (found on
    the product's pattern, :func:`~mitld_lp.solvers.value_one.prob1e_first`)."""
    played = 0
    for seed in range(40):
        dense, owner = _draw_acyclic(seed) if acyclic else _draw(seed, False)
        mdp = as_mdp(dense, owner, False)
        n = dense.shape[1]
        goal = np.zeros(n, dtype=bool)
        goal[-1] = True
        low, _ = analyse(mdp, goal, sense=Sense.MAX)
        succ = _choices(dense, owner)
        g = set(np.flatnonzero(goal).tolist())
        sure = prob1_e(succ, g) - g
        assert sure == set(np.flatnonzero(np.asarray(low.state_map) < 0).tolist()) & (
            set(range(n)) - g - set(np.flatnonzero(np.asarray(low.prob0)).tolist())), seed
        strategy = low.shared.get(ATTRACTOR_STRATEGY)
        if not sure:
            continue
        assert strategy is not None, seed
        assert set(np.asarray(strategy.states).tolist()) == sure, seed
        groups = np.asarray(mdp.row_groups)
        play = {int(s): int(c) - int(groups[s])
                for s, c in zip(strategy.states, strategy.choices, strict=True)}
        assert all(0 <= play[s] < len(succ[s]) for s in play), seed
        assert _almost_surely(succ, play, g) == sure, seed
        played += sum(len(succ[s]) > 1 for s in sure)
    assert played > 0  # states with a choice to make
