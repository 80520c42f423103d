"""The LP's randomised policy divided in place (lp._randomized, the LP stage's memory
peak): each choice's share of its state's occupancy where the state is visited, the
deterministic policy's choice at 1 elsewhere, against a loop state by state; and the
whole LP answer of a random MDP the same as the policy's share read from its occupancy."""

from __future__ import annotations

import numpy as np
from conftest import build_mdp
from test_single_levels import layered_mdp

from mitld_lp.solvers import lp as lp_mod
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.lp import solve_lp


def _mdp():
    # three states of two, one and three choices, then the goal and a dead end
    return build_mdp([
        [("a", {1: 0.5, 3: 0.5}), ("b", {2: 1.0})],
        [("a", {3: 1.0})],
        [("a", {3: 0.2, 4: 0.8}), ("b", {4: 1.0}), ("c", {3: 1.0})],
        [], []], target=[3], sink=[4])


def _by_loop(groups, occupancy, policy, threshold):
    out = []
    for s in range(groups.size - 1):
        ys = [float(occupancy[c]) for c in range(groups[s], groups[s + 1])]
        flow = sum(ys)  # the same order as bincount's (choices in order)
        for k, c in enumerate(range(groups[s], groups[s + 1])):
            if flow > threshold:
                out.append(ys[k] / flow)
            else:
                out.append(1.0 if policy[s] == c else 0.0)
    return np.array(out)


def test_the_randomised_policy_is_each_choices_share_of_its_state() -> None:
    mdp = _mdp()
    groups = np.asarray(mdp.row_groups)
    occupancy = np.array([0.3, 0.6, 0.9, 0.0, 0.0, 0.0, 1.0, 1.0])[:mdp.n_choices]
    occupancy[groups[2]:groups[3]] = [1e-12, 0.0, 0.0]  # under the visit threshold
    policy = np.full(mdp.n_states, -1)
    policy[2] = groups[2] + 2  # the deterministic choice where unvisited
    tol = 1e-9
    every, flow = lp_mod._occupancy(mdp, np.arange(mdp.n_choices), occupancy)
    assert np.array_equal(every, occupancy)
    got = lp_mod._randomized(mdp, every, flow, policy, tol)
    want = _by_loop(groups, occupancy, policy, lp_mod._visit_threshold(tol))
    assert got.dtype == np.float64
    assert np.array_equal(got, want)
    assert got[groups[2] + 2] == 1.0 and got[0] == 0.3 / (0.3 + 0.6) and got[1] == 0.6 / (0.3 + 0.6)


def test_the_lps_randomised_policy_is_its_occupancys_share() -> None:
    mdp, _, _ = layered_mdp(7, depth=10)
    tol = 1e-9
    lp = solve_lp(mdp, mdp.target, sense=Sense.MAX, everywhere=True, tol=tol)
    want = _by_loop(np.asarray(mdp.row_groups), lp.occupancy, lp.policy,
                    lp_mod._visit_threshold(tol))
    assert np.array_equal(lp.randomized, want)
    g = np.asarray(mdp.row_groups)
    s0 = int(mdp.initial)  # visited: its choices' shares add up to one
    assert abs(float(lp.randomized[g[s0]:g[s0 + 1]].sum()) - 1.0) < 1e-12
