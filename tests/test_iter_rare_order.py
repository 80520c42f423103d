"""The block renumbered for the compiled sweeps (mitld_lp.solvers.sweep_order.renumbered)
is the block ``Block.of`` builds from the quotient for the states in that order: every
field the same to the bit and in the same types, on random MDPs and random orders; and the
interval iteration's bracket with it is the one the block built twice gives."""

from __future__ import annotations

import numpy as np
import pytest

from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.quotient import quotient_for
from mitld_lp.solvers.sweep_order import renumbered, value_order
from mitld_lp.solvers.topological import Block
from mitld_lp.testing import random_mdp


def _same(a: Block, b: Block) -> None:
    for name in ("states", "choices", "starts", "to_target"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype, name
        np.testing.assert_array_equal(x, y, err_msg=name)
    for name in ("inner", "outer"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.shape == y.shape, name
        for part in ("indptr", "indices", "data"):
            u, v = getattr(x, part), getattr(y, part)
            assert u.dtype == v.dtype, (name, part)
            # the same entries in the same stored order, the values to the bit
            np.testing.assert_array_equal(u.view(np.uint8), v.view(np.uint8),
                                          err_msg=f"{name}.{part}")


@pytest.mark.parametrize("seed", range(8))
def test_renumbered_block_is_block_of_the_states_in_that_order(seed: int) -> None:
    # renumbering is structural (the sense only shapes the quotient): a maximum's
    # quotients keep more states than a minimum's on these MDPs
    mdp = random_mdp(120, seed=seed, locality=5, sink_fraction=0.1, self_loop_fraction=0.3)
    q = quotient_for(mdp, mdp.target, None, Sense.MAX)
    rng = np.random.default_rng(seed)
    n = q.n_states
    assert n >= 20
    states = np.sort(rng.choice(n, size=max(2, n // 2), replace=False))
    block = Block.of(q, states)
    for order in (rng.permutation(states.size), value_order(block)[::-1]):
        _same(renumbered(block, order), Block.of(q, states[order]))


def _order_by_hand(block: Block) -> list[int]:
    """The value order by its definition (sweep_order's docs), by breadth-first searches
    in Python: the states that reach a state with a target choice along the block's
    moves, nearest first (ties: the last state first); then, of the others, those that
    reach a state with an exit (distances through every state); then the rest, the last
    first."""
    n = block.states.size
    groups = block.groups
    preds: list[set[int]] = [set() for _ in range(n)]
    target, leaving = set(), set()
    for s in range(n):
        for c in range(int(groups[s]), int(groups[s + 1])):
            for e in range(int(block.inner.indptr[c]), int(block.inner.indptr[c + 1])):
                preds[int(block.inner.indices[e])].add(s)
            if block.to_target[c] > 0:
                target.add(s)
            if block.outer.indptr[c + 1] > block.outer.indptr[c]:
                leaving.add(s)
    out: list[int] = []
    seen: set[int] = set()
    for seeds in (target, leaving):
        dist = dict.fromkeys(seeds, 1)
        frontier = sorted(seeds)
        while frontier:
            nxt = []
            for t in frontier:
                for s in preds[t]:
                    if s not in dist:
                        dist[s] = dist[t] + 1
                        nxt.append(s)
            frontier = nxt
        for s in sorted((s for s in dist if s not in seen), key=lambda s: (dist[s], -s)):
            out.append(s)
            seen.add(s)
    out += [s for s in range(n - 1, -1, -1) if s not in seen]
    return out


@pytest.mark.parametrize("seed", range(8))
def test_value_order_is_its_definition(seed: int) -> None:
    mdp = random_mdp(150, seed=seed, locality=4, sink_fraction=0.1, self_loop_fraction=0.3)
    q = quotient_for(mdp, mdp.target, None, Sense.MAX)
    rng = np.random.default_rng(seed)
    for states in (np.arange(q.n_states),
                   np.sort(rng.choice(q.n_states, size=q.n_states // 2, replace=False))):
        block = Block.of(q, states)
        order = value_order(block)
        assert order.dtype == np.int64
        assert order.tolist() == _order_by_hand(block)
