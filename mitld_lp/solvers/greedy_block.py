r"""A block's occupancy LP answered by the greedy policy of sound bounds, when the LP's
own optimality conditions certify it (:func:`certified_greedy`; called by
:func:`mitld_lp.solvers.lp_blocks.solve_decomposed` before a block goes to the solver).

The block LP (``b = 1`` on every state, exit rewards ``r``) and its dual
:math:`\min \sum_s v(s)` s.t. :math:`v(s) \ge r(c) + \sum_{s'} P(c, s') v(s')` have,
for a deterministic policy :math:`\pi` whose chain leaves the block (every policy of
the quotient does), the primal point :math:`y_\pi` (the policy's occupancy from
``b``: feasible, and positive only on the policy's choices) and the dual point
:math:`v_\pi` (the policy's values).  Complementary slackness holds by construction
(the policy's choices are tight at its own values), so the pair is optimal as soon as
:math:`v_\pi` is dual feasible: no choice ``c`` of a state ``s`` scores above
:math:`v_\pi(s)`.  That is the test, over every choice of the block (not only those
the bounds keep), with the crossover's tie scale
(:func:`mitld_lp.solvers.crossover.polish`): a choice may score above by at most the
state's threshold (``tol``, and ``precision`` of its value) over the policy's longest
expected exit time, and the policy's own choices must meet their equations to that
scale too (the evaluation's residual).  Where the test holds, the block's answer is
what the crossover would accept from the interior-point solution, at the cost of one
evaluation of a chain; where it fails anywhere, the block goes to the LP as before.

Which policy: greedy on the bound that a greedy policy's value lies beyond (a
maximum's lower bound, a minimum's upper: :func:`mitld_lp.solvers.crossover.
crossover_start` ranks with the same).  Interval iteration brings those bounds within
each state's threshold of the optimum, so a choice it picks loses at most that.

The chain of one deterministic policy is far more acyclic than the block: on QVBS
``zeroconf`` 1000-4-false the 213,268-state block's policy chain splits into 208,702
components (the largest 4,567 states) over 95 levels.  It is solved level by level
(:func:`chain_solve`: single states by their self-loop, a cyclic component by one
sparse LU of its own size) in 0.12 s, where one LU of the whole chain took 1.0 s.

Why not the LP there: 319,663 of that block's 336,567 choices that the bounds keep are
exact ties (symmetric hosts), which no bound can prune; the interior-point method
took 10 iterations of about 6 s each on them, and policy iteration to the exact
fixpoint (:func:`mitld_lp.solvers.topological.improve_policy`) ten LUs of 1 s for
switches whose gains were below 3e-16 of the values, float64 noise.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.crossover import Polished
from mitld_lp.solvers.graph import Sense, graph_blocks, rows_dot, segmented_argmax
from mitld_lp.solvers.kernels import thresholds
from mitld_lp.solvers.topological import Block, transient_solve

__all__ = ["certified_greedy", "chain_solve"]

logger = logging.getLogger(__name__)


def chain_solve(chain: sp.csr_array, rhs: np.ndarray) -> np.ndarray:
    r"""``x = rhs + Q x`` (``rhs``: ``(n, k)``, a column per right-hand side) for the
    transient sub-stochastic ``Q`` of ``chain``, level by level downstream first over
    its own strongly connected components: a single state by
    :math:`x(s) = (b(s) + \sum_{s' \ne s} Q(s, s') x(s')) / (1 - Q(s, s))`, a cyclic
    component by one sparse LU (:func:`~mitld_lp.solvers.topological.transient_solve`)
    in float64."""
    chain = sp.csr_array(chain)
    rhs = np.asarray(rhs, dtype=np.float64)
    self_loop = chain.diagonal()
    blk = graph_blocks(sp.csr_array(chain != 0, dtype=np.float64), self_loop)
    x = np.zeros(rhs.shape)
    for level in blk.walk():
        one, cyclic = level.single, level.rest
        # the level's own states are still 0 in x: the products see only below
        x[one] = (rhs[one] + rows_dot(chain, one, x)) / (1.0 - self_loop[one])[:, None]
        if cyclic.size:
            rows = sp.csr_array(chain[cyclic])
            x[cyclic] = transient_solve(sp.csr_array(rows[:, cyclic]),
                                        rhs[cyclic] + rows @ x)
    return x


def certified_greedy(block: Block, reward: np.ndarray, bound: np.ndarray, sense: Sense,
                     tol: float, precision: float | None) -> Polished | None:
    """The block LP's answer as the greedy policy (in ``sense``) of ``bound`` (sound
    bounds on the block's values on the side a policy's value lies beyond: a maximum's
    lower, a minimum's upper), if its values are dual feasible over every choice to the
    tie scale (module docs); ``None`` if not (the caller solves the LP)."""
    groups = block.groups
    counts = np.diff(groups)
    n = counts.size
    chosen = segmented_argmax(reward + block.inner @ bound, groups, sense=sense)
    both = chain_solve(sp.csr_array(block.inner[chosen]),
                       np.column_stack([reward[chosen], np.ones(n)]))
    v, steps = both[:, 0], both[:, 1]
    if not (np.all(np.isfinite(both)) and np.all(steps >= 1.0)):
        logger.info("greedy policy of %d block states: its chain did not solve", n)
        return None
    v_ld = v.astype(np.longdouble)
    # how far each choice's score falls short of its state's value (below 0: it beats it)
    slack = np.asarray(-sense.gain(reward + block.inner.astype(np.longdouble) @ v_ld,
                                   np.repeat(v_ld, counts)), dtype=np.float64)
    tie = thresholds(np.clip(v, 0.0, 1.0), tol, precision) / float(np.max(steps))
    beaten = np.repeat(tie, counts) + slack < 0.0
    off = np.abs(slack[chosen]) > tie  # the evaluation's own residual
    if beaten.any() or off.any():
        logger.info("greedy policy of %d block states not certified: %d choices beat it, "
                    "%d residuals above the tie scale; the LP solves the block", n,
                    int(np.count_nonzero(beaten)), int(np.count_nonzero(off)))
        return None
    weights = np.zeros(block.choices.size)
    weights[chosen] = 1.0
    logger.info("greedy policy of %d block states (%d choices) certified by its dual "
                "values: no LP", n, block.choices.size)
    return Polished(chosen, np.clip(v, 0.0, 1.0), weights, True)
