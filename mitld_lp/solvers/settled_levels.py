"""A quotient of single states (a deadline's product, acyclic up to self-loops) whose
level walk the iteration's bounds already answer (:func:`settled_by_bounds`, called by
:func:`mitld_lp.solvers.lp_blocks.solve_decomposed` before its walk).

The LP stage's values on such a quotient are the walk of
:meth:`~mitld_lp.solvers.topological.SingleLevels.values`: each state's choices scored
against the values below it, the best picked (ties within ``TIE`` to the larger one-step
reward), its score the value.  Interval iteration walked the same levels with the same
sums for its bounds (:meth:`~mitld_lp.solvers.topological.SingleLevels.solve`), so where
nothing is near a tie its bounds are those values already, and the walk (60
microseconds a level in NumPy, a deadline makes a thousand levels) only says so.  Here
that is checked at once, exactly, and the walk runs only where the check fails.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from mitld_lp.solvers.graph import Blocks, Sense, segmented_argmax
from mitld_lp.solvers.reach import backward_reachable
from mitld_lp.solvers.reduced import Quotient
from mitld_lp.solvers.topological import TIE, SingleLevels
from mitld_lp.util.sparsetools import sparsetools

__all__ = ["SETTLED_BY_BOUNDS", "settled_by_bounds"]

logger = logging.getLogger(__name__)

SETTLED_BY_BOUNDS = True
"""Whether :func:`settled_by_bounds` may answer a quotient of single states from the
iteration's bounds (``False``: the level walk always runs; the same answers)."""


def settled_by_bounds(q: Quotient, blk: Blocks, singles: SingleLevels,
                      bounds: tuple[Any, Any] | None, values: np.ndarray,
                      reduced_choice: np.ndarray, weights: np.ndarray) -> bool:
    """The level walk of a quotient with no non-trivial component (a deadline's
    product, acyclic up to self-loops), answered from the iteration's bounds where they
    are already the walk's values: every single state's choices scored at once against
    the bound (:func:`~mitld_lp.solvers.topological.single_scores`' formula, the walk's
    sums in its order: its arrays, one compiled CSR product), each state's choice picked
    by the walk's rule among ties, and the pick's score compared to the state's bound
    bit for bit.  Where every successor of a state passes (its score read the walk's own
    values) and the state does, the walk would write that score and that choice
    (induction down the levels); the states that fail, and every state that reaches
    one, are walked as before from the lowest level holding one, the others kept
    (``skip``).  ``True``: the values, choices and weights are written; ``False``: not
    tried (blocks, no bounds), the caller walks."""
    if (not SETTLED_BY_BOUNDS or bounds is None or bool((blk.size > 1).any())
            or singles.states.size == 0):
        return False
    n = q.n_states
    every = np.arange(n)
    candidate = np.asarray(bounds[0 if q.sense is Sense.MAX else 1][every],
                           dtype=np.float64)
    other = np.asarray(bounds[1 if q.sense is Sense.MAX else 0][every])
    # a state the iteration left open (one it skipped: the initial state cannot reach
    # it) has its value below a walk from its level up: not worth the check
    if not np.array_equal(candidate[~q.zero], other[~q.zero]):
        return False
    del other, every
    candidate[q.zero] = 0.0  # what the walk reads there (never solved: 0)
    sl = singles
    m = sl.choices.size
    ptr, local, cols, vals = sl.entries()  # (a copy for the compiled walks, freed here)
    if ptr is not None and sparsetools is not None:
        sums = np.zeros(m)
        sparsetools.csr_matvec(m, n, ptr, cols, vals, candidate, sums)
    else:
        sums = np.bincount(local, weights=vals * candidate[cols], minlength=m)
    reward = q.to_target[sl.choices]
    score = reward + sums
    del sums
    score = (score / sl.leave if sl.positive else
             np.divide(score, sl.leave, out=np.zeros_like(score), where=sl.leave > 0))
    np.clip(score, 0.0, 1.0, out=score)
    best = segmented_argmax(score, sl.state_choice, tie=TIE, sense=q.sense,
                            prefer=reward if q.sense is Sense.MAX else -reward)
    del reward
    got = score[best]
    states = np.asarray(sl.states, dtype=np.int64)
    live = ~q.zero[states]
    failed = np.zeros(n, dtype=bool)
    failed[states] = live & (got.view(np.int64) != candidate[states].view(np.int64))
    del candidate
    if failed.any():  # and every state that reaches one: walked
        owner = np.repeat(states, np.diff(sl.state_choice))
        failed = backward_reachable(n, owner[local], cols, failed)
        del owner
    del ptr, local, cols, vals
    take = live & ~failed[states]
    picks = np.asarray(sl.choices, dtype=np.int64)[best[take]]
    values[states[take]] = got[take]
    reduced_choice[states[take]] = picks
    weights[picks] = 1.0
    walked = np.flatnonzero(~take & live)
    logger.info("single states by the bounds: %d of %d, %d walked", int(take.sum()),
                int(live.sum()), walked.size)
    if walked.size:  # from the lowest level holding one, the others kept
        level_of = np.searchsorted(sl.level_state, walked, side="right") - 1
        singles.values(int(level_of.min()), blk.n_levels, q.to_target, q.zero | ~failed,
                       values, reduced_choice, weights)
    return True
