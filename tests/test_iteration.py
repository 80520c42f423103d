"""Interval iteration and exact policy evaluation against hand values."""

from __future__ import annotations

import numpy as np
import pytest
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
    mdp = build_mdp([[("a", {1: 1.0})], []], initial=1, target=[1])
    r = interval_iteration(mdp, mdp.target, progress=False)
    assert r.iterations == 0 and r.value_lower == r.value_upper == 1.0
    assert r.lower[0] == 0.0 and r.upper[0] == 1.0  # not refined, still sound


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
    np.testing.assert_allclose(direct, iterative, atol=1e-11)


def test_evaluate_policy_rejects_bad_policies() -> None:
    with pytest.raises(ValueError, match="not owned"):
        evaluate_policy(HAND, HAND.target, np.array([2, 2, -1, -1, 6, 8, 9]))
    with pytest.raises(ValueError, match="stop"):
        evaluate_policy(HAND, HAND.target, np.array([-1, 2, -1, -1, 6, 8, 9]))
    with pytest.raises(ValueError, match="shape"):
        evaluate_policy(HAND, HAND.target, np.array([0]))
