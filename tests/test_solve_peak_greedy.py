"""The greedy policy's dual check judged batch by batch (mitld_lp.solvers.greedy_block,
no array a choice kept) against the old path, which kept the whole block's slack,
each choice's state and their tie scale: on random blocks with bounds that are not
the optimum (so that some states fail and others are settled) the same chosen
choices, the same values and the same failing set to the bit, whatever the batch
size; and a small solve's answer is the same for every batch size."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import greedy_block, lp_blocks
from mitld_lp.solvers.chain_levels import ChainLevels
from mitld_lp.solvers.graph import Sense, backward_reachable, segmented_argmax
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.kernels import thresholds
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.quotient import reduce
from mitld_lp.solvers.topological import Block
from mitld_lp.testing import random_mdp


def _old_path(block: Block, reward: np.ndarray, bound: np.ndarray, sense: Sense,
              tol: float, precision: float | None):
    """The check as it was before (355aaee): the whole block's slack in one array, the
    tie scale repeated a choice, each entry's state from each choice's."""
    groups = block.groups
    counts = np.diff(groups)
    n = counts.size
    chosen = segmented_argmax(reward + block.inner @ bound, groups, sense=sense)
    walk = ChainLevels(sp.csr_array(block.inner[chosen]))
    both = walk.solve(np.column_stack([reward[chosen], np.ones(n)]))
    v, steps = both[:, 0], both[:, 1]
    v_ld = v.astype(np.longdouble)
    owner = np.repeat(np.arange(n, dtype=np.int32), counts)
    slack = np.empty(owner.size)
    for a in range(0, owner.size, 1 << 16):
        z = min(a + (1 << 16), owner.size)
        score = reward[a:z] + block.inner[a:z].astype(np.longdouble) @ v_ld
        slack[a:z] = -sense.gain(score, v_ld[owner[a:z]])
    tie = thresholds(np.clip(v, 0.0, 1.0), tol, precision) / (4.0 * float(np.max(steps)))
    failed = np.zeros(n, dtype=bool)
    failed[owner[np.repeat(tie, counts) + slack < 0.0]] = True
    failed[np.abs(slack[chosen]) > tie] = True
    left = np.flatnonzero(backward_reachable(
        n, np.repeat(owner, np.diff(block.inner.indptr)), block.inner.indices,
        failed)) if failed.any() else np.zeros(0, dtype=np.int64)
    return chosen, np.clip(v, 0.0, 1.0), left


def _block(seed: int, sense: Sense, n: int = 60):
    """A random MDP's quotient as one block, and its optimal values there (interval
    iteration's lower bounds, closed to 1e-12)."""
    mdp = random_mdp(n, seed=seed, max_choices=4, target_fraction=0.1)
    q = reduce(mdp, mdp.target, sense=sense)
    if q.n_states == 0:
        pytest.skip("nothing left to solve")
    it = interval_iteration(mdp, mdp.target, quotient=q, sense=sense, tol=1e-12,
                            precision=None, gap="max", progress=False)
    kept = np.flatnonzero(q.state_map >= 0)
    v = np.zeros(q.n_states)
    v[q.state_map[kept]] = it.lower[kept]
    return Block.of(q, np.arange(q.n_states)), v


@pytest.mark.parametrize("batch", [1, 3, 7, greedy_block.BATCH])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", range(6))
def test_batched_check_is_the_old_one(seed: int, sense: Sense, batch: int,
                                      monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(greedy_block, "BATCH", batch)
    block, v = _block(seed, sense)
    rng = np.random.default_rng(seed)
    n = block.starts.size
    reward = block.to_target
    # the optimum (every state settled), the optimum bent at a few states (a losing
    # choice ranked first there: those and the states upstream fail, the rest are
    # settled), and noise everywhere (most states fail)
    bent = v.copy()
    few = rng.choice(n, size=max(1, n // 10), replace=False)
    bent[few] = np.clip(bent[few] + rng.choice([-0.3, 0.3], few.size), 0.0, 1.0)
    noisy = np.clip(v + rng.normal(0.0, 0.05, n), 0.0, 1.0)
    # tol 1e-30: a scale below the evaluation's own residual (that check decides)
    for bound, tol, precision in itertools.product((v, bent, noisy), (1e-9, 1e-30),
                                                   (None, 1e-6)):
        want_chosen, want_v, want_left = _old_path(block, reward, bound, sense,
                                                   tol, precision)
        got = greedy_block.certified_greedy(block, reward, bound, sense, tol,
                                            precision)
        if want_left.size == n:
            assert got is None
            continue
        assert got is not None
        np.testing.assert_array_equal(got.chosen, want_chosen)
        assert got.values.tobytes() == want_v.tobytes()
        np.testing.assert_array_equal(got.left, want_left)


@pytest.mark.parametrize("seed", range(4))
def test_a_small_solve_is_the_same_for_every_batch(seed: int,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """The LP's answer with the greedy check on every block, its choices judged one,
    two or all at a time: the same values to the bit (no batch reads what an earlier
    one freed or wrote), and within the interval iteration's bracket."""
    monkeypatch.setattr(lp_blocks, "GREEDY_MIN_CHOICES", 0)
    mdp = random_mdp(80, seed=100 + seed, max_choices=3, target_fraction=0.1)
    it = interval_iteration(mdp, mdp.target, gap="max", progress=False)
    answers = []
    for batch in (1, 2, greedy_block.BATCH):
        monkeypatch.setattr(greedy_block, "BATCH", batch)
        got = solve_lp(mdp, mdp.target, everywhere=True, bounds=(it.lower, it.upper))
        assert got.values is not None and got.status.value == "optimal"
        answers.append(np.asarray(got.values))
    for a in answers[1:]:
        assert a.tobytes() == answers[0].tobytes()
    assert np.all(answers[0] >= it.lower - 1e-9) and np.all(answers[0] <= it.upper + 1e-9)
