"""Block LPs over the choices the interval-iteration bounds leave possible: the values
are those of the whole LP (dense value iteration on the raw MDP), the columns left out
are exactly the provably suboptimal ones, and wrong bounds cost time, not the answer."""

from __future__ import annotations

import re

import numpy as np
import pytest
from test_analysis import _dense_values

from mitld_lp.solvers.crossover import better_of, crossover_start, polish
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.lp_backends import solve_one
from mitld_lp.solvers.lp_blocks import block_lp, may_be_optimal, tightened
from mitld_lp.solvers.options import SolveOptions
from mitld_lp.solvers.quotient import reduce
from mitld_lp.solvers.topological import Block, Factors, evaluate_chain, improve_policy
from mitld_lp.testing import random_mdp


def _mdp(seed: int):  # big strongly connected parts: the block LPs do the work
    return random_mdp(80, seed=seed, target_fraction=0.08, sink_fraction=0.08,
                      self_loop_fraction=0.0, max_choices=4, max_successors=3)


def _whole_block(seed: int):
    """The random MDP's quotient as one block, its one-step target probabilities and
    the dense value iteration's values on its states."""
    mdp = _mdp(seed)
    q = reduce(mdp, mdp.target)
    want = _dense_values(mdp, mdp.target)
    v_red = np.zeros(q.n_states)
    kept = np.flatnonzero(q.state_map >= 0)
    v_red[q.state_map[kept]] = want[kept]
    block = Block.of(q, np.arange(q.n_states))
    return block, q.to_target[block.choices], v_red


@pytest.mark.parametrize("seed", range(6))
def test_pruned_block_lps_give_the_whole_lps_values(seed: int) -> None:
    mdp = _mdp(seed)
    want = _dense_values(mdp, mdp.target)
    it = interval_iteration(mdp, mdp.target, gap="max", progress=False)
    plain = solve_lp(mdp, mdp.target, everywhere=True)
    # the pruned LP itself (the bounds' greedy policy, certified, would skip it)
    pruned = solve_lp(mdp, mdp.target, everywhere=True, bounds=(it.lower, it.upper),
                      greedy=False)
    kept, total = map(int, re.search(r"\((\d+) of (\d+) block columns may be optimal",
                                      pruned.message).groups())
    assert 0 < kept < total  # some choices were left out, not all
    for r in (plain, pruned):
        assert r.values is not None and np.allclose(r.values, want, atol=1e-8)
        assert r.status.value == "optimal"
    # wrong bounds (lower above the truth) prune optimal choices: the polish restores
    wrong = solve_lp(mdp, mdp.target, everywhere=True,
                     bounds=(np.minimum(want + 0.3, 1.0), np.minimum(want + 0.3, 1.0)))
    assert wrong.values is not None and np.allclose(wrong.values, want, atol=1e-8)


@pytest.mark.parametrize("seed", range(6))
def test_left_out_are_exactly_the_suboptimal_choices(seed: int) -> None:
    block, reward, v_red = _whole_block(seed)  # no states downstream: the whole quotient
    keep = may_be_optimal(block, reward, v_red, v_red)  # exact bounds
    q_star = reward + block.inner @ v_red
    owner = np.repeat(np.arange(v_red.size), np.diff(block.groups))
    best = q_star >= v_red[owner] - 1e-9
    assert np.all(keep[best])  # no optimal choice is left out
    loses = q_star < v_red[owner] - 1e-6
    assert not np.any(keep & loses)  # every clearly losing one is


@pytest.mark.parametrize("seed", range(4))
def test_pruning_is_scale_free(seed: int) -> None:
    """Values are linear in the one-step target probabilities: scaled by 1e-15 (values
    like the bus blocks' 1e-19..1e-9), the same choices are left out, none of them
    optimal (an absolute margin would keep every choice there)."""
    block, reward, v = _whole_block(seed)
    keep = may_be_optimal(block, reward, v, v)
    tiny = may_be_optimal(block, reward * 1e-15, v * 1e-15, v * 1e-15)
    assert not keep.all()
    assert np.array_equal(keep, tiny)


@pytest.mark.parametrize("seed", range(4))
def test_tightened_bounds_stay_sound_and_prune_more(seed: int) -> None:
    block, reward, v = _whole_block(seed)
    lo, hi = np.zeros_like(v), np.ones_like(v)  # sound, and useless for pruning
    t_lo, t_hi = tightened(block, reward, lo, hi)
    assert np.all(t_lo <= v + 1e-12) and np.all(t_hi >= v - 1e-12)
    assert np.all(t_lo >= lo) and np.all(t_hi <= hi)
    before = int(np.count_nonzero(may_be_optimal(block, reward, lo, hi)))
    after = may_be_optimal(block, reward, t_lo, t_hi)
    assert int(np.count_nonzero(after)) < before
    q_star = reward + block.inner @ v
    owner = np.repeat(np.arange(v.size), np.diff(block.groups))
    assert np.all(after[q_star >= v[owner] - 1e-12])  # no optimal choice left out



def _block_answer(seed: int):
    """A random block, its LP, Clarabel's answer and the block's values, computed apart
    from the LP (policy iteration in extended precision from the first choices)."""
    block, _, v = _whole_block(seed)
    lp = block_lp(block, np.zeros(block.states.size))
    raw = solve_one(lp, SolveOptions("CLARABEL", "direct", 1e-9), retry=False)
    assert raw.y is not None and raw.v is not None
    _, exact, _ = improve_policy(block, lp.objective, np.asarray(block.groups[:-1]))
    exact = np.asarray(exact, dtype=np.float64)
    assert np.allclose(exact, v, atol=1e-9)  # the dense value iteration agrees
    return block, lp, np.maximum(raw.y, 0.0), raw.v, exact


def _start(block, lp, y, duals, lower):
    return crossover_start(block, lp, y, duals, np.arange(block.choices.size), lower,
                            Factors())


def _exact(block, lp, chosen) -> np.ndarray:
    return np.asarray(evaluate_chain(block.inner, chosen, lp.objective)[0], dtype=np.float64)


@pytest.mark.parametrize("seed", range(6))
def test_thecrossover_start_is_worth_both_candidates(seed: int) -> None:
    """The crossover starts from a policy worth, in every state, at least the better of
    its two candidates (here random policies, each better in some states), and the
    crossover's answer is exact whatever bound it is given."""
    block, lp, y, duals, exact = _block_answer(seed)
    groups, everything = block.groups, np.arange(block.choices.size)
    rng = np.random.default_rng(seed)
    counts = np.diff(groups)
    for _ in range(50):  # a pair where neither policy is the better everywhere
        first, second = (groups[:-1] + rng.integers(0, counts) for _ in range(2))
        v_first, v_second = _exact(block, lp, first), _exact(block, lp, second)
        if np.any(v_first > v_second + 1e-9) and np.any(v_second > v_first + 1e-9):
            break
    else:
        pytest.fail("no pair of random policies where each is better somewhere")
    merged = better_of(block, lp.objective, first, second, Factors())
    worth = _exact(block, lp, merged)
    assert np.all(worth >= np.maximum(v_first, v_second) - 1e-12)
    assert np.all(worth <= exact + 1e-12)
    for lower in (exact, np.zeros_like(exact), None):
        got = polish(block, lp, y, duals, everything, 1e-9, bound=lower)
        assert got.optimal and np.allclose(got.values, exact, atol=1e-12)


def test_the_two_candidates_differ_and_neither_is_always_better() -> None:
    """The check above is not empty: on these blocks the duals' greedy policy (from
    duals of 0: the best one-step reward) and the bound's (the values themselves) differ,
    and the start is optimal where one of them is not."""
    losses = []
    for seed in range(6):
        block, lp, y, duals, exact = _block_answer(seed)
        zero = np.zeros_like(duals)
        start = _start(block, lp, y, zero, exact)
        q = lp.objective + block.inner @ exact
        assert np.all(q[start] >= exact - 1e-12)  # optimal up to rounding
        alone = _start(block, lp, y, zero, None)  # the duals' greedy policy alone
        losses.append(float(np.max(exact - q[alone])))
    assert max(losses) > 1e-3
