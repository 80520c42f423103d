"""The interval iteration's early jump on a compiled block
(:mod:`mitld_lp.solvers.iteration`, its ``_EARLY``): the policy jump's cost forecast
from the block's structure (:mod:`mitld_lp.solvers.jump_cost`) against the sweeps it
would save, and the jump itself (:func:`mitld_lp.solvers.policy_jump.jump`) where it
pays, abandoned past the rounds of policy iteration those sweeps pay for.

The forecast is made on the block as the sweeps hold it (its moves out of it left out by
:func:`~mitld_lp.solvers.sweep_order.for_sweeps`), so that a refused jump never rebuilds
the block with them (QVBS-sized ``bus_scaled`` n128 d3: both its blocks refused, a
``Block.of`` of 32,768 and of 16,384 states each before).
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from mitld_lp.solvers import jump_cost
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.kernels import excess
from mitld_lp.solvers.policy_jump import Abandoned, jump, start_policy
from mitld_lp.solvers.reduced import Quotient
from mitld_lp.solvers.sweep_order import whole
from mitld_lp.solvers.topological import Block, Factors

__all__ = ["early_jump"]

# the iteration's own logger: its lines (taken, refused, abandoned) stay where they were
logger = logging.getLogger("mitld_lp.solvers.iteration")


def early_jump(block: Block, rewards: np.ndarray, bounds: np.ndarray, first: np.ndarray,
                tol: float, precision: float | None, sense: Sense, saved: float,
                exits: np.ndarray, q: Quotient) -> bool | Block | None:
    """The early jump of the iteration's ``_EARLY`` on every model, if its cost is at most
    a share of that of the ``saved`` sweeps (:func:`mitld_lp.solvers.jump_cost.worth`),
    its rounds of
    policy iteration within what they pay for; ``True`` if it closed the block's gap
    (else its bounds are at least as tight, and the block with its moves out of it,
    made for the jump, is returned; ``None`` where the jump was refused before it).
    The cost is forecast on ``block`` as swept (its moves out of it may be left out:
    :func:`~mitld_lp.solvers.sweep_order.for_sweeps`), the start policy greedy on its
    ``exits`` (the sweeps' exit rewards, a row a choice: each the same to the bit as
    the block's own ``to_target + outer @ bounds`` of that column, the same entries
    added in the same order), so a refused jump never makes the block's moves out."""
    models = bounds.shape[1] // 2
    own = 0 if sense is Sense.MAX else 1  # the first model's start (policy_jump.jump)
    exit_own = np.ascontiguousarray(exits[:, own])
    c = jump_cost.cost(block, start_policy(block, exit_own, first[:, own], sense), saved)
    del exit_own  # a float a choice, not held through the jump (it makes its own)
    logger.debug("early jump on %d states: %.0f sweeps saved, %.1f rounds of %.1f "
                 "sweeps forecast (depth %d, %.3g LU multiplies)", block.states.size,
                 saved, c.rounds, c.round / c.sweep, c.depth, c.flops)
    # a sweep and a jump both cost once per model: the models cancel in the decision
    if not jump_cost.worth(c, saved):
        logger.debug("early jump on %d states refused: it would cost more than "
                     "half the sweeps it saves", block.states.size)
        return None
    block = whole(q, block)
    allowance = c.allowance(saved * models)
    try:
        for j in range(models):
            model = replace(block, to_target=rewards[block.choices, 2 * j])
            lo, hi = bounds[:, 2 * j], bounds[:, 2 * j + 1]  # views: written through
            factors = Factors()
            ok = jump(model, lo, hi, tol, precision, sense, first[:, 2 * j:2 * j + 2],
                      allowance, factors)
            allowance -= factors.factorised
            if not ok:
                return block
    except Abandoned:
        logger.debug("early jump on %d states abandoned: past its %.1f rounds",
                     block.states.size, c.allowance(saved * models))
        return block
    return excess(bounds[block.states], tol, precision) < 1.0 or block
