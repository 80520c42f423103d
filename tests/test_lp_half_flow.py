"""The LP stage's leaner paths (lp-half): a level settled whole by the greedy policy
pushes its flow out along its exits only (``lp_blocks.Walked``), the greedy answer's
weights are written where they go, the bounds are read at the block's states by the
check itself, the start weights are made for the flow only, and the product state of
each reduced choice is spread over the plain states (``lp._origin_states``).

Checked against routes that share none of that code: the optimal reach probability by
SciPy's HiGHS on the value LP of the original MDP (``min sum v`` subject to ``v(s) >=
r(c) + sum P(c, s') v(s')``, whose optimum is the least fixed point, the maximum); the
returned deterministic policy's own reach probability by a sparse solve of its chain;
the occupancy by its flow-conservation equations; the choices' states by the product's
``choice_state``."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog

from mitld_lp.solvers import lp as lp_mod
from mitld_lp.solvers import lp_blocks, shared_levels
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.greedy_block import certified_greedy
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.quotient import reduce
from mitld_lp.solvers.topological import Block
from mitld_lp.testing import random_mdp


def _highs_max_reach(mdp) -> np.ndarray:
    """The maximal probability of reaching ``mdp.target`` from every state, by HiGHS on
    the value LP over the original states (targets fixed to 1)."""
    n = mdp.n_states
    m = mdp.matrix.tocoo()
    owner = mdp.choice_state()
    # r(c) + P(c, .) v - v(owner) <= 0, as A_ub v <= -r with targets' values moved out
    target = np.asarray(mdp.target, dtype=bool)
    rows = np.concatenate([m.row, np.arange(mdp.n_choices)])
    cols = np.concatenate([m.col, owner])
    vals = np.concatenate([m.data, -np.ones(mdp.n_choices)])
    a = sp.csr_array((vals, (rows, cols)), shape=(mdp.n_choices, n))
    got = linprog(np.ones(n), A_ub=a, b_ub=np.zeros(mdp.n_choices),
                  bounds=[(1.0, 1.0) if t else (0.0, 1.0) for t in target],
                  method="highs")
    assert got.status == 0, got.message
    return got.x


def _policy_reach(mdp, policy: np.ndarray) -> np.ndarray:
    """The reach probability of the deterministic ``policy`` (a product choice a state,
    -1 where it does not matter) from every state: the chain's states that can reach
    the target solved by one sparse LU, the others 0."""
    target = np.asarray(mdp.target, dtype=bool)
    pick = np.where(policy >= 0, policy, np.asarray(mdp.row_groups[:-1]))
    chain = sp.csr_array(mdp.matrix[pick])
    can = target.copy()  # backward reachability in the chain's graph
    graph = sp.csr_array(chain != 0)
    while True:
        grown = can | (graph @ can.astype(np.float64) > 0)
        if np.array_equal(grown, can):
            break
        can = grown
    solve = np.flatnonzero(can & ~target)
    x = target.astype(np.float64)
    if solve.size:
        q = chain[solve][:, solve]
        rhs = chain[solve] @ target.astype(np.float64)
        x[solve] = sp.linalg.spsolve(sp.csc_array(sp.eye_array(solve.size) - q), rhs)
    return x


def _reduced_flow_residual(q, y: np.ndarray, b: np.ndarray) -> float:
    """``max |E y - P^T y - b|`` on the quotient: the occupancy's conservation."""
    owner = np.repeat(np.arange(q.n_states), np.diff(q.row_groups))
    out = np.bincount(owner, weights=y, minlength=q.n_states)
    inflow = q.matrix.T @ y
    return float(np.max(np.abs(out - inflow - b), initial=0.0))


@pytest.mark.parametrize("everywhere", [False, True])
@pytest.mark.parametrize("seed", range(5))
def test_greedy_levels_against_highs_and_the_policy_chain(
        seed: int, everywhere: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every block by the greedy check and every walk by runs (the new paths taken on
    small MDPs): the value, every state's value (``everywhere``) and the policy's own
    reach probability agree with HiGHS; the occupancy conserves flow; the levels settled
    whole pushed their flow out through their exits."""
    monkeypatch.setattr(lp_blocks, "GREEDY_MIN_CHOICES", 0)
    monkeypatch.setattr(lp_blocks, "RUNS_MIN_LEVELS", 1)
    monkeypatch.setattr(shared_levels, "RUNS_MIN_LEVELS", 1)
    pushes = []
    push = lp_blocks.Walked.push
    monkeypatch.setattr(lp_blocks.Walked, "push",
                        lambda self, *a: (pushes.append(self.row.size), push(self, *a)))
    mdp = random_mdp(70, seed=300 + seed, max_choices=3, target_fraction=0.08,
                     self_loop_fraction=0.05, locality=12)
    it = interval_iteration(mdp, mdp.target, gap="max", tol=1e-12, precision=None,
                            progress=False)
    got = solve_lp(mdp, mdp.target, everywhere=everywhere, bounds=(it.lower, it.upper))
    assert got.status.value == "optimal"
    assert all(rows >= 0 for rows in pushes)
    want = _highs_max_reach(mdp)
    assert abs(got.value - want[mdp.initial]) <= 1e-7
    policy_value = _policy_reach(mdp, np.asarray(got.policy))
    assert abs(policy_value[mdp.initial] - want[mdp.initial]) <= 1e-7
    q = reduce(mdp, mdp.target)
    if everywhere:
        kept = np.flatnonzero(q.state_map >= 0)
        np.testing.assert_allclose(np.asarray(got.values)[kept], want[kept], atol=1e-7)
        np.testing.assert_allclose(policy_value[kept], want[kept], atol=1e-7)
    if q.n_states:
        y = np.asarray(got.occupancy)[q.choice_origin]
        b = (np.ones(q.n_states) if everywhere else
             np.eye(1, q.n_states, max(q.initial, 0)).ravel() * (q.initial >= 0))
        assert _reduced_flow_residual(q, y, b) <= 1e-9 * max(1.0, float(np.max(y)))


def test_some_level_is_settled_whole_by_its_walk(monkeypatch: pytest.MonkeyPatch) -> None:
    """The seeds above include levels the greedy policy settles whole (so the exits'
    push runs, with exits), not only blocks the solver takes."""
    monkeypatch.setattr(lp_blocks, "GREEDY_MIN_CHOICES", 0)
    pushed = []
    push = lp_blocks.Walked.push
    monkeypatch.setattr(lp_blocks.Walked, "push",
                        lambda self, *a: (pushed.append(self.row.size), push(self, *a)))
    for seed in range(5):
        mdp = random_mdp(70, seed=300 + seed, max_choices=3, target_fraction=0.08,
                         self_loop_fraction=0.05, locality=12)
        it = interval_iteration(mdp, mdp.target, gap="max", tol=1e-12, precision=None,
                                progress=False)
        solve_lp(mdp, mdp.target, everywhere=True, bounds=(it.lower, it.upper))
    assert pushed and max(pushed) > 0


@pytest.mark.parametrize("seed", range(6))
def test_origin_states_are_the_products(seed: int) -> None:
    """The product state of every reduced choice, end components collapsed or not, is
    the one the product's own ``choice_state`` gives."""
    mdp = random_mdp(120, seed=500 + seed, max_choices=3, self_loop_fraction=0.3,
                     locality=6)
    for sense in (Sense.MAX, Sense.MIN):
        q = reduce(mdp, mdp.target, sense=sense)
        got = lp_mod._origin_states(mdp, q, q.choice_origin)
        want = mdp.choice_state()[np.asarray(q.choice_origin, dtype=np.int64)]
        np.testing.assert_array_equal(got, want)
    assert reduce(mdp, mdp.target).mecs.n_mecs > 0 or seed  # some seed has end components


@pytest.mark.parametrize("seed", range(4))
def test_bounds_read_at_the_block_are_the_callers_slice(seed: int) -> None:
    """``of_quotient=True`` reads the quotient's bounds at the block's states: the same
    answer as the caller's slice; the weights are the chosen choices' one-hot."""
    mdp = random_mdp(60, seed=700 + seed, max_choices=4, target_fraction=0.1)
    q = reduce(mdp, mdp.target)
    if q.n_states < 2:
        pytest.skip("nothing left to solve")
    it = interval_iteration(mdp, mdp.target, quotient=q, tol=1e-12, precision=None,
                            gap="max", progress=False)
    kept = np.flatnonzero(q.state_map >= 0)
    lower = np.zeros(q.n_states)
    lower[q.state_map[kept]] = it.lower[kept]
    states = np.arange(1, q.n_states)  # not the whole quotient: a real slice
    block = Block.of(q, states)
    reward = block.to_target + block.outer @ lower
    a = certified_greedy(block, reward, lower[states], Sense.MAX, 1e-9, None)
    b = certified_greedy(block, reward, lower, Sense.MAX, 1e-9, None, of_quotient=True)
    assert (a is None) == (b is None)
    if a is None:
        return
    np.testing.assert_array_equal(a.chosen, b.chosen)
    assert a.values.tobytes() == b.values.tobytes()
    w = b.weights
    assert w.shape == (block.choices.size,) and w.sum() == states.size
    assert np.all(w[b.chosen] == 1.0)
