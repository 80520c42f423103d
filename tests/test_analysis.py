"""The one graph analysis both truncation models share (mitld_lp.solvers.analysis),
checked against references written differently: reachability by boolean matrix
closure, end components by the naive refinement of test_mdp, values by dense value
iteration on the raw MDP, components by scipy on the dense quotient graph."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse import csgraph
from test_mdp import naive_mecs

from mitld_lp.mdp import MDP
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.testing import random_mdp


def _split(mdp: MDP, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The random MDP's targets split into a goal and an 'extra' (truncated) set."""
    rng = np.random.default_rng(seed)
    extra = mdp.target & (rng.random(mdp.n_states) < 0.5)
    return mdp.target & ~extra, extra


def _can_reach(mdp: MDP, seeds: np.ndarray) -> np.ndarray:
    """States with a path to ``seeds``: closure of the dense adjacency by squaring."""
    adj = np.zeros((mdp.n_states, mdp.n_states), dtype=bool)
    dense = mdp.matrix.toarray() > 0
    for s in range(mdp.n_states):
        adj[s] = dense[mdp.choices(s)].any(axis=0)
    reach = adj | np.eye(mdp.n_states, dtype=bool)
    for _ in range(int(np.ceil(np.log2(mdp.n_states))) + 1):
        reach = (reach.astype(np.int64) @ reach.astype(np.int64)) > 0
    return reach[:, seeds].any(axis=1)


def _dense_values(mdp: MDP, target: np.ndarray, sweeps: int = 20_000) -> np.ndarray:
    """Maximal reach probabilities by plain value iteration from 0 on the raw MDP."""
    p = mdp.matrix.toarray()
    v = target.astype(float)
    starts = mdp.row_groups[:-1]
    for _ in range(sweeps):
        v = np.where(target, 1.0, np.maximum.reduceat(p @ v, starts))
    return v


@pytest.mark.parametrize("seed", range(10))
def test_shared_analysis_matches_references(seed: int) -> None:
    mdp = random_mdp(40 + 5 * seed, seed=seed, target_fraction=0.15, sink_fraction=0.1,
                     self_loop_fraction=0.3, max_successors=3,
                     locality=None if seed % 2 else 4)
    goal, extra = _split(mdp, seed)
    low, high = analyse(mdp, goal, extra)
    wide = goal | extra
    assert np.array_equal(low.prob0, ~_can_reach(mdp, goal) & ~goal)
    assert np.array_equal(high.prob0, ~_can_reach(mdp, wide) & ~wide)
    maybe = ~wide & ~high.prob0
    assert np.array_equal(high.state_map >= 0, maybe)
    got = {frozenset(high.mecs.states_of(k).tolist()) for k in range(high.mecs.n_mecs)}
    assert got == naive_mecs(mdp, set(np.flatnonzero(maybe).tolist()))
    # one matrix for both; the lower model keeps the states that reach only `extra`
    assert low.matrix is high.matrix
    kept_zero = np.zeros(low.n_states, dtype=bool)
    kept_zero[low.state_map[maybe & low.prob0]] = True
    assert np.array_equal(low.zero, kept_zero) and not high.zero.any()
    # the order: components strongly connected, every edge between them going down
    order = high.order
    dense = (high.matrix.toarray() > 0)
    graph = np.zeros((high.n_states, high.n_states), dtype=bool)
    for r in range(high.n_states):
        graph[r] = dense[high.row_groups[r]:high.row_groups[r + 1]].any(axis=0)
    _, scc = csgraph.connected_components(sp.csr_array(graph.astype(float)),
                                          directed=True, connection="strong")
    same = order.component[:, None] == order.component[None, :]
    assert np.array_equal(same, scc[:, None] == scc[None, :])
    src, dst = np.nonzero(graph)
    cross = order.component[src] != order.component[dst]
    level = order.level[order.component]
    assert np.all(level[src[cross]] > level[dst[cross]])
    # values of both models, by the solvers on the shared quotients
    for q, target in ((low, goal), (high, wide)):
        want = _dense_values(mdp, target)
        it = interval_iteration(mdp, target, quotient=q, gap="max", progress=False)
        assert np.allclose(it.lower, want, atol=1e-8) and np.allclose(it.upper, want, atol=1e-8)
        lp = solve_lp(mdp, target, quotient=q, everywhere=True)
        assert lp.values is not None and np.allclose(lp.values, want, atol=1e-8)


def test_no_extra_gives_one_quotient() -> None:
    mdp = random_mdp(50, seed=3)
    low, high = analyse(mdp, mdp.target, np.zeros(mdp.n_states, dtype=bool))
    assert low is high and not low.zero.any()


def test_zero_entries_are_not_edges() -> None:
    # state 0 -> 1 with probability 0 stored explicitly: 0 cannot reach the target 1
    m = sp.csr_array((np.array([1.0, 0.0, 1.0, 1.0]), np.array([0, 1, 1, 2]),
                      np.array([0, 2, 3, 4])), shape=(3, 3))
    no = np.zeros(3, dtype=bool)
    mdp = MDP(matrix=m, row_groups=np.array([0, 1, 2, 3]),
              choice_actions=np.array([0, -1, -1], dtype=np.int32), action_names=("a",),
              initial=0, target=np.array([False, True, False]), sink=no, truncated=no,
              states=(0, 1, 2))
    low, _ = analyse(mdp, mdp.target)
    assert low.prob0[0] and low.initial == -1 and low.initial_value == 0.0


@pytest.mark.parametrize("seed", range(8))
def test_policy_evaluated_on_the_analysis_layers(seed: int) -> None:
    """A random policy's chain solved in the product's order (no decomposition of its
    own) gives the values of a dense solve of the chain."""
    from mitld_lp.mdp import absorbing_states
    from mitld_lp.solvers.certify import chain as policy_chain
    from mitld_lp.solvers.certify import rounding
    from mitld_lp.solvers.iteration import evaluate_policy

    mdp = random_mdp(60, seed=seed, self_loop_fraction=0.2, locality=None if seed % 2 else 5)
    low, _ = analyse(mdp, mdp.target)
    rng = np.random.default_rng(seed)
    lo, hi = mdp.row_groups[:-1], mdp.row_groups[1:]
    policy = lo + (rng.random(mdp.n_states) * (hi - lo)).astype(np.int64)
    policy[mdp.target | absorbing_states(mdp)] = -1
    p = mdp.matrix.toarray()
    chain = np.zeros((mdp.n_states, mdp.n_states))
    acting = policy >= 0
    chain[acting] = p[policy[acting]]
    reach = _can_reach_chain(chain, mdp.target)
    solve = acting & reach & ~mdp.target
    want = mdp.target.astype(float)
    sub = chain[np.ix_(solve, solve)]
    rhs = chain[np.ix_(solve, mdp.target)].sum(axis=1)
    want[solve] = np.linalg.solve(np.eye(int(solve.sum())) - sub, rhs)
    # the analysis's layers are the quotient's, -1 outside it: where every state the
    # chain solves has one they serve, else the chain is decomposed apart
    comp, level = (np.asarray(a) for a in low.layers)
    if bool(np.all(level[comp[solve]] >= 0)):
        got = evaluate_policy(mdp, mdp.target, policy, layers=low.layers)
        assert np.allclose(got, want, atol=1e-10)
    ch = policy_chain(mdp, mdp.target, policy, rounding(mdp.matrix), low.layers)
    assert np.allclose(np.asarray(ch.values)[solve], want[solve], atol=1e-10)
    assert np.allclose(evaluate_policy(mdp, mdp.target, policy), want, atol=1e-10)


def _can_reach_chain(chain: np.ndarray, target: np.ndarray) -> np.ndarray:
    reach = target.copy()
    for _ in range(chain.shape[0]):
        reach = reach | ((chain > 0) @ reach.astype(float) > 0)
    return reach


@pytest.mark.parametrize("seed", range(8))
def test_both_models_iterated_in_one_pass(seed: int) -> None:
    """interval_iterations on the two shared quotients: each model's bounds bracket its
    values (dense value iteration), within the tolerance, like each model alone."""
    from mitld_lp.solvers.iteration import interval_iterations

    mdp = random_mdp(50 + 5 * seed, seed=seed, target_fraction=0.15, sink_fraction=0.1,
                     self_loop_fraction=0.2, max_successors=3,
                     locality=None if seed % 2 else 4)
    goal, extra = _split(mdp, seed)
    low, high = analyse(mdp, goal, extra)
    both = interval_iterations(mdp, [low, high], gap="max", progress=False, tol=1e-9)
    for q, target, it in ((low, goal, both[0]), (high, goal | extra, both[1])):
        want = _dense_values(mdp, target)
        assert it.status.value == "optimal"
        assert np.all(it.lower <= want + 1e-12) and np.all(want <= it.upper + 1e-12)
        assert np.max(it.upper - it.lower) < 1e-9
        alone = interval_iteration(mdp, target, quotient=q, gap="max", progress=False)
        assert np.allclose(alone.lower, it.lower, atol=1e-9)
    with pytest.raises(ValueError, match="share their matrix"):
        other = analyse(mdp, goal)[0]
        interval_iterations(mdp, [low, other], progress=False)


@pytest.mark.parametrize("seed", range(6))
def test_walk_visits_each_state_once_below_before_above(seed: int) -> None:
    """Blocks.walk, the one level loop of the solvers: every state not skipped exactly
    once, split into single and non-trivial by scipy's components of the dense quotient
    graph, and every edge between components leads to a level walked earlier
    (downstream first) or later (upstream first)."""
    mdp = random_mdp(50 + 7 * seed, seed=seed, target_fraction=0.1, sink_fraction=0.1,
                     self_loop_fraction=0.3, max_successors=3,
                     locality=None if seed % 2 else 5)
    q, _ = analyse(mdp, mdp.target)
    n = q.n_states
    owner = np.repeat(np.arange(n), np.diff(q.row_groups))
    dense = np.zeros((n, n), dtype=bool)
    m = q.matrix.toarray() > 0
    for c in range(q.n_choices):
        dense[owner[c]] |= m[c]
    n_comp, comp = csgraph.connected_components(sp.csr_array(dense), directed=True,
                                                connection="strong")
    size = np.bincount(comp, minlength=n_comp)
    skip = np.random.default_rng(seed).random(n) < 0.2
    for upstream in (False, True):
        when = np.full(n, -1)
        for k, level in enumerate(q.order.walk(skip=skip, upstream_first=upstream)):
            assert np.array_equal(np.sort(level.states),
                                  np.sort(np.concatenate([level.single, level.rest])))
            assert (size[comp[level.single]] == 1).all()
            assert (size[comp[level.rest]] > 1).all()
            assert (when[level.states] == -1).all()
            when[level.states] = k
        assert np.array_equal(when >= 0, ~skip)
        src, dst = np.nonzero(dense)
        cross = (comp[src] != comp[dst]) & ~skip[src] & ~skip[dst]
        earlier = when[dst[cross]] < when[src[cross]]
        assert earlier.all() if not upstream else (~earlier).all()
