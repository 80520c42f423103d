"""The policy jump's look-ahead (mitld_lp.solvers.policy_jump): each state's best score
where every state has the same number of choices, folded column by column, is
``reduceat``'s to the bit (NaN, signed zeros, both senses); a jump on a block of such
states proves the same bounds with and without the fold, and they hold against the
block's values by a dense solve of every policy."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import policy_jump
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.topological import Block


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("width", [1, 2, 3, 5])
def test_fold_is_reduceat(width: int, sense: Sense) -> None:
    rng = np.random.default_rng(width)
    n = 500
    scores = rng.choice([0.0, -0.0, 1.0, 0.5, np.nan, -np.inf, 0.25], size=n * width)
    scores[: width * 10] = rng.random(width * 10)
    starts = np.arange(0, n * width, width)
    op = np.maximum if sense is Sense.MAX else np.minimum
    want = op.reduceat(scores, starts)
    got = policy_jump._best(scores, starts, width, sense)
    # The same bits, NaNs included, but for the sign of a zero: IEEE 754 leaves the
    # minimum (maximum) of 0.0 and -0.0 unspecified, and NumPy's reduceat answers it
    # differently by CPU (AMD EPYC's SIMD loop gives -0.0 where the pairwise fold
    # gives 0.0).  Adding +0.0 maps -0.0 to 0.0 and keeps every other bit.
    assert (got + 0.0).tobytes() == (want + 0.0).tobytes()
    assert np.array_equal(got, want, equal_nan=True)


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("width", [1, 2, 3, 5])
def test_argbest_is_segmented_argmax(width: int, sense: Sense) -> None:
    from mitld_lp.solvers.graph import segmented_argmax

    rng = np.random.default_rng(10 + width)
    n = 400
    scores = rng.choice([0.0, -0.0, 1.0, 0.5, 0.25, np.nan], size=n * width)
    groups = np.arange(0, n * width + 1, width)
    want = segmented_argmax(scores, groups, sense=sense)
    got = policy_jump._argbest(scores, groups, width, sense)
    np.testing.assert_array_equal(got, want)


def _uniform_block(seed: int, n: int = 6, width: int = 2) -> Block:
    """``n`` states of ``width`` choices each, every choice moving inside the block
    with probability below 1 and leaving with a reward of its own."""
    rng = np.random.default_rng(seed)
    m = n * width
    dense = rng.random((m, n)) * (rng.random((m, n)) < 0.5)
    dense *= rng.uniform(0.3, 0.9, size=(m, 1)) / np.maximum(dense.sum(axis=1), 1e-9)[:, None]
    inner = sp.csr_array(dense)
    reward = rng.random(m) * (1.0 - dense.sum(axis=1))
    return Block(np.arange(n), np.arange(m), inner, sp.csr_array((m, n)),
                 np.arange(0, m, width), reward)


def _optimum(block: Block, sense: Sense) -> np.ndarray:
    n = block.states.size
    groups = block.groups
    dense = block.inner.toarray()
    best = None
    for policy in itertools.product(*[range(groups[s], groups[s + 1]) for s in range(n)]):
        pick = np.array(policy)
        v = np.linalg.solve(np.eye(n) - dense[pick], block.to_target[pick])
        best = v if best is None else (np.maximum(best, v) if sense is Sense.MAX
                                       else np.minimum(best, v))
    return best


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", range(4))
def test_jump_same_with_and_without_the_fold(seed: int, sense: Sense,
                                             monkeypatch) -> None:
    block = _uniform_block(seed)
    n = block.states.size
    want = _optimum(block, sense)

    def run() -> tuple[bool, np.ndarray, np.ndarray]:
        lo, hi = np.zeros(n), np.ones(n)
        ok = policy_jump.jump(block, lo, hi, 1e-9, 1e-6, sense)
        return ok, lo, hi

    ok, lo, hi = run()
    assert policy_jump._width(block) == 2
    monkeypatch.setattr(policy_jump, "_width", lambda b: 0)
    ok0, lo0, hi0 = run()
    assert ok == ok0
    assert lo.tobytes() == lo0.tobytes() and hi.tobytes() == hi0.tobytes()
    assert ok  # both bounds proven, and sound against the enumerated optimum
    assert np.all(lo <= want + 1e-12) and np.all(want <= hi + 1e-12)
    np.testing.assert_allclose(lo, want, atol=1e-8)
    np.testing.assert_allclose(hi, want, atol=1e-8)
