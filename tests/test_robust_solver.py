"""The robust solver on small interval MDPs written here: against a brute-force max-min
over the two extreme hazards per step (a finite-horizon recursion in plain Python),
against fixed laws in the band, and against today's solver when the band is a point."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.mdp import ABSORB
from mitld_lp.product.imdp import IntervalMDP, point_mdp, vertex_rows
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.result import Status
from mitld_lp.solvers.robust import (
    bellman_residual,
    robust_interval_iteration,
    robust_policy,
)
from mitld_lp.solvers.robust_graph import RobustGame
from mitld_lp.solvers.robust_lp import policy_lp


@dataclass
class World:
    """``choices[s]``: a list of ``(bands, branches)``; ``bands`` the ``(lo, hi)`` of each
    ambiguous event, ``branches[b]`` a dict successor -> probability (bit i of b: event
    i happened).  State 0 starts; ``goal`` is the target."""

    choices: list[list[tuple[list[tuple[float, float]], list[dict[int, float]]]]]
    goal: int


def to_imdp(w: World) -> IntervalMDP:
    n = len(w.choices)
    rows, cols, vals, lo, hi, actions = [], [], [], [], [], []
    branch_groups, band_groups, row_groups = [0], [0], [0]
    for s in range(n):
        for i, (bands, branches) in enumerate(w.choices[s]):
            for j, b in enumerate(branches):
                for t, p in b.items():
                    rows.append(branch_groups[-1] + j)
                    cols.append(t)
                    vals.append(p)
            branch_groups.append(branch_groups[-1] + len(branches))
            lo += [a for a, _ in bands]
            hi += [z for _, z in bands]
            band_groups.append(len(lo))
            actions.append(ABSORB if s == w.goal else i)
        row_groups.append(len(actions))
    target = np.zeros(n, bool)
    target[w.goal] = True
    return IntervalMDP(
        branches=sp.csr_array((vals, (rows, cols)), shape=(branch_groups[-1], n)),
        branch_groups=np.array(branch_groups, dtype=np.int64),
        band_groups=np.array(band_groups, dtype=np.int64),
        band_lo=np.array(lo, dtype=np.float64),
        band_hi=np.array(hi, dtype=np.float64),
        band_events=tuple(f"e{i}" for i in range(len(lo))),
        row_groups=np.array(row_groups, dtype=np.int64),
        choice_actions=np.array(actions, dtype=np.int32),
        action_names=tuple(f"a{i}" for i in range(max(len(c) for c in w.choices))),
        initial=0,
        target=target,
        sink=np.zeros(n, bool),
        truncated=np.zeros(n, bool),
        states=tuple(range(n)),
    )


def game_of(m: IntervalMDP) -> RobustGame:
    v = vertex_rows(m)
    return RobustGame(v.matrix, v.groups, m.row_groups)


def brute_force(w: World, horizon: int) -> list[float]:
    """``V_H(s) = max_c min_{h in corners} sum_b w_b(h) sum_t B_b(t) V_{H-1}(t)``,
    ``V_0 = [s == goal]``: the best probability of reaching the goal within ``horizon``
    steps against a nature picking extreme hazards at every step."""
    n = len(w.choices)
    v = [1.0 if s == w.goal else 0.0 for s in range(n)]
    for _ in range(horizon):
        new = []
        for s in range(n):
            if s == w.goal:
                new.append(1.0)
                continue
            best = 0.0
            for bands, branches in w.choices[s]:
                worst = 1.0
                for corner in itertools.product(*[(a, z) for a, z in bands]):
                    total = 0.0
                    for b, row in enumerate(branches):
                        weight = 1.0
                        for i, h in enumerate(corner):
                            weight *= h if (b >> i) & 1 else 1.0 - h
                        total += weight * sum(p * v[t] for t, p in row.items())
                    worst = min(worst, total)
                best = max(best, worst)
            new.append(best)
        v = new
    return v


def random_world(rng: np.random.Generator, n: int) -> World:
    goal = n - 1
    sink = n - 2
    choices = []
    for s in range(n):
        if s in (goal, sink):
            choices.append([([], [{s: 1.0}])])
            continue
        mine = []
        for _ in range(int(rng.integers(1, 4))):
            k = int(rng.integers(0, 3))
            bands = []
            for _ in range(k):
                a, z = sorted(rng.choice([0.0, 0.1, 0.3, 0.5, 0.8, 1.0], 2, replace=False))
                bands.append((float(a), float(z)))
            branches = []
            for _ in range(1 << k):
                succ = rng.choice(n, size=int(rng.integers(1, 3)), replace=False)
                p = rng.dirichlet(np.ones(succ.size))
                branches.append({int(t): float(q) for t, q in zip(succ, p, strict=True)})
            mine.append((bands, branches))
        choices.append(mine)
    return World(choices, goal)


@pytest.mark.parametrize("seed", range(12))
def test_robust_iteration_brackets_the_brute_force_max_min(seed: int) -> None:
    rng = np.random.default_rng(seed)
    w = random_world(rng, 7)
    m = to_imdp(w)
    game = game_of(m)
    it = robust_interval_iteration(game, m.target, tol=1e-10)
    assert it.status is Status.OPTIMAL
    deep = brute_force(w, 3000)
    for s in range(len(w.choices)):
        # V_H rises to the robust value; it never exceeds the upper bound
        assert deep[s] <= it.upper[s] + 1e-9
        assert it.lower[s] - 1e-7 <= deep[s] + 1e-7
        assert abs(deep[s] - it.lower[s]) <= 1e-6, (s, deep[s], it.lower[s], it.upper[s])
    # the policy read off the lower bound guarantees the robust value (LP and Bellman)
    policy = robust_policy(game, m.target, it.lower, tie=1e-9)
    lp = policy_lp(game, m.target, policy)
    assert lp.status is Status.OPTIMAL and lp.values is not None
    assert np.all(lp.values <= it.upper + 1e-7)
    assert abs(lp.values[0] - it.lower[0]) <= 1e-6
    assert bellman_residual(game, m.target, lp.values) <= 1e-6
    ev = robust_interval_iteration(game.restrict(policy), m.target, tol=1e-10)
    np.testing.assert_allclose(ev.lower, lp.values, atol=1e-6)


def test_nature_trap_needs_deflation() -> None:
    # State 0: "wait" loops on 0 with the event (hazard in [0, 0.5]) leading to the goal;
    # "go" reaches the goal with probability 0.4.  Nature sets the hazard to 0: waiting
    # may last for ever, so the robust value is 0.4 (an upper bound stuck at 1 without
    # deflation).
    w = World([
        [([(0.0, 0.5)], [{0: 1.0}, {2: 1.0}]), ([], [{2: 0.4, 1: 0.6}])],
        [([], [{1: 1.0}])],
        [([], [{2: 1.0}])],
    ], goal=2)
    m = to_imdp(w)
    it = robust_interval_iteration(game_of(m), m.target, tol=1e-12)
    assert it.lower[0] == pytest.approx(0.4) and it.upper[0] == pytest.approx(0.4)
    policy = robust_policy(game_of(m), m.target, it.lower, tie=1e-9)
    assert policy[0] == 1  # "go"


def test_single_event_interval_minimum_is_the_sorted_one() -> None:
    # One ambiguous event, hazard in [0.2, 0.6].  Not happening (branch 0) loses (state
    # 3); happening (branch 1) leads to state 1, worth 0.25.  The interval distribution
    # is P(happen) in [0.2, 0.6], P(not) in [0.4, 0.8]; its minimum (by sorting the
    # successors by value) gives the worse successor the most mass: 0.8 * 0 + 0.2 * 0.25.
    w = World([
        [([(0.2, 0.6)], [{3: 1.0}, {1: 1.0}])],
        [([], [{2: 0.25, 3: 0.75}])],
        [([], [{2: 1.0}])],
        [([], [{3: 1.0}])],
    ], goal=2)
    m = to_imdp(w)
    it = robust_interval_iteration(game_of(m), m.target, tol=1e-12)
    assert it.lower[0] == pytest.approx(0.2 * 0.25)
    assert it.upper[0] == pytest.approx(0.2 * 0.25)


@pytest.mark.parametrize("seed", range(6))
def test_point_band_is_todays_answer(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    w = random_world(rng, 8)
    for bands, _ in (c for cs in w.choices for c in cs):
        for i, (a, _) in enumerate(bands):
            bands[i] = (a, a)
    m = to_imdp(w)
    v = vertex_rows(m)
    # one vertex row per choice: the point MDP; its optimum by today's solver
    rows = sp.csr_array(v.matrix[v.groups[:-1]])
    mdp = point_mdp(m, rows)
    today = interval_iteration(mdp, m.target, tol=1e-12)
    it = robust_interval_iteration(game_of(m), m.target, tol=1e-12)
    np.testing.assert_allclose(it.lower, today.lower, atol=1e-10)
    np.testing.assert_allclose(it.upper, today.upper, atol=1e-10)


@pytest.mark.parametrize("seed", range(6))
def test_robust_value_is_at_most_every_fixed_law(seed: int) -> None:
    rng = np.random.default_rng(200 + seed)
    w = random_world(rng, 7)
    m = to_imdp(w)
    robust = robust_interval_iteration(game_of(m), m.target, tol=1e-10)
    for _ in range(5):
        h = m.band_lo + rng.random(m.band_lo.size) * (m.band_hi - m.band_lo)
        fixed = replace(m, band_lo=h, band_hi=h)
        v = vertex_rows(fixed)
        mdp = point_mdp(m, sp.csr_array(v.matrix[v.groups[:-1]]))
        opt = interval_iteration(mdp, m.target, tol=1e-10)
        assert robust.lower[0] <= opt.upper[0] + 1e-9
