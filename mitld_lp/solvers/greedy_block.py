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
the bounds keep), on a quarter of the crossover's tie scale
(:func:`mitld_lp.solvers.crossover.polish`): a choice may score above by at most a
quarter of the state's threshold (``tol``, and ``precision`` of its value) over the
policy's longest expected exit time, and the policy's own choices must meet their
equations to that scale too (the evaluation's residual); the rest of the threshold
is left to the certificate that checks the answer afterwards
(:mod:`mitld_lp.solvers.certify`).  Where the test holds, the block's answer is what
the crossover would accept from the interior-point solution, at the cost of one
evaluation of a chain.  Where it fails, at a state and at every state that can reach
one (by any choice), the values may change; the other states form a set that no
choice leaves but downwards and on which the test holds throughout, so the
certificate proves their values alone, and the LP (pruned, eliminated and polished as
before) is solved over the failing states and those upstream of them, with the
settled ones as exits.

Which policy: greedy on the bound that a greedy policy's value lies beyond (a
maximum's lower bound, a minimum's upper: :func:`mitld_lp.solvers.crossover.
crossover_start` ranks with the same).  Interval iteration brings those bounds within
each state's threshold of the optimum, so a choice it picks loses at most that.

The chain of one deterministic policy is far more acyclic than the block: on QVBS
``zeroconf`` 1000-4-false the 213,268-state block's policy chain splits into 208,702
components (the largest 4,567 states) over 95 levels.  It is solved level by level
(:class:`~mitld_lp.solvers.chain_levels.ChainLevels`: single states by their
self-loop, a cyclic component by one sparse LU of its own size) in 0.12 s, where one LU
of the whole chain took 1.0 s; the walk is kept with the answer, and the block's flow
under the policy (a block it settles whole) is its transposed solve.

Why not the LP there: 319,663 of that block's 336,567 choices that the bounds keep are
exact ties (symmetric hosts), which no bound can prune; the interior-point method
took 10 iterations of about 6 s each on them, and policy iteration to the exact
fixpoint (:func:`mitld_lp.solvers.topological.improve_policy`) ten LUs of 1 s for
switches whose gains were below 3e-16 of the values, float64 noise.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.chain_levels import ChainLevels
from mitld_lp.solvers.graph import Sense, backward_reachable, segmented_argmax
from mitld_lp.solvers.kernels import thresholds
from mitld_lp.solvers.topological import Block
from mitld_lp.util import kernel_loader

__all__ = ["Greedy", "certified_greedy"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True, eq=False)
class Greedy:
    """The greedy policy of a block's bounds and what its certificate settles: its
    choice (local), value and one-hot weights in every state, exact LP answers on the
    states that cannot reach one where the certificate fails; ``left`` (local state
    indices, sorted) are the others, for the LP.  ``walk``: the level walk of the
    policy's chain over its own components (local indices), its factorisations kept:
    the block's flow under this policy is its transposed solve
    (:func:`mitld_lp.solvers.lp_blocks.policy_flow`)."""

    chosen: np.ndarray
    values: np.ndarray
    left: np.ndarray
    walk: ChainLevels
    n_choices: int  # the block's

    @property
    def n_settled(self) -> int:
        return int(self.chosen.size - self.left.size)

    @property
    def weights(self) -> np.ndarray:
        """Per block choice, 1 where the policy takes it, else 0 (made when asked: the
        caller writes the ones where they go, so no float a choice is held beside the
        block at the LP stage's peak)."""
        weights = np.zeros(self.n_choices)
        weights[self.chosen] = 1.0
        return weights


def certified_greedy(block: Block, reward: np.ndarray, bound: np.ndarray, sense: Sense,
                     tol: float, precision: float | None, *,
                     of_quotient: bool = False) -> Greedy | None:
    """The block LP's answer as the greedy policy (in ``sense``) of ``bound`` (bounds
    on the block's values on the side a policy's value lies beyond: a maximum's lower, a
    minimum's upper; their soundness only decides how often this succeeds) where its
    values are dual feasible to the tie scale (module docs).  A state where a choice
    beats the policy's value, or where the evaluation's residual is above the scale,
    fails, and so does every state of the block that can reach one (by any choice):
    their values may change; the others form a set no choice leaves but downwards,
    whose values and policy the certificate proves.  ``None`` if no state is settled
    (the caller solves the whole block).  ``of_quotient``: ``bound`` is per quotient
    state (read here at ``block.states``), so the caller holds no copy of the block's
    bounds while this runs."""
    # the block's ``groups`` (a copy of ``starts`` with the total) only where a call
    # takes them, not held beside the batches; the policy's choices in the index type
    # the batches use (a block choice each fits it)
    starts = block.starts
    n, m = starts.size, int(block.choices.size)
    index = np.int32 if max(n, m, block.inner.nnz) < 2**31 - 1 else np.int64
    local = bound[block.states] if of_quotient else bound
    inner = block.inner
    chosen = (segmented_argmax(reward + inner @ local, block.groups, sense=sense)
              if not _paid(m) else
              _compiled().greedy_choices(inner.indptr, inner.indices, inner.data,
                                         block.groups, reward,
                                         np.asarray(local, dtype=np.float64),
                                         sense is Sense.MAX)).astype(index)
    del local
    walk = ChainLevels(sp.csr_array(block.inner[chosen]))
    both = walk.solve(np.column_stack([reward[chosen], np.ones(n)]))
    if not (np.all(np.isfinite(both)) and np.all(both[:, 1] >= 1.0)):
        logger.info("greedy policy of %d block states: its chain did not solve", n)
        return None
    # the values unclipped (what the check reads, each entry widened to long double
    # where a batch reads it: no long double copy of the block's values, 16 bytes a
    # state, held), the values clipped and the tie scale, made one after the other:
    # the solve's two columns (the exit times only for their maximum) freed first,
    # the scale divided in place
    longest = float(np.max(both[:, 1]))
    raw = both[:, 0].copy()
    del both
    values = np.clip(raw, 0.0, 1.0)
    tie = thresholds(values, tol, precision)
    tie /= _SHARE * longest
    # how far each choice's score falls short of its state's value (below 0: it beats
    # it), BATCH choices at a time and judged there: no array a choice (a long double
    # copy of the whole block is 16 bytes an entry; the slack, each choice's state and
    # their tie scale were 8 + 4 + 8 bytes a choice alive at the LP stage's peak)
    failed = np.zeros(n, dtype=bool)
    batches: range | np.ndarray = range(0, m, BATCH)
    rows = _canonical(block, m)
    if rows is not None:
        # one compiled pass decides every choice float64 can (the same decisions);
        # the batches holding a choice it cannot are judged as below
        kernels = _compiled()
        flag = kernels.dual_check(rows.indptr, rows.indices, rows.data, block.groups,
                                  reward, raw, tie, chosen, sense is Sense.MAX)
        del rows
        failed = flag == kernels.FAILED
        unsure = np.flatnonzero(flag == kernels.UNSURE)
        del flag
        batches = _batches_of(starts, m, unsure) * BATCH
    for a in batches:
        a = int(a)
        z = min(a + BATCH, m)
        owner = _owners(starts, a, z, index)
        score = reward[a:z] + _scores(_rows(block.inner, a, z), raw, index)
        slack = (-sense.gain(score, raw[owner].astype(np.longdouble))).astype(np.float64)
        del score
        failed[owner[tie[owner] + slack < 0.0]] = True  # a choice beats it
        # the policy's own choices there (one a state, increasing with it)
        mine = np.arange(*np.searchsorted(chosen, (a, z)))
        failed[mine[np.abs(slack[chosen[mine] - a]) > tie[mine]]] = True  # its residual
    del raw, tie
    left = np.flatnonzero(backward_reachable(
        n, np.repeat(np.arange(n, dtype=index),  # each entry's state
                     np.diff(block.inner.indptr[block.groups])),
        block.inner.indices, failed)) if failed.any() else np.zeros(0, dtype=np.int64)
    if left.size:
        logger.info("greedy policy of %d block states (%d choices): %d fail its dual "
                    "check and %d more reach them (the LP solves those)", n,
                    block.choices.size, int(np.count_nonzero(failed)),
                    left.size - int(np.count_nonzero(failed)))
    else:
        logger.info("greedy policy of %d block states (%d choices) certified by its "
                    "dual values: no LP", n, block.choices.size)
    if left.size == n:
        return None
    return Greedy(chosen, values, left, walk, m)


KERNEL_MIN_CHOICES = 1 << 14
"""The fewest choices of a block whose dual check is the compiled pass
(:mod:`mitld_lp.solvers.greedy_kernels`), once the compiled kernels' load is paid."""


def _paid(m: int) -> bool:
    """Whether a block of ``m`` choices takes the compiled kernels
    (:data:`KERNEL_MIN_CHOICES` and more, their load paid, numba installed)."""
    return (m >= KERNEL_MIN_CHOICES and kernel_loader.compiled_paid()
            and _compiled() is not None)


def _compiled() -> Any:
    """:mod:`mitld_lp.solvers.greedy_kernels`, ``None`` without numba."""
    try:
        from mitld_lp.solvers import greedy_kernels
    except ImportError:  # numba not installed
        return None
    return greedy_kernels


def _canonical(block: Block, m: int) -> sp.csr_array | None:
    """The block's rows as the long double route sums them (each row's columns sorted,
    as its ``sum_duplicates`` sorts a batch's), where the compiled dual check pays
    (:func:`_paid`): the block's own rows where they are canonical, else a sorted copy
    (the block is left as it came); ``None`` where a row repeats a column (that route
    merges them) or the check does not pay."""
    if not _paid(m):
        return None
    inner = block.inner
    if inner.has_canonical_format:
        return inner
    inner = inner.copy()
    inner.sort_indices()
    rows = sp.csr_array((inner.data, inner.indices, inner.indptr), shape=inner.shape)
    return rows if rows.has_canonical_format else None


def _batches_of(starts: np.ndarray, m: int, states: np.ndarray) -> np.ndarray:
    """The indices of the batches (of :data:`BATCH` choices) holding a choice of one of
    ``states`` (sorted), each once, increasing."""
    if states.size == 0:
        return np.zeros(0, dtype=np.int64)
    first = starts[states] // BATCH
    ends = np.append(starts, m)[states + 1]
    last = (ends - 1) // BATCH
    # each once, increasing: marked (``np.unique`` imports ``numpy.ma``, 15 ms once)
    marked = np.zeros(int(last.max()) + 1, dtype=bool)
    for f, z in zip(first.tolist(), last.tolist(), strict=True):
        marked[f:z + 1] = True
    return np.flatnonzero(marked)


def _owners(starts: np.ndarray, a: int, z: int, index: type) -> np.ndarray:
    """The state of each choice ``a`` to ``z - 1`` (``starts``: the states' first
    choices, the total after them or not): the states the batch spans, each repeated by
    its choices inside it (two binary searches a batch, not one a choice)."""
    first, last = np.searchsorted(starts, (a, z - 1), side="right") - 1
    ends = np.append(np.clip(starts[first:last + 1], a, z), z)
    return np.repeat(np.arange(first, last + 1, dtype=index), np.diff(ends))


def _scores(rows: sp.csr_array, values: np.ndarray, index: type) -> np.ndarray:
    """Each row's sum of its entries times ``values`` at their columns, in long double:
    what ``rows.astype(np.longdouble) @ values.astype(np.longdouble)`` sums (the same
    products, each row's added in its stored order from 0), with only the values the
    rows read widened (one a stored entry, not one a column).  Rows not in canonical
    order (sorted columns, no duplicate) are put in it first, in place, as SciPy's
    ``astype`` does (on the block's arrays, which ``rows`` views: the same sums and the
    same block afterwards as that product)."""
    if not rows.has_canonical_format:
        rows.sum_duplicates()
    if rows.nnz == 0:
        return np.zeros(rows.shape[0], dtype=np.longdouble)
    widened = values[rows.indices].astype(np.longdouble)
    spread = sp.csr_array((rows.data.astype(np.longdouble),
                           np.arange(rows.nnz, dtype=index), rows.indptr.astype(index)),
                          shape=(rows.shape[0], rows.nnz))
    return spread @ widened


def _rows(m: sp.csr_array, a: int, z: int) -> sp.csr_array:
    """Rows ``a:z`` of ``m`` on views of its arrays (SciPy's slice copies them): the
    same entries in the same order, so each row's product sums as before."""
    lo, hi = int(m.indptr[a]), int(m.indptr[z])
    return sp.csr_array((m.data[lo:hi], m.indices[lo:hi], m.indptr[a:z + 1] - lo),
                        shape=(z - a, m.shape[1]))


BATCH = 1 << 13
"""Choices scored at a time by :func:`certified_greedy` (its memory bound, not its
answer: each row's sum is the same).  2**16 choices' long double scores and rows were
the LP stage's traced peak on QVBS ``zeroconf`` 1000-4 (90.0 bytes a transition above
its entry; 86.2 at 2**14, where the chain's component search peaks instead).  2**13
since a batch also widens the values its rows read (16 bytes an entry, where no long
double copy of the block's values is held): QVBS ``consensus`` 4-4's greedy checks
peaked at 12.5 and 14.4 bytes a transition above their entry at 2**14, 9.9 at 2**13."""

_SHARE = 4.0
"""The greedy policy's loss may take a quarter of each state's threshold (as the policy
jump's shift does, :mod:`mitld_lp.solvers.iteration`); the rest is the certificate's."""
