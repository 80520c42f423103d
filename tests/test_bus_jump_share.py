"""The early jump's margin (mitld_lp.solvers.jump_cost.SHARE) and the forecast that
refuses without counting the LU: expectations computed by hand from the module's
formulas, on a block built here."""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers import jump_cost
from mitld_lp.solvers.topological import Block


def _line(n: int) -> Block:
    """A line of ``n`` states, each with one choice moving half to the next state
    (the last leaves the block): depth ``n - 1``."""
    rows, cols = np.arange(n - 1), np.arange(1, n)
    inner = sp.csr_array((np.full(n - 1, 0.5), (rows, cols)), shape=(n, n))
    return Block(states=np.arange(n), choices=np.arange(n), inner=inner,
                 outer=sp.csr_array((n, 1)), starts=np.arange(n), to_target=np.zeros(n))


def test_worth_takes_half_the_saving() -> None:
    c = jump_cost.Cost(sweep=100.0, round=1000.0, rounds=5.0, depth=44, flops=0.0)
    # 5 rounds of 1,000 entries = 5,000 = 50 sweeps of 100: worth it only from 100 saved
    assert jump_cost.SHARE == 0.5
    assert jump_cost.worth(c, 100.0)
    assert not jump_cost.worth(c, 99.0)
    assert not jump_cost.worth(c, 60.0)  # within the saving, but not within half


def test_refused_without_the_lu() -> None:
    n = 12
    block = _line(n)
    chosen = np.arange(n)
    full = jump_cost.cost(block, chosen)
    # by hand: 11 entries, 12 choices; depth 11; a round 400 * 12 + 20 * 11 entries
    assert full.sweep == 23.0
    assert full.depth == 11
    assert full.rounds == 1.0 + 11 / 11
    floor = 400.0 * 12 + 20.0 * 11
    # and 0.5 entries a multiply of its LU, counted on the chain
    assert full.round == floor + 0.5 * full.flops
    # saved so few that even the floor (2 rounds of 5,020 entries) passes half of them
    refused = jump_cost.cost(block, chosen, saved=10.0)
    assert math.isnan(refused.flops)
    assert refused.round == floor
    assert not jump_cost.worth(refused, 10.0)
    # saved enough: counted in full, the same cost as without ``saved``
    taken = jump_cost.cost(block, chosen, saved=1e6)
    assert taken == full
    assert jump_cost.worth(taken, 1e6)
