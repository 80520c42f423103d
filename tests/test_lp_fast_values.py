"""The LP stage (solve_lp by blocks, the bounds' greedy policy tried on every block and
its dual check compiled) against independent routes: scipy's linprog (HiGHS) on the
value LP of random MDPs, and every deterministic policy of tiny MDPs evaluated by a
dense solve, the best taken state by state; the LP's policy attains the optimum."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.optimize import linprog

from mitld_lp.mdp import MDP
from mitld_lp.solvers import greedy_block, lp_blocks
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.testing import random_mdp


@pytest.fixture(autouse=True)
def _greedy_everywhere(monkeypatch: pytest.MonkeyPatch) -> None:
    """The greedy policy and its compiled check on these small blocks too."""
    from mitld_lp.util import kernel_loader

    try:
        kernel_loader.prepare()
    except ImportError:  # without numba the long double batches decide alone
        pass
    monkeypatch.setattr(lp_blocks, "GREEDY_MIN_CHOICES", 0)
    monkeypatch.setattr(greedy_block, "KERNEL_MIN_CHOICES", 0)


def _policy_values(mdp: MDP, policy: np.ndarray) -> np.ndarray:
    """Reach probability of ``mdp.target`` under the deterministic ``policy`` (a choice
    per state): 0 where the chain cannot reach the target, else the dense solve."""
    p = mdp.matrix.toarray()[policy]
    n = mdp.n_states
    stop = mdp.target | mdp.sink
    reach = mdp.target.copy()
    while True:  # the states that reach the target with positive probability
        more = reach | (~stop & ((p[:, reach] > 0).any(axis=1)))
        if np.array_equal(more, reach):
            break
        reach = more
    live = np.flatnonzero(reach & ~mdp.target)
    v = mdp.target.astype(float)
    if live.size:
        q = p[np.ix_(live, live)]
        b = p[live][:, mdp.target].sum(axis=1)
        v[live] = np.linalg.solve(np.eye(live.size) - q, b)
    v[~reach] = 0.0
    assert n == v.size
    return v


def _brute_force(mdp: MDP, sense: Sense) -> np.ndarray:
    """The optimum at every state over every deterministic memoryless policy."""
    groups = mdp.row_groups
    ranges = [range(int(groups[s]), int(groups[s + 1])) for s in range(mdp.n_states)]
    best = None
    for policy in itertools.product(*ranges):
        v = _policy_values(mdp, np.array(policy))
        best = v if best is None else (np.maximum(best, v) if sense is Sense.MAX
                                       else np.minimum(best, v))
    assert best is not None
    return best


def _linprog_values(mdp: MDP, sense: Sense) -> np.ndarray:
    """The value LP by HiGHS: for a maximum the least ``v`` in [0, 1] with ``v(s) >=
    P(c) v`` for every choice (1 on the target, 0 where no policy reaches it); for a
    minimum the greatest with ``<=`` (0 where some policy avoids the target for ever)."""
    n, p = mdp.n_states, mdp.matrix.toarray()
    owner = np.repeat(np.arange(n), np.diff(mdp.row_groups))
    zero = ~mdp.target
    while True:  # max: no choice reaches; min: some choice stays in ``zero``
        if sense is Sense.MAX:
            leaves = (p[:, ~zero] > 0).any(axis=1)
            more = zero & ~(np.bincount(owner, weights=leaves, minlength=n) > 0)
        else:
            stays = (p[:, ~zero] == 0).all(axis=1)
            more = zero & (np.bincount(owner, weights=stays, minlength=n) > 0)
        if np.array_equal(more, zero):
            break
        zero = more
    free = ~mdp.target[owner] & ~zero[owner]
    rows = p[free].copy()
    rows[np.arange(rows.shape[0]), owner[free]] -= 1.0  # P(c) v - v(s)
    sign = 1.0 if sense is Sense.MAX else -1.0
    bounds = [(1.0, 1.0) if t else (0.0, 0.0) if z else (0.0, 1.0)
              for t, z in zip(mdp.target, zero, strict=True)]
    res = linprog(sign * np.ones(n), A_ub=sign * rows, b_ub=np.zeros(rows.shape[0]),
                  bounds=bounds, method="highs",
                  options={"primal_feasibility_tolerance": 1e-10,
                           "dual_feasibility_tolerance": 1e-10})
    assert res.status == 0
    return res.x


def _solved(mdp: MDP, sense: Sense, loose: bool = False):
    """The LP stage with interval iteration's bounds, or (``loose``) the trivial ones
    0 and 1, whose greedy policy the check refuses on some blocks (the LP solves
    those)."""
    if loose:
        bounds = (np.zeros(mdp.n_states), np.ones(mdp.n_states))
    else:
        it = interval_iteration(mdp, mdp.target, sense=sense, gap="max", progress=False)
        bounds = (it.lower, it.upper)
    got = solve_lp(mdp, mdp.target, sense=sense, everywhere=True, bounds=bounds)
    assert got.status.value == "optimal" and got.values is not None
    assert got.policy is not None
    return got


@pytest.mark.parametrize("loose", [False, True])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", range(5))
def test_values_and_policy_are_linprogs(seed: int, sense: Sense, loose: bool) -> None:
    mdp = random_mdp(120, seed=seed, target_fraction=0.08, sink_fraction=0.08,
                     self_loop_fraction=0.05, max_choices=4, max_successors=4)
    want = _linprog_values(mdp, sense)
    got = _solved(mdp, sense, loose)
    np.testing.assert_allclose(got.values, want, atol=1e-8)
    attained = _policy_values(mdp, np.asarray(got.policy))
    np.testing.assert_allclose(attained, want, atol=1e-8)


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", range(8))
def test_tiny_mdps_match_every_policy_enumerated(seed: int, sense: Sense) -> None:
    mdp = random_mdp(7, seed=100 + seed, target_fraction=0.15, sink_fraction=0.15,
                     self_loop_fraction=0.1, max_choices=3, max_successors=3)
    want = _brute_force(mdp, sense)
    got = _solved(mdp, sense, loose=seed % 2 == 1)
    np.testing.assert_allclose(got.values, want, atol=1e-9)
    np.testing.assert_allclose(_policy_values(mdp, np.asarray(got.policy)), want,
                               atol=1e-9)


def test_loose_bounds_leave_blocks_to_the_lp() -> None:
    """With the trivial bounds the check refuses the greedy policy somewhere, so the
    tests above reach the block LPs too (and with interval iteration's, the greedy
    policy settles blocks without them)."""
    mdp = random_mdp(120, seed=0, target_fraction=0.08, sink_fraction=0.08,
                     self_loop_fraction=0.05, max_choices=4, max_successors=4)
    assert not _solved(mdp, Sense.MAX, loose=True).message.startswith("0 block LPs")
    assert "by the bounds' greedy policy, certified" in _solved(mdp, Sense.MAX).message
