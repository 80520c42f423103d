"""The analysis (``mitld_lp.solvers.analysis.analyse``) with its record of no end
component as stride-0 read-only views (``EndComponents.none``), a minimum's Prob0E and
Prob1A run around the product's components, against an independent brute force on small
random MDPs, both senses, both truncation models.

The brute force enumerates every positional deterministic policy (optimal for reaching a
set, minimum or maximum, in a finite MDP), builds its Markov chain as a dense matrix,
finds the states of the chain with a path to the target by a Boolean closure, solves the
linear system on them (0 elsewhere) with NumPy, and takes the best value state by state.
The quotient is solved the same way (every positional policy of it: it has no end
component, so each system is regular), lifted, and compared; the graph's sets (prob-0,
value 1) are compared with the brute force's exact zeros and ones; the lifted policy of
the quotient's greedy choice is evaluated in the product's own chain."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.mdp import MDP
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.end_components import EndComponents
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.quotient import lift_policy
from mitld_lp.solvers.reduced import greedy_choices


def _random_mdp(seed: int) -> tuple[MDP, np.ndarray, np.ndarray]:
    """4-7 states: goal, truncated (``extra``) and sink states absorbing, the others 1-3
    choices of 1-3 successors anywhere (self-loops and cycles: end components), each
    probability at least 0.1 / 3.3 of its row."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(4, 8))
    kind = rng.integers(0, 6, n)
    goal, extra, sink = kind == 0, kind == 1, kind == 2
    goal[n - 1], extra[n - 1], sink[n - 1] = True, False, False
    goal[0] = extra[0] = sink[0] = False
    dense, groups = [], [0]
    for s in range(n):
        if goal[s] or extra[s] or sink[s]:
            rows = [np.eye(n)[s]]
        else:
            rows = []
            for _ in range(int(rng.integers(1, 4))):
                row = np.zeros(n)
                cs = np.unique(rng.integers(0, n, int(rng.integers(1, 4))))
                p = rng.random(cs.size) + 0.1
                row[cs] = p / p.sum()
                rows.append(row)
        dense += rows
        groups.append(groups[-1] + len(rows))
    matrix = sp.csr_array(np.array(dense))
    mdp = MDP(matrix=matrix, row_groups=np.asarray(groups, dtype=np.int64),
              choice_actions=np.zeros(groups[-1], dtype=np.int32), action_names=(),
              initial=0, target=goal | extra, sink=sink, truncated=extra, states=range(n))
    return mdp, goal, extra


def _chain_value(p: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The probability of reaching ``target`` in the chain ``p`` (dense, rows summing to
    at most 1): 0 where no path, a linear solve elsewhere."""
    n = p.shape[0]
    reach = target.copy()
    while True:  # the Boolean closure of one-step predecessors
        more = reach | ((p > 0).astype(int) @ reach.astype(int) > 0)
        if np.array_equal(more, reach):
            break
        reach = more
    out = np.zeros(n)
    out[target] = 1.0
    live = reach & ~target
    if live.any():
        a = np.eye(int(live.sum())) - p[np.ix_(live, live)]
        out[live] = np.linalg.solve(a, p[np.ix_(live, target)].sum(axis=1))
    return out


def _policies(groups: np.ndarray):
    return itertools.product(*[range(int(a), int(b)) for a, b in
                               zip(groups[:-1], groups[1:], strict=True)])


def _brute(mdp: MDP, target: np.ndarray, sense: Sense) -> np.ndarray:
    """The optimum of reaching ``target`` from each state over every positional policy."""
    dense = mdp.matrix.toarray()
    best = None
    for pol in _policies(np.asarray(mdp.row_groups)):
        v = _chain_value(dense[list(pol)], target)
        best = v if best is None else (np.maximum(best, v) if sense is Sense.MAX
                                       else np.minimum(best, v))
    return best


def _quotient_optimum(q, sense: Sense) -> np.ndarray:
    """The optimum on the quotient over its positional policies: each a regular system
    ``(I - M) v = to_target`` (no end component is left in it)."""
    n = q.row_groups.shape[0] - 1
    if n == 0:
        return np.zeros(0)
    m = q.matrix.toarray()
    best = None
    for pol in _policies(q.row_groups):
        rows = list(pol)
        v = np.linalg.solve(np.eye(n) - m[rows], q.to_target[rows])
        best = v if best is None else (np.maximum(best, v) if sense is Sense.MAX
                                       else np.minimum(best, v))
    return best


@pytest.mark.parametrize("sense", [Sense.MIN, Sense.MAX])
@pytest.mark.parametrize("seed", range(40))
def test_analysis_against_brute_force(seed: int, sense: Sense) -> None:
    mdp, goal, extra = _random_mdp(seed)
    quotients = analyse(mdp, goal, extra, sense=sense)
    dense = mdp.matrix.toarray()
    for q, target in zip(quotients, [goal, goal | extra], strict=True):
        want = _brute(mdp, target, sense)
        # the graph's sets: exactly the brute force's zeros and ones
        assert np.array_equal(q.qualitative.zero, want == 0.0)
        assert np.array_equal(q.qualitative.one, want > 1.0 - 1e-12)
        assert np.array_equal(q.prob0, want == 0.0)
        # the numbers: the quotient's optimum lifted
        v = _quotient_optimum(q, sense)
        got = q.lift(v)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
        # the lifted greedy policy, evaluated in the product's own chain, is optimal
        # from every state whose value the graph did not decide as 0
        policy = lift_policy(mdp, q, greedy_choices(q, v) if v.size else
                             np.zeros(0, dtype=np.int64))
        value = _chain_value(dense[policy], target)
        undecided = ~q.qualitative.zero
        np.testing.assert_allclose(value[undecided], want[undecided], rtol=0, atol=1e-9)


def _assert_none(mecs: EndComponents, n: int, n_choices: int) -> None:
    assert mecs.n_mecs == 0
    assert mecs.mec_of.shape == (n,) and mecs.internal.shape == (n_choices,)
    assert bool(np.all(mecs.mec_of == -1)) and not bool(np.any(mecs.internal))
    assert mecs.mec_of.strides == (0,) and mecs.internal.strides == (0,)  # nothing a state
    with pytest.raises(ValueError):
        mecs.mec_of[0] = 3
    with pytest.raises(ValueError):
        mecs.internal[0] = True


@pytest.mark.parametrize("seed", range(20))
def test_minimum_holds_no_end_component_record(seed: int) -> None:
    """A minimum's quotients hold the stride-0 record of none (its maybe states have no
    end component: the brute force's check, a positional policy that stays among them
    for ever from some state, would make that state's value 0)."""
    mdp, goal, extra = _random_mdp(seed)
    for q in analyse(mdp, goal, extra, sense=Sense.MIN):
        _assert_none(q.mecs, mdp.n_states, mdp.n_choices)


def test_maximum_without_end_component_holds_the_record() -> None:
    """A maximum on an acyclic product (no end component among its maybe states) holds
    the record of none too; one with a two-state end component holds a real one."""
    # 0 -a-> {1: .5, goal 2: .5}, 0 -b-> {goal: .3, sink 3: .7}; 1 -> goal: acyclic
    dense = np.array([[0, .5, .5, 0], [0, 0, .3, .7], [0, 0, 1, 0], [0, 0, 1, 0],
                      [0, 0, 0, 1]], dtype=float)
    groups = np.array([0, 2, 3, 4, 5])
    mdp = MDP(matrix=sp.csr_array(dense), row_groups=groups,
              choice_actions=np.zeros(5, dtype=np.int32), action_names=(), initial=0,
              target=np.array([0, 0, 1, 0], bool), sink=np.array([0, 0, 0, 1], bool),
              truncated=np.zeros(4, bool), states=range(4))
    q, _ = analyse(mdp, mdp.target, sense=Sense.MAX)
    _assert_none(q.mecs, 4, 5)
    # 0 <-> 1 (a two-state end component), 1 may also go to the goal 2 or the sink 3
    dense = np.array([[0, 1, 0, 0], [1, 0, 0, 0], [0, .5, .25, .25], [0, 0, 1, 0],
                      [0, 0, 0, 1]], dtype=float)
    mdp = MDP(matrix=sp.csr_array(dense), row_groups=np.array([0, 1, 3, 4, 5]),
              choice_actions=np.zeros(5, dtype=np.int32), action_names=(), initial=0,
              target=np.array([0, 0, 1, 0], bool), sink=np.array([0, 0, 0, 1], bool),
              truncated=np.zeros(4, bool), states=range(4))
    q, _ = analyse(mdp, mdp.target, sense=Sense.MAX)
    assert q.mecs.n_mecs == 1
    assert q.mecs.mec_of.tolist() == [0, 0, -1, -1]
    assert q.mecs.internal.tolist() == [True, True, False, False, False]
    want = _brute(mdp, mdp.target, Sense.MAX)
    np.testing.assert_allclose(q.lift(_quotient_optimum(q, Sense.MAX)), want, atol=1e-12)
    # by hand: from 1, leaving by its second choice, x = .5 x + .25, so 1/2; 0 moves to 1
    assert want[0] == pytest.approx(0.5) and want[1] == pytest.approx(0.5)
