"""Interval iteration and exact policy evaluation against hand values."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from conftest import HAND, HAND_VALUES, build_mdp

from mitld_lp.solvers import Status, evaluate_policy, interval_iteration
from mitld_lp.testing import random_mdp


def test_interval_iteration_hand_values() -> None:
    r = interval_iteration(HAND, HAND.target, gap="max", progress=False)
    assert r.status == Status.OPTIMAL
    np.testing.assert_allclose(r.lower, HAND_VALUES, atol=1e-9)
    np.testing.assert_allclose(r.upper, HAND_VALUES, atol=1e-9)
    assert r.value_lower <= 0.25 <= r.value_upper
    assert np.all(r.lower <= r.upper)
    # The greedy policy leaves the MEC {1, 4} by 'd' and never loops at 0.
    np.testing.assert_allclose(evaluate_policy(HAND, HAND.target, r.policy), HAND_VALUES,
                               atol=1e-12)
    assert r.policy[0] == 1 and r.policy[4] == 7 and r.policy[1] == 3


def test_gap_at_initial_only_stops_early_but_bounds_stay_sound() -> None:
    r = interval_iteration(HAND, HAND.target, progress=False)
    assert r.status == Status.OPTIMAL
    assert r.value_upper - r.value_lower < 1e-9
    assert np.all(r.lower <= HAND_VALUES + 1e-12) and np.all(HAND_VALUES <= r.upper + 1e-12)


def test_iteration_limit_is_a_status_with_a_valid_bracket() -> None:
    # A slow leak: 0 'w' stays with 0.99, else target 0.005 / sink 0.005 -> Pmax 1/2.
    mdp = build_mdp([[("w", {0: 0.99, 1: 0.005, 2: 0.005})], [], []], target=[1], sink=[2])
    r = interval_iteration(mdp, mdp.target, max_iterations=10, progress=False,
                           topological=False)
    assert r.status == Status.MAX_ITERATIONS and r.iterations == 10
    assert r.value_lower < 0.5 < r.value_upper
    done = interval_iteration(mdp, mdp.target, tol=1e-10, progress=False, topological=False)
    assert done.status == Status.OPTIMAL
    assert done.value_lower == pytest.approx(0.5, abs=1e-10)
    # In topological order a single state with a self-loop is solved exactly:
    # v = 0.005 / (1 - 0.99), no sweep at all.
    exact = interval_iteration(mdp, mdp.target, max_iterations=10, progress=False)
    assert exact.status == Status.OPTIMAL and exact.iterations == 0
    assert exact.value_lower == exact.value_upper == pytest.approx(0.5, abs=1e-14)


def test_initial_decided_without_iterating() -> None:
    mdp = build_mdp([[("a", {1: 1.0}), ("b", {0: 0.5, 2: 0.5})], [], [("c", {0: 1.0})]],
                    initial=1, target=[1])
    r = interval_iteration(mdp, mdp.target, progress=False)
    assert r.iterations == 0 and r.value_lower == r.value_upper == 1.0
    # state 0 is not iterated: its value (1, by "a") is decided by the graph (Prob1E);
    # state 2 (value 1 too, by going back to 0) as well
    assert r.lower[0] == r.upper[0] == 1.0 and r.lower[2] == r.upper[2] == 1.0


@pytest.mark.parametrize("seed", range(6))
def test_random_bracket_contains_exact_policy_value(seed: int) -> None:
    mdp = random_mdp(150, seed=seed, locality=6, sink_fraction=0.1, self_loop_fraction=0.2)
    r = interval_iteration(mdp, mdp.target, gap="max", tol=1e-10, progress=False)
    exact = evaluate_policy(mdp, mdp.target, r.policy)
    # A policy's value is a lower bound on the optimum <= upper; greedy is optimal here.
    assert np.all(exact <= r.upper + 1e-9)
    np.testing.assert_allclose(exact, r.lower, atol=1e-8)


def test_evaluate_policy_by_hand() -> None:
    # Staying at 0 forever reaches nothing; 'go' then 'a' from 1: v1 = 0.3 + 0.7 v0,
    # v0 = 0.5 v1  ->  v1 = 0.3 / 0.65, v0 = 0.15 / 0.65.
    stay = np.array([0, 2, -1, -1, 6, 8, 9])
    np.testing.assert_allclose(evaluate_policy(HAND, HAND.target, stay)[[0, 6]], [0.0, 1.0])
    via_a = np.array([1, 2, -1, -1, 6, 8, 10])
    v = evaluate_policy(HAND, HAND.target, via_a)
    np.testing.assert_allclose(v[[0, 1, 4, 6]], [0.15 / 0.65, 0.3 / 0.65, 0.3 / 0.65, 0.0],
                               atol=1e-14)
    # The in-MEC loop b/c never leaves: value 0 although each state has a good exit.
    loop = np.array([1, 3, -1, -1, 6, 8, 9])
    assert evaluate_policy(HAND, HAND.target, loop)[1] == 0.0


def test_evaluate_policy_methods_agree() -> None:
    mdp = random_mdp(300, seed=5, locality=10)
    r = interval_iteration(mdp, mdp.target, gap="max", progress=False)
    direct = evaluate_policy(mdp, mdp.target, r.policy, method="direct")
    iterative = evaluate_policy(mdp, mdp.target, r.policy, method="iterative")
    by_blocks = evaluate_policy(mdp, mdp.target, r.policy)
    np.testing.assert_allclose(direct, iterative, atol=1e-11)
    np.testing.assert_allclose(direct, by_blocks, atol=1e-12)


def test_solve_chain_matches_one_factorisation() -> None:
    from mitld_lp.solvers.topological import graph_blocks, solve_chain

    # A random sub-stochastic chain with cycles of every size and self-loops.
    rng = np.random.default_rng(7)
    n = 400
    rows = np.repeat(np.arange(n), 3)
    cols = np.clip(rows + rng.integers(-4, 6, rows.size), 0, n - 1)
    q = sp.csr_array((rng.random(rows.size), (rows, cols)), shape=(n, n))
    q.sum_duplicates()
    q = sp.csr_array(sp.diags_array(0.97 / np.asarray(q.sum(axis=1)).ravel()) @ q)
    b = rng.random(n)
    ref = spla.spsolve(sp.csc_array(sp.eye_array(n) - q), b)
    np.testing.assert_allclose(solve_chain(q, b), ref, rtol=1e-11)
    blk = graph_blocks(sp.csr_array(q != 0, dtype=np.float64), q.diagonal())
    assert blk.n_levels > 1 and np.any(blk.size > 1) and np.any(blk.size == 1)


def test_evaluate_policy_rejects_bad_policies() -> None:
    with pytest.raises(ValueError, match="not owned"):
        evaluate_policy(HAND, HAND.target, np.array([2, 2, -1, -1, 6, 8, 9]))
    with pytest.raises(ValueError, match="stop"):
        evaluate_policy(HAND, HAND.target, np.array([-1, 2, -1, -1, 6, 8, 9]))
    with pytest.raises(ValueError, match="shape"):
        evaluate_policy(HAND, HAND.target, np.array([0]))


# ------------------------------------------------------------------------------------
# Topological order: slow components, time limits, agreement with the plain sweeps.
# ------------------------------------------------------------------------------------

EPS = 1e-6
# A two-state component left once in a million steps: 0 -> 1 or target (EPS), 1 -> 0 or
# sink (EPS).  By hand v0 = EPS + (1-EPS) v1, v1 = (1-EPS) v0, so v0 = 1 / (2 - EPS).
SLOW = build_mdp(
    [[("x", {1: 1 - EPS, 2: EPS})], [("y", {0: 1 - EPS, 3: EPS})], [], []],
    target=[2], sink=[3],
)


def slow_exact() -> tuple[Fraction, Fraction]:
    """v0, v1 of SLOW in exact arithmetic on the stored float probabilities (1 / (2 - EPS)
    is off by 1e-11: 1 - EPS is not a binary fraction)."""
    m = SLOW.matrix.toarray()
    v0 = Fraction(m[0, 2]) / (1 - Fraction(m[0, 1]) * Fraction(m[1, 0]))
    return v0, Fraction(m[1, 0]) * v0


def test_slowly_draining_component_converges() -> None:
    r = interval_iteration(SLOW, SLOW.target, gap="max", max_iterations=100_000,
                           progress=False)
    assert r.status == Status.OPTIMAL, r.message
    v0, v1 = slow_exact()
    assert float(v0) == pytest.approx(1 / (2 - EPS), abs=1e-10)
    assert Fraction(r.lower[0]) <= v0 <= Fraction(r.upper[0])
    assert Fraction(r.lower[1]) <= v1 <= Fraction(r.upper[1])
    assert r.upper[0] - r.lower[0] < 1e-9 and r.upper[1] - r.lower[1] < 1e-9


def test_geometric_one_in_a_million_event_converges() -> None:
    from mitld_lp import GridWorld, Model, synthesize

    world = GridWorld.make(3, 3, start=(0, 0), slip=0.1, regions={"A": [(1, 2)]})
    spec = "D[geometric(0.000001)] e & F(e & F[0,3] A)"
    result = synthesize(Model.from_game(world, spec), method="vi")
    mdp = result.mdp
    r = interval_iteration(mdp, mdp.target, max_iterations=100_000, progress=False)
    assert r.status == Status.OPTIMAL, r.message
    from mitld_lp.solvers import Layout, solve_lp

    highs = solve_lp(mdp, mdp.target, solver="HIGHS", layout=Layout.WHOLE)
    assert r.value_lower - 1e-8 <= highs.value <= r.value_upper + 1e-8
    # The default LP route: its block (the waiting layer, left once in a million steps)
    # comes back from Clarabel off by 0.15 and is made exact by policy iteration.
    lp = solve_lp(mdp, mdp.target)
    assert lp.status == Status.OPTIMAL, lp.message
    assert r.value_lower - 1e-9 <= lp.value <= r.value_upper + 1e-9
    assert lp.primal_objective == pytest.approx(lp.dual_objective, abs=1e-9)
    exact = evaluate_policy(mdp, mdp.target, r.policy)[mdp.initial]
    assert r.value_lower - 1e-12 <= exact <= r.value_upper + 1e-9
    assert result.certified


def test_time_limit_returns_the_bracket_so_far() -> None:
    for topological in (True, False):
        r = interval_iteration(SLOW, SLOW.target, time_limit=0.0, progress=False,
                               topological=topological)
        assert r.status == Status.TIME_LIMIT and "time limit" in r.message
        assert Fraction(r.value_lower) <= slow_exact()[0] <= Fraction(r.value_upper)


@pytest.mark.parametrize("seed", range(4))
def test_topological_and_plain_sweeps_agree(seed: int) -> None:
    mdp = random_mdp(200, seed=50 + seed, locality=4, self_loop_fraction=0.3)
    plain = interval_iteration(mdp, mdp.target, gap="max", topological=False,
                               progress=False)
    topo = interval_iteration(mdp, mdp.target, gap="max", progress=False)
    assert plain.status == topo.status == Status.OPTIMAL
    assert np.all(topo.lower <= plain.upper + 1e-12)
    assert np.all(plain.lower <= topo.upper + 1e-12)
    np.testing.assert_allclose(topo.lower, plain.lower, atol=2e-9)
