"""The greedy check's batches (``greedy_block._owners``): the state of each choice of
a batch, found by two binary searches a batch and a repeat, against the state of every
choice written out state by state; and the check's answer where batches cut states in
two (``BATCH`` smaller than a state's choices), against HiGHS."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog

from mitld_lp.solvers import greedy_block
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.greedy_block import _owners, certified_greedy
from mitld_lp.solvers.topological import Block


def _owner_by_loop(groups: np.ndarray) -> list[int]:
    owner = []
    for s in range(groups.size - 1):
        owner += [s] * int(groups[s + 1] - groups[s])
    return owner


@pytest.mark.parametrize("seed", range(20))
def test_owners_are_each_choices_state(seed: int) -> None:
    rng = np.random.default_rng(seed)
    counts = rng.integers(1, 6, size=int(rng.integers(1, 40)))
    groups = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    m = int(groups[-1])
    want = _owner_by_loop(groups)
    for a in range(m):  # every batch start, batches of every length
        for z in {a + 1, min(m, a + 3), m}:
            got = _owners(groups, a, z, np.int32)
            assert got.dtype == np.int32
            assert got.tolist() == want[a:z]


def _block(rng: np.random.Generator, n: int) -> tuple[Block, np.ndarray]:
    """A block of ``n`` states, 1-4 choices each, each choice staying with probability
    at most 0.6 (split over up to two states) and leaving with the rest, its exit
    reward drawn in [0, 1 - stay]."""
    counts = rng.integers(1, 5, size=n)
    groups = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    m = int(groups[-1])
    rows, cols, vals, reward = [], [], [], np.zeros(m)
    for c in range(m):
        stay = rng.uniform(0.0, 0.6)
        to = rng.choice(n, size=2, replace=False)
        split = rng.uniform(0.0, 1.0)
        rows += [c, c]
        cols += to.tolist()
        vals += [stay * split, stay * (1.0 - split)]
        reward[c] = rng.uniform(0.0, 1.0 - stay)
    inner = sp.csr_array((vals, (rows, cols)), shape=(m, n))
    inner.sum_duplicates()
    outer = sp.csr_array((m, 1))
    block = Block(np.arange(n), np.arange(m), inner, outer, groups[:-1].copy(),
                  np.zeros(m))
    return block, reward


def _highs_values(block: Block, reward: np.ndarray) -> np.ndarray:
    """The block's optimal values: min sum v s.t. v(s) >= r(c) + P(c, .) v."""
    n = block.states.size
    owner = np.repeat(np.arange(n), np.diff(block.groups))
    a = (block.inner - sp.csr_array((np.ones(owner.size), (np.arange(owner.size), owner)),
                                    shape=block.inner.shape))
    got = linprog(np.ones(n), A_ub=a, b_ub=-reward, bounds=[(0, 1)] * n, method="highs")
    assert got.status == 0, got.message
    return got.x


@pytest.mark.parametrize("seed", range(6))
def test_check_with_batches_cutting_states_agrees_with_highs(
        seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """With batches of 3 choices (most states' choices cut across two batches) the
    greedy policy of the exact optimal values (rounded) is certified, and its values
    are HiGHS's to its tolerance."""
    monkeypatch.setattr(greedy_block, "BATCH", 3)
    rng = np.random.default_rng(50 + seed)
    block, reward = _block(rng, 25)
    want = _highs_values(block, reward)
    got = certified_greedy(block, reward, want, Sense.MAX, 1e-6, None)
    assert got is not None and got.left.size == 0
    np.testing.assert_allclose(got.values, want, atol=1e-7)
