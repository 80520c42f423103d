"""A maximum's strategy for the removed value-1 states, read from the analysis's own
attractor (:func:`~mitld_lp.solvers.analysis._attractor_strategy`) instead of a second
search in the lift: on random MDPs of 5-9 states with cycles (end components among the
value-1 states too), it covers exactly the states the nested fixpoint ``Prob1E``
(:func:`~mitld_lp.solvers.quotient.prob1_max`, written apart from the analysis) gives
less the goal, each state plays one of its own choices, and the lifted policy reaches
the goal with probability exactly 1 from each of them: in fractions
(:func:`~mitld_lp.testing.exact.chain_values`) and by the graph criterion of a finite
chain (every state it can reach, before the goal, can still reach the goal).  The
attractor's spared choices are the same on the compiled walk and the NumPy one."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp
from test_analysis_half_quotient import as_mdp

from mitld_lp.solvers import graph
from mitld_lp.solvers.analysis import ATTRACTOR_STRATEGY, analyse
from mitld_lp.solvers.graph import Sense, attractor_spared
from mitld_lp.solvers.quotient import lift_policy, maximal_end_components, prob0_max, prob1_max
from mitld_lp.solvers.walks import load_walks
from mitld_lp.testing.exact import chain_values


def _draw(seed: int, truncated: bool) -> tuple[np.ndarray, list[list[Fraction]], list[int]]:
    """5-9 states; the last the goal (absorbing), with ``truncated`` the one before it
    absorbing too; every other state 1-3 choices of 1-3 successors (integer weights
    1-3), drawn mostly among its neighbours (so that end components form), sometimes a
    loop on itself alone."""
    rng = np.random.default_rng(4500 + seed)
    n = int(rng.integers(5, 10))
    absorbing = 2 if truncated else 1
    rows: list[list[Fraction]] = []
    owner: list[int] = []
    for s in range(n):
        for _ in range(1 if s >= n - absorbing else int(rng.integers(1, 4))):
            w = [0] * n
            if s >= n - absorbing or rng.random() < 0.1:
                w[s] = 1
            else:
                near = [t for t in range(max(0, s - 2), min(n, s + 3))]
                pool = near if rng.random() < 0.7 else list(range(n))
                k = int(rng.integers(1, min(3, len(pool)) + 1))
                for t in rng.choice(pool, k, replace=False):
                    w[int(t)] = int(rng.integers(1, 4))
            total = sum(w)
            rows.append([Fraction(x, total) for x in w])
            owner.append(s)
    dense = np.array([[float(x) for x in r] for r in rows])
    return dense, rows, owner


def _reaches_surely(rows: list[list[Fraction]], policy: np.ndarray, goal: np.ndarray,
                    ) -> tuple[np.ndarray, list[Fraction]]:
    """Per state, whether the chain of ``policy`` reaches ``goal`` almost surely by the
    graph criterion, and its exact probability of reaching it (fractions)."""
    n = goal.size
    adj = np.eye(n, dtype=bool)  # the chain's steps (none out of the goal), reflexive
    for s in np.flatnonzero(~goal):
        adj[s, [t for t, p in enumerate(rows[int(policy[s])]) if p]] = True
    closure = adj
    while True:  # transitive closure by squaring
        wider = (closure.astype(np.int64) @ closure.astype(np.int64)) > 0
        if np.array_equal(wider, closure):
            break
        closure = wider
    can = closure[:, goal].any(axis=1)  # a path to the goal
    sure = np.array([bool(np.all(can[closure[s]])) for s in range(n)])
    step: dict[int, dict[int, Fraction]] = {}
    for s in np.flatnonzero(~goal).tolist():  # the goal's states merged into one, -1
        step[s] = {}
        for t, p in enumerate(rows[int(policy[s])]):
            if p:
                key = -1 if goal[t] else t
                step[s][key] = step[s].get(key, Fraction(0)) + p
    unknown = [s for s in range(n) if can[s] and not goal[s]]
    solved = chain_values(step, unknown, -1)
    return sure, [Fraction(1) if goal[s] else solved.get(s, Fraction(0)) for s in range(n)]


@pytest.mark.parametrize("truncated", [False, True])
def test_recorded_strategy_reaches_the_goal_almost_surely(truncated: bool) -> None:
    seen = in_components = 0
    for seed in range(40):
        dense, rows, owner = _draw(seed, truncated)
        mdp = as_mdp(dense, owner, truncated)
        goal = np.asarray(mdp.target & ~mdp.truncated)
        extra = np.asarray(mdp.truncated)
        low, high = analyse(mdp, goal, extra, sense=Sense.MAX)
        expected = prob1_max(mdp, goal) & ~goal
        assert low.shared is high.shared  # one record for both models
        if not expected.any():
            assert ATTRACTOR_STRATEGY not in low.shared, seed
            continue
        played = low.shared[ATTRACTOR_STRATEGY]
        states, choices = played.states, played.choices
        assert np.array_equal(states, np.flatnonzero(expected)), seed
        groups = np.asarray(mdp.row_groups)
        assert np.all((choices >= groups[states]) & (choices < groups[states + 1])), seed
        seen += states.size
        maybe = ~prob0_max(mdp, goal | extra) & ~goal & ~extra
        in_components += int(np.count_nonzero(
            np.asarray(maximal_end_components(mdp, maybe).mec_of)[states] >= 0))
        for q, target in ((low, goal), (high, goal | extra)):
            policy = lift_policy(mdp, q, np.asarray(q.row_groups[:-1], dtype=np.int64))
            assert np.array_equal(policy[states], choices), seed  # the recorded one
            played = np.where(policy >= 0, policy, groups[:-1])
            sure, exact = _reaches_surely(rows, played, target)
            assert np.all(sure[states]), seed
            assert all(exact[s] == 1 for s in states), seed
    assert seen > 40  # the draws do exercise the removal
    assert in_components > 0  # and end components among the removed states


def test_spared_choices_alike_compiled_and_not(monkeypatch: pytest.MonkeyPatch) -> None:
    """The attractor's spared choices (those never hit): the same on both walks, and
    each, of a state outside the set, has its support outside it; a state outside
    with a choice keeps at least one."""
    walks = load_walks()
    if walks is None:  # pragma: no cover - numba is a dependency of the venv
        pytest.skip("numba is not installed")
    rng = np.random.default_rng(11)
    for _ in range(30):
        n = int(rng.integers(4, 30))
        counts = rng.integers(0, 4, size=n)
        groups = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        n_choices = int(groups[-1])
        dense = (rng.random((n_choices, n)) < 0.15).astype(np.float64)
        dense[np.arange(n_choices), rng.integers(0, n, n_choices)] = 1.0
        matrix = sp.csr_array(dense / dense.sum(axis=1, keepdims=True))
        seeds = rng.random(n) < 0.15
        hit0 = rng.random(n_choices) < 0.1
        monkeypatch.setattr(graph, "compiled_walks", lambda entries: None)
        plain = attractor_spared(matrix, groups, seeds, hit0)
        monkeypatch.setattr(graph, "compiled_walks", lambda entries: walks)
        compiled = attractor_spared(matrix, groups, seeds, hit0)
        assert np.array_equal(plain[0], compiled[0])
        assert np.array_equal(plain[1], compiled[1])
        inside, hit = plain
        owner = np.repeat(np.arange(n), counts)
        spared = ~hit
        for c in np.flatnonzero(spared & ~inside[owner]):
            assert not inside[matrix.indices[matrix.indptr[c]:matrix.indptr[c + 1]]].any()
            assert not hit0[c]
        for s in np.flatnonzero(~inside & (counts > 0)):
            assert spared[groups[s]:groups[s + 1]].any()
