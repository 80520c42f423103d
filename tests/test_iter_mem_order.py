"""The compiled sweeps' order and renumbered block (mitld_lp.solvers.sweep_order) within
their memory: the order's searches peak below a bound computed here from the block's
sizes (the moves reversed once, an index and a float an entry, not owner and successor
pairs and their sparse matrix per search), and a block handed over in a list is let go
as its renumbered copy is made (weak references), the copy still ``Block.of``'s."""

from __future__ import annotations

import gc
import tracemalloc
import weakref

import numpy as np
import pytest

from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.quotient import quotient_for
from mitld_lp.solvers.sweep_order import renumbered, value_order
from mitld_lp.solvers.topological import Block
from mitld_lp.testing import random_mdp


def _block(seed: int, n: int) -> tuple[object, Block]:
    mdp = random_mdp(n, seed=seed, locality=20, sink_fraction=0.05, self_loop_fraction=0.1)
    q = quotient_for(mdp, mdp.target, None, Sense.MAX)
    return q, Block.of(q, np.arange(q.n_states))


def test_value_order_peak_is_bounded_by_the_block_sizes() -> None:
    _, block = _block(3, 60_000)
    n, nnz, nc = block.states.size, block.inner.nnz, block.choices.size
    assert nnz > 4 * n // 2  # a block with several entries a state
    # the reversed moves rooted for a search: an int32 index and a float64 an entry
    # (12 bytes), the transposed pattern beside it while it is made (5 bytes); the
    # states' searches and distances: ~100 bytes a state; a choice's marks: 8 bytes
    bound = 17 * nnz + 100 * n + 8 * nc
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        order = value_order(block)
        peak = tracemalloc.get_traced_memory()[1] - before
    finally:
        tracemalloc.stop()
    assert np.array_equal(np.sort(order), np.arange(n))
    assert peak <= bound, (peak, bound, peak / nnz)


@pytest.mark.parametrize("seed", range(3))
def test_renumbered_lets_the_old_block_go(seed: int) -> None:
    q, block = _block(seed, 3_000)
    order = value_order(block)[::-1]
    want = Block.of(q, block.states[order])
    refs = [weakref.ref(block.inner), weakref.ref(block.outer)]
    held = [block]
    del block
    got = renumbered(held, order)
    gc.collect()
    assert held == []
    assert all(r() is None for r in refs)
    for name in ("states", "choices", "starts", "to_target"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name))
    for name in ("inner", "outer"):
        a, b = getattr(got, name), getattr(want, name)
        for part in ("indptr", "indices", "data"):
            x, y = getattr(a, part), getattr(b, part)
            assert x.dtype == y.dtype
            np.testing.assert_array_equal(x.view(np.uint8), y.view(np.uint8))


@pytest.mark.parametrize("seed", range(3))
def test_for_sweeps_drops_the_outer_moves_and_keeps_the_exits_to_the_bit(seed: int) -> None:
    from mitld_lp.solvers.sweep_order import for_sweeps, whole

    q, block = _block(seed, 3_000)
    rng = np.random.default_rng(seed)
    bounds = rng.random((q.n_states, 2))
    order = value_order(block)[::-1]
    want = Block.of(q, block.states[order])
    # the exits as the iteration made them on the renumbered block before
    want_exits = np.column_stack([want.to_target, want.to_target]) + want.outer @ bounds
    exits = np.column_stack([block.to_target, block.to_target]) + block.outer @ bounds
    ref = weakref.ref(block.outer)
    held = [block]
    del block
    got, got_exits = for_sweeps(held, order, exits)
    gc.collect()
    assert got.outer is None and ref() is None
    np.testing.assert_array_equal(got_exits.view(np.uint64), want_exits.view(np.uint64))
    back = whole(q, got)
    for part in ("indptr", "indices", "data"):
        np.testing.assert_array_equal(getattr(back.outer, part), getattr(want.outer, part))
    np.testing.assert_array_equal(back.inner.data, want.inner.data)


@pytest.mark.parametrize("seed", range(3))
def test_prepared_self_loops_by_hand(seed: int) -> None:
    """Each choice's ``1 - self-loop`` and the diagonal entries' places, by a loop over
    the block's rows written here."""
    from mitld_lp.solvers.kernels import Prepared

    mdp = random_mdp(800, seed=seed, locality=5, self_loop_fraction=0.4)
    q = quotient_for(mdp, mdp.target, None, Sense.MAX)
    block = Block.of(q, np.arange(q.n_states))
    prep = Prepared(block.inner, block.groups)
    groups, m = block.groups, block.inner
    loops = np.zeros(m.shape[0])
    places = []
    for s in range(groups.size - 1):
        for c in range(int(groups[s]), int(groups[s + 1])):
            for e in range(int(m.indptr[c]), int(m.indptr[c + 1])):
                if int(m.indices[e]) == s:
                    loops[c] += float(m.data[e])
                    places.append(e)
    assert places  # the block has self-loops
    np.testing.assert_array_equal(prep._diag, places)
    np.testing.assert_array_equal(prep.leave, 1.0 - loops)
