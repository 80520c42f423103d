"""The states of value 1 (a minimum's ``Prob1A``, a maximum's ``Prob1E``) out of the
quotient (:func:`~mitld_lp.solvers.analysis.analyse`), checked against exact values: on
random MDPs of 3-6 states (with cycles and without, with and without truncated states)
every deterministic policy is evaluated in fractions, and the optimum of each state is
the least (the greatest) of them.  The states the quotient removes beside the target
and the value-0 states are exactly those whose optimum is 1 for the goal (end
components of them among them, for a maximum); every solver's values there are 1; the
lifted policy is a valid choice there and, evaluated exactly, reaches the target with
probability exactly 1 there and is optimal within the tolerance everywhere.  The step
objectives do not read the quotient: a ``--then min-steps`` answer on a world whose
states all have the minimum 1 is the hand-counted one."""

from __future__ import annotations

import itertools
from fractions import Fraction

import numpy as np
import pytest
from test_analysis_half_quotient import as_mdp

from mitld_lp.mdp import MDP
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.quotient import maximal_end_components, prob0_max
from mitld_lp.testing.exact import chain_values

SEEDS = range(30)


def _draw(seed: int, acyclic: bool, truncated: bool
          ) -> tuple[MDP, list[list[Fraction]], list[int], np.ndarray, np.ndarray]:
    """3-6 states; the last absorbing (the goal), with ``truncated`` the one before it
    absorbing too (the truncated set); every other state 1-2 choices of 1-3 successors
    with integer weights 1-4 (exact fractions beside the floats), only to higher states
    when ``acyclic``; a state may also loop on itself alone (a choice that avoids the
    goal for ever)."""
    rng = np.random.default_rng(7000 + seed)
    n = int(rng.integers(3, 7))
    absorbing = 2 if truncated else 1
    rows: list[list[Fraction]] = []
    owner: list[int] = []
    for s in range(n):
        for _ in range(1 if s >= n - absorbing else int(rng.integers(1, 3))):
            w = [0] * n
            if s >= n - absorbing or rng.random() < 0.1:
                w[s] = 1
            else:
                low = s + 1 if acyclic else 0
                k = int(rng.integers(1, min(3, n - low) + 1))
                for t in rng.choice(np.arange(low, n), k, replace=False):
                    w[int(t)] = int(rng.integers(1, 5))
            total = sum(w)
            rows.append([Fraction(x, total) for x in w])
            owner.append(s)
    mdp = as_mdp(np.array([[float(x) for x in r] for r in rows]), owner, truncated)
    return mdp, rows, owner, np.asarray(mdp.target & ~mdp.truncated), np.asarray(mdp.truncated)


def _policy_values(rows: list[list[Fraction]], policy: list[int], target: np.ndarray
                   ) -> list[Fraction]:
    """The exact probability of reaching ``target`` from each state under the
    deterministic ``policy`` (a row per state): 0 where the chain cannot reach it, else
    :func:`~mitld_lp.testing.exact.chain_values` (the target merged into one state)."""
    n = target.size
    reach = set(np.flatnonzero(target).tolist())
    grew = True
    while grew:
        grew = False
        for s in range(n):
            if s not in reach and any(rows[policy[s]][t] > 0 for t in reach):
                reach.add(s)
                grew = True
    step: dict[int, dict[int, Fraction]] = {}
    for s in range(n):
        step[s] = {}
        for t, p in enumerate(rows[policy[s]]):
            if p:
                key = -1 if target[t] else t
                step[s][key] = step[s].get(key, Fraction(0)) + p
    unknown = [s for s in range(n) if s in reach and not target[s]]
    solved = chain_values(step, unknown, -1)
    return [Fraction(1) if target[s] else solved.get(s, Fraction(0)) for s in range(n)]


def _optimum(rows: list[list[Fraction]], owner: list[int], target: np.ndarray,
             sense: Sense) -> list[Fraction]:
    """Each state's exact optimum over every deterministic policy."""
    n = target.size
    choices = [[c for c, o in enumerate(owner) if o == s] for s in range(n)]
    pick = min if sense is Sense.MIN else max
    values = [_policy_values(rows, list(p), target) for p in itertools.product(*choices)]
    return [pick(v[s] for v in values) for s in range(n)]


@pytest.mark.parametrize("truncated", [False, True])
@pytest.mark.parametrize("acyclic", [False, True])
@pytest.mark.parametrize("sense", [Sense.MIN, Sense.MAX])
def test_value_one_sets_and_what_leaves_the_quotient(sense: Sense, acyclic: bool,
                                                     truncated: bool) -> None:
    removed_seen = in_components = 0
    for seed in SEEDS:
        mdp, rows, owner, goal, extra = _draw(seed, acyclic, truncated)
        low, high = analyse(mdp, goal, extra, sense=sense)
        if sense is Sense.MAX:  # the end components the analysis finds before removing
            maybe = ~prob0_max(mdp, goal | extra) & ~goal & ~extra
            in_components += int(np.count_nonzero(
                (np.asarray(maximal_end_components(mdp, maybe).mec_of) >= 0)
                & (np.asarray(low.state_map) < 0)))
        for q, target in ((low, goal), (high, goal | extra)):
            exact = _optimum(rows, owner, target, sense)
            one = np.array([v == 1 for v in exact])
            zero = np.array([v == 0 for v in exact])
            assert np.array_equal(np.asarray(q.qualitative.one), one), seed
            assert np.array_equal(np.asarray(q.qualitative.zero), zero), seed
            gone = (np.asarray(q.state_map) < 0) & ~target & ~np.asarray(q.prob0)
            # removed: the goal's value-1 states (value 1 for the wider target too), and
            # in the lower model the truncated states (value 0 there)
            goal_one = np.array([v == 1 for v in _optimum(rows, owner, goal, sense)])
            assert np.array_equal(gone & ~extra, goal_one & ~goal), seed
            removed_seen += int((gone & ~extra).sum())
            # the lift gives them 1, every kept state its own value
            lifted = q.lift(np.full(q.n_states, 0.5))
            assert np.all(lifted[goal_one] == 1.0)
            assert np.all(lifted[np.asarray(q.state_map) >= 0] == 0.5)
            if q.initial < 0:
                assert q.initial_value == float(exact[int(mdp.initial)])
    assert removed_seen > 10  # the draws do exercise the removal
    if sense is Sense.MAX and not acyclic:
        assert in_components > 0  # and a collapsed end component's


@pytest.mark.parametrize("method", ["iteration", "lp"])
@pytest.mark.parametrize("acyclic", [False, True])
@pytest.mark.parametrize("sense", [Sense.MIN, Sense.MAX])
def test_lifted_policy_reaches_the_optimum(sense: Sense, method: str, acyclic: bool,
                                           ) -> None:
    """The policy lifted from the smaller quotient, evaluated exactly, is the optimum
    in every state within the tolerance, and exactly 1 on the removed value-1 states
    (a minimum's: any choice reaches the goal almost surely; a maximum's: the attractor
    strategy does); there it is a valid choice, and the solvers' values are 1."""
    removed_seen = 0
    for seed in SEEDS:
        mdp, rows, owner, goal, _ = _draw(seed, acyclic, False)
        exact = _optimum(rows, owner, goal, sense)
        q = analyse(mdp, goal, sense=sense)[0]  # the plain route's, value-1 states out
        if method == "iteration":
            got = interval_iteration(mdp, goal, quotient=q, sense=sense, gap="max",
                                     tol=1e-12)
            values = np.asarray(got.lower)
            assert np.all(np.asarray(got.upper) >= np.array([float(v) for v in exact])
                          - 1e-12)
        else:
            got = solve_lp(mdp, goal, quotient=q, sense=sense, everywhere=True)
            values = np.asarray(got.values)
        policy = np.asarray(got.policy)
        n = mdp.n_states
        one = np.array([v == 1 for v in exact]) & ~goal
        assert np.array_equal((np.asarray(q.state_map) < 0) & ~goal
                              & ~np.asarray(q.prob0), one), seed  # removed, all of them
        removed_seen += int(one.sum())
        groups = np.asarray(mdp.row_groups)
        lo, hi = groups[:-1], groups[1:]
        absorbing = goal  # the goal state is the only absorbing one here
        assert np.all((policy[~absorbing] >= lo[~absorbing])
                      & (policy[~absorbing] < hi[~absorbing])), seed
        assert np.all(values[one] == 1.0)
        played = _policy_values(rows, [int(c) if c >= 0 else int(lo[s])
                                       for s, c in enumerate(policy)], goal)
        assert all(played[s] == 1 for s in np.flatnonzero(one))  # exactly
        for s in range(n):
            assert float(played[s]) == pytest.approx(float(exact[s]), abs=1e-9), (seed, s)
            assert abs(values[s] - float(exact[s])) <= 1e-9, (seed, s)
    assert removed_seen > 10


def test_then_min_steps_counts_the_steps_of_value_one_states() -> None:
    """Every state reaches the goal almost surely whatever is played (value 1): the
    least expected steps still count the corridor's states; ``fast`` takes 1 step,
    ``slow`` 3, and ``retry`` (a coin of 1/2 back to ``a``) 2 in expectation: the hand
    count is 1, through ``fast``."""
    from mitld_lp.model import Model
    from mitld_lp.synthesis import synthesize_constrained
    from mitld_lp.worlds.game import ExplicitGame

    g = ExplicitGame(initial="a", transitions={
        "a": {"slow": {"c1": 1.0}, "fast": {"goal": 1.0}, "retry": {"a": 0.5, "goal": 0.5}},
        "c1": {"go": {"c2": 1.0}}, "c2": {"go": {"goal": 1.0}},
        "goal": {"wait": {"goal": 1.0}}}, labels={"goal": {"goal"}})
    r = synthesize_constrained(Model.from_game(g, "F goal"), [], then="min-steps")
    assert r.lower == pytest.approx(1.0, abs=1e-6)
    assert r.secondary == pytest.approx(1.0, abs=1e-6)


def test_a_stored_zero_is_not_an_edge_of_the_attractor_strategy() -> None:
    """A maximum's removed value-1 state whose best choice stores a zero toward a dead
    state (the sensed routes' chains keep such entries): the analysis's graph has no
    such edge, so its attractor strategy takes that choice (it reaches the goal with
    probability 1, the other choice with 1/2).  It once found no choice there and
    failed: the strategy read the zero as a way out of the value-1 states."""
    import scipy.sparse as sp

    from mitld_lp.solvers.quotient import lift_policy

    # states: 0 start, 1 dead (loops), 2 goal (absorbing); choices: 0 -> {2: 1, 1: 0},
    # 0 -> {1: 1/2, 2: 1/2}, 1 -> {1: 1}, 2 -> {2: 1}
    matrix = sp.csr_array((np.array([0.0, 1.0, 0.5, 0.5, 1.0, 1.0]),
                           np.array([1, 2, 1, 2, 1, 2]), np.array([0, 2, 4, 5, 6])),
                          shape=(4, 3))
    assert matrix.nnz == 6  # the zero is stored
    no = np.zeros(3, dtype=bool)
    mdp = MDP(matrix=matrix, row_groups=np.array([0, 2, 3, 4], dtype=np.int64),
              choice_actions=np.zeros(4, dtype=np.int32), action_names=(), initial=0,
              target=np.array([False, False, True]), sink=no, truncated=no,
              states=range(3))
    q = analyse(mdp, mdp.target, sense=Sense.MAX)[0]
    assert q.state_map[0] < 0 and q.qualitative.one[0]  # decided 1, removed
    policy = lift_policy(mdp, q, np.zeros(q.n_states, dtype=np.int64))
    assert policy[0] == 0  # the sure choice, not the coin
