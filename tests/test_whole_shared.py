"""``sweep_order.whole``: the jump's block with its moves out of it, sharing the swept
block's moves inside it (no second copy held through the jump).

Independent routes: the quotient's dense rows (the block's moves inside and out, read
off ``toarray``), ``Block.of`` of the same states (the quotient's rows cut afresh), the
optimum by brute force over every memoryless deterministic policy
(``tests.test_iter_mem``), and the iteration with ``whole`` as it was (a fresh cut),
whose bounds must be the same bits; tracemalloc for what ``whole`` keeps.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from mitld_lp.solvers import early_jump, iteration, sweep_order
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.quotient import quotient_for
from mitld_lp.solvers.sweep_order import for_sweeps, value_order, whole
from mitld_lp.solvers.topological import Block
from mitld_lp.testing import random_mdp
from tests.test_iter_mem import _brute_force, _dyadic_mdp, _force_early, needs_numba


def _swept(seed: int, n: int = 400):
    mdp = random_mdp(n, seed=seed, locality=12, sink_fraction=0.05, self_loop_fraction=0.1)
    q = quotient_for(mdp, mdp.target, None, Sense.MAX)
    block = Block.of(q, np.arange(q.n_states))
    order = value_order(block)[::-1]
    exits = np.zeros((block.choices.size, 2))
    swept, _ = for_sweeps([block], order, exits)
    return q, swept


def _same_csr(a, b) -> bool:
    return (a.shape == b.shape and a.indptr.dtype == b.indptr.dtype
            and a.indices.dtype == b.indices.dtype and a.data.dtype == b.data.dtype
            and np.array_equal(a.indptr, b.indptr) and np.array_equal(a.indices, b.indices)
            and np.array_equal(a.data.view(np.uint64), b.data.view(np.uint64)))


@pytest.mark.parametrize("seed", range(4))
def test_whole_is_block_of_with_the_swept_inner(seed: int) -> None:
    q, swept = _swept(seed)
    got = whole(q, swept)
    want = Block.of(q, swept.states)
    assert got.inner is swept.inner  # shared, not copied
    assert _same_csr(got.inner, want.inner) and _same_csr(got.outer, want.outer)
    for name in ("states", "choices", "starts"):
        a, b = getattr(got, name), getattr(want, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), name
    assert got.to_target is None  # each model's own is set by the jump's callers
    # the moves inside and out, read off the quotient's dense rows
    dense = q.matrix.toarray()[got.choices]
    outside = np.ones(q.n_states, dtype=bool)
    outside[got.states] = False
    assert np.array_equal(got.inner.toarray(), dense[:, got.states])
    assert np.array_equal(got.outer.toarray()[:, outside], dense[:, outside])
    assert not got.outer.toarray()[:, got.states].any()
    assert whole(q, got) is got  # a block with its moves out is itself


def test_whole_keeps_no_second_inner() -> None:
    q, swept = _swept(7, n=20_000)
    inner_bytes = swept.inner.data.nbytes + swept.inner.indices.nbytes + \
        swept.inner.indptr.nbytes
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        got = whole(q, swept)
        kept = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    own = (got.outer.data.nbytes + got.outer.indices.nbytes + got.outer.indptr.nbytes
           + got.choices.nbytes + got.starts.nbytes)
    assert inner_bytes > 100_000
    assert kept < own + 64 * 1024 < own + inner_bytes


CASES = [(seed, sense) for seed in range(3) for sense in (Sense.MAX, Sense.MIN)]


@needs_numba
@pytest.mark.parametrize(("seed", "sense"), CASES)
def test_iteration_jumps_on_the_shared_block_to_the_same_bits(
        monkeypatch: pytest.MonkeyPatch, seed: int, sense: Sense) -> None:
    calls: list[bool] = []
    _force_early(monkeypatch)
    mdp, choices = _dyadic_mdp(seed, 7)

    def recorded(q, block):
        got = whole(q, block)
        calls.append(got.inner is block.inner)
        return got

    monkeypatch.setattr(early_jump, "whole", recorded)
    monkeypatch.setattr(iteration, "whole", recorded)
    res = iteration.interval_iteration(mdp, mdp.target, sense=sense, compiled=True,
                                       gap="max", precision=None, progress=False)
    assert calls and any(calls)  # the jump's block shared the swept one's rows
    exact = _brute_force(choices, sense)
    lower, upper = np.asarray(res.lower)[:7], np.asarray(res.upper)[:7]
    slack = 4 * np.spacing(np.maximum(np.abs(exact), 1e-300))
    assert np.all(lower <= exact + slack) and np.all(exact <= upper + slack)

    def fresh(q, block):  # whole as it was: the quotient's rows cut again
        return block if block.outer is not None else Block.of(q, block.states)

    monkeypatch.setattr(early_jump, "whole", fresh)
    monkeypatch.setattr(iteration, "whole", fresh)
    monkeypatch.setattr(sweep_order, "whole", fresh)
    old = iteration.interval_iteration(mdp, mdp.target, sense=sense, compiled=True,
                                       gap="max", precision=None, progress=False)
    for a, b in ((res.lower, old.lower), (res.upper, old.upper)):
        assert np.array_equal(np.asarray(a).view(np.uint64), np.asarray(b).view(np.uint64))
