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
