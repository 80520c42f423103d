"""The verified policy jump of the interval iteration (:mod:`mitld_lp.solvers.iteration`'s
module docs): a block whose sweeps close its gap too slowly gets its bounds from a
policy improved to a fixpoint with exact solves of its chain, kept only where they prove
themselves (``x <= T(x)`` for a lower bound, ``T(x) <= x`` for an upper one, checked in
extended precision and rounded outwards).

**Policy iteration with a look-ahead** (:func:`improve_ahead`).  Each round of policy
iteration is one sparse LU of the policy's chain.  On QVBS ``consensus`` the rounds'
switches form a long tail: on 6-2 ``c2``'s block of 29,060 states, after six rounds of
thousands of switches, 25 more rounds switch 20-40 states each, the gains halving every
three rounds (an improvement carried one step further along the shared counter per
round): 31 LUs, 1.9-2.0 s CPU.  Where a round switches, the policy is made greedy on
``T^K v`` (``K`` = :data:`AHEAD_SWEEPS` Bellman sweeps of the block from the policy's
values ``v``, in float64) instead of on ``v``: the sweeps carry the improvement
``K`` steps at once.  For a maximum ``v <= T v`` (``v`` a policy's values), so
``v <= T^K v <= v*`` and a policy greedy on ``w = T^K v`` has ``T_pi' w = T w >= w``,
hence values at least ``w``: each round still improves the policy (for a minimum the
same, reversed).  The same block's jump then costs 0.36-0.39 s.  The fixpoint test is
unchanged (no choice gains more than :data:`~mitld_lp.solvers.topological.GAIN` over
the exactly evaluated policy), and the bounds are proven by the checks whatever the
policy, so the look-ahead can cost time but never soundness.

**The policy's own totals first.**  The bound checked over every choice is shifted by
``e W`` with ``W`` the largest expected total over the nearly optimal choices (one more
policy iteration, one LU at least).  When the policy iterations end on the policy they
started from, its own totals ``W = t`` are tried first and the check decides: on QVBS
``consensus`` 4-4 ``c2`` it passed on all four blocks (excess -3e-13 to -4e-14), solve
stage 0.72-0.77 -> 0.65 s CPU, the same bracket to the bit; where it refuses, the
slowest choices' totals are computed as before.

**A budget in rounds** (``allowance``: the compiled blocks' early jump of
:mod:`mitld_lp.solvers.iteration`, priced by :mod:`mitld_lp.solvers.jump_cost`).  Before
each round of policy iteration the rest is forecast: the LUs made so far (shared by the
jump's policy iterations through their :class:`~mitld_lp.solvers.topological.Factors`)
and the rounds left, read from how fast the switches fall (:func:`_rounds_left`).  If
that passes the allowance the jump raises :class:`Abandoned` and writes nothing; the
caller sweeps on.  No clock is read: the same block gives the same decisions.

**What a jump holds** (the iteration's traced peak on QVBS ``consensus`` 4-4 ``c2``
was in it: 32.1 bytes a product transition above the iteration's entry, 14.9 since,
the same bracket to the bit).  No long double copy of the block's rows is made:
each extended-precision product widens the rows :data:`LD_BATCH` entries at a time
(:func:`ld_product`, the same sums as the widened matrix's); a policy's own rows only
where only they are read; the refinement's residual, the scores and the checks made
in place; one side's exit rewards at a time; the tie search by arrays a state, not a
score and an index a choice; the last round's values and the last LU let go before
the next ones are made.  ``experiments/peak_sites.py`` lists what is alive at a
stage's traced peak.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers import topo_chain
from mitld_lp.solvers.graph import Sense, segmented_argmax
from mitld_lp.solvers.kernels import thresholds
from mitld_lp.solvers.rows import gather_ranges
from mitld_lp.solvers.topological import (
    DENSE_LU_STATES,
    GAIN,
    POLICY_ROUNDS,
    Block,
    Factors,
    chain_lu,
    evaluate_chain,
    policy_round,
)

__all__ = ["AHEAD_SWEEPS", "Abandoned", "improve_ahead", "jump", "start_policy"]

logger = logging.getLogger(__name__)

AHEAD_SWEEPS = 10
"""Bellman sweeps of the look-ahead before each improvement (module docs).  The jump
alone from the same start, CPU seconds: on the block of 29,060 states above 31 LUs
without the look-ahead, 1.9 s; 4 LUs and 0.36-0.39 s with 10 sweeps, 3 LUs and 0.43 s
with 20, 2 LUs and 0.43 s with 50; on ``consensus`` 4-4 ``c2``'s block of 7,863 states
(in its jump the policy iterations take 7 + 0 + 1 LUs without) 0.19 s without, 0.13 s
with 10 sweeps, 0.16-0.17 s with 20 and 50.  Looked at only once a round switches at
most 1/64 of the states (the tail): 0.61-0.69 s and 0.17-0.19 s."""
class Abandoned(Exception):
    """A budgeted jump stopped before a round it forecast to take it past its allowance
    of rounds (:func:`improve_ahead`'s ``allowance``); nothing of it was written."""


AHEAD_GAIN = 1e-12
"""The least gain, relative to the scores compared, for which the look-ahead switches a
choice (its float64 sweeps round to about ``K`` units in the last place)."""


def improve_ahead(block: Block, reward: np.ndarray, chosen: np.ndarray,
                  allowed: np.ndarray | None = None, *,
                  factors: Factors | None = None, sense: Sense = Sense.MAX,
                  sweeps: int = AHEAD_SWEEPS, allowance: float | None = None,
                  inner_ld: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Policy iteration on the block with exit rewards ``reward`` from ``chosen`` (local
    choice indices) to a fixpoint, maximising (or minimising, ``sense``), over the
    ``allowed`` choices only if given, each improvement greedy on ``sweeps`` Bellman
    sweeps from the policy's values (module docs).  Returns the policy, its values and
    its expected exit times (extended precision).  The fixpoint is
    :func:`~mitld_lp.solvers.topological.improve_policy`'s: no choice beats the policy by
    more than ``GAIN`` of the values compared.  ``allowance``: :class:`Abandoned` is
    raised before a round after which the LUs made (``factors.factorised``, shared by
    the jump's calls) and the rounds forecast left would pass it (the policy jump's
    budget, module docs).  ``inner_ld``: the block's rows in extended precision, read
    only by :func:`~mitld_lp.solvers.topological.policy_round` (made here if not given
    and :data:`LEAN_ROUNDS` is off); :func:`lean_round` widens them a batch at a time
    (:func:`ld_product`), so no long double copy of the block is held."""
    starts = block.starts
    if inner_ld is None and not LEAN_ROUNDS:  # policy_round reads the block's rows so
        inner_ld = block.inner.astype(np.longdouble)
    factors = Factors() if factors is None else factors
    worst = -np.inf if sense is Sense.MAX else np.inf
    reward64 = np.asarray(reward, dtype=np.float64)
    barred = None if allowed is None else ~allowed
    width = _width(block)
    before: int | None = None  # the switches of the last round
    v = t = None
    for _ in range(POLICY_ROUNDS):
        # the last round's values and times let go before the next round's are made
        v = t = None
        if LEAN_ROUNDS:
            v, t, nxt = lean_round(block, inner_ld, reward, chosen, allowed, factors,
                                   sense, width)
        else:
            v, t, nxt = policy_round(block, inner_ld, reward, chosen, allowed, factors,
                                     sense)
        if np.array_equal(nxt, chosen):
            return chosen, v, t
        if allowance is not None:
            switched = int(np.count_nonzero(nxt != chosen))
            left = _rounds_left(before, switched)
            logger.debug("budgeted policy iteration: %d LUs made, %d switches, %.1f "
                         "rounds forecast, %.1f allowed", factors.factorised, switched,
                         left, allowance)
            if factors.factorised + left > allowance:
                raise Abandoned
            before = switched
        if sweeps > 0:
            x = np.asarray(v, dtype=np.float64)
            for sweep in range(sweeps + 1):
                # in place: the product, plus the rewards (the same sums), the barred
                # choices overwritten (no second float a choice)
                ahead = block.inner @ x
                ahead += reward64
                if barred is not None:
                    np.copyto(ahead, worst, where=barred)
                if sweep < sweeps:  # the last sweep's scores are what is compared
                    x = _best(ahead, starts, width, sense)
            best = _argbest(ahead, block.groups, width, sense)
            with np.errstate(invalid="ignore"):  # -inf against -inf: not a lead
                lead = sense.gain(ahead[best], ahead[chosen])
                size = np.maximum(np.abs(ahead[best]), np.abs(ahead[chosen]))
                nxt = np.where(lead > AHEAD_GAIN * size, best, nxt)
            # the look-ahead's scores let go before the next round's are made
            del ahead, x, best, lead, size
        chosen = nxt
    return chosen, v, t


LEAN_ROUNDS = True
"""Each round of :func:`improve_ahead` by :func:`lean_round` (else by
:func:`~mitld_lp.solvers.topological.policy_round`): the same floats, less overhead
(the tests force both and compare the bits)."""


def lean_round(block: Block, inner_ld: sp.csr_array, reward: np.ndarray,
               chosen: np.ndarray, allowed: np.ndarray | None, factors: Factors,
               sense: Sense, width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`~mitld_lp.solvers.topological.policy_round` with the same operations on
    the same operands (so the same bits), less around them and less held: the chain's
    rows in extended precision for the refinement made from its float64 arrays (SciPy's
    ``astype`` copies and checks the index arrays too), the refinement's residual and
    the scores made in place, the block's rows widened a batch at a time
    (:func:`ld_product`; ``inner_ld`` is not read), and the greedy step by
    :func:`_argbest`'s column folds where every state has ``width`` choices
    (``segmented_argmax``'s two ``reduceat`` passes over every choice: on
    ``consensus`` 4-4 ``c2`` about a third of a round that reuses its LU)."""
    k = chosen.shape[0]
    chain = sp.csr_array(block.inner[chosen])
    reward_c = np.asarray(reward[chosen], dtype=np.float64)
    rhs = np.column_stack([reward_c, np.ones(k)])
    base = factors.base
    if factors.lu is not None and base is not None and _same_chain(chain, base):
        lu = factors.lu
        factors.reused += 1
    else:
        # the last factorisation is of another chain: let go before the new one is
        # made (SuperLU's factors of both were held at once)
        factors.lu = factors.base = None
        lu = chain_factor(chain)
        factors.lu, factors.base = lu, chain
        factors.factorised += 1
    x = lu.solve(rhs).astype(np.longdouble)
    q_ld = sp.csr_array((chain.data.astype(np.longdouble), chain.indices, chain.indptr),
                        shape=chain.shape)
    for _ in range(2):  # evaluate_chain's two rounds of refinement
        # b + Q x - x in place: ``rhs`` widens exactly where it is added (the same sums
        # as with a long double copy of it, none held)
        residual = q_ld @ x
        residual += rhs
        residual -= x
        x += lu.solve(np.asarray(residual, dtype=np.float64))
        del residual
    del q_ld, rhs
    v, t = x[:, 0], x[:, 1]
    # the scores: the block's rows widened a batch at a time (ld_product: the sums of
    # the block's long double copy, which is not held), the rewards added in place
    score = ld_product(block.inner, v)
    score += reward
    if allowed is not None:
        np.copyto(score, -np.inf if sense is Sense.MAX else np.inf, where=~allowed)
    better = _argbest(score, block.groups, width, sense)
    top, own = score[better], score[chosen]  # each gathered once (long doubles)
    # the scores (a long double a choice) let go once gathered, the scale and its
    # bound made in place (the same operations on the same operands: the same bits;
    # QVBS ``consensus`` 6-2 ``disagree``: the iteration's traced peak was this return)
    del score
    gain = sense.gain(top, own)
    scale = np.maximum(np.abs(top, out=top), np.abs(own, out=own), out=top)
    del own
    scale *= GAIN
    return v, t, np.where(gain > scale, better, chosen)


TOPO_LU = True
"""Chains whose strong components are all small factorised in their components' order
(:func:`chain_factor`), else by :func:`~mitld_lp.solvers.topological.chain_lu`."""

TOPO_MAX_COMPONENT = 256
"""The largest strong component of a chain :func:`chain_factor` factorises in its
components' order (a component is factorised whole, its fill at most its square)."""


class TopoLU:
    """The LU of ``I - Q`` permuted to its strong components' order, ``solve`` as
    SciPy's ``SuperLU`` answers it in the chain's own order."""

    __slots__ = ("at", "lu", "order")

    def __init__(self, lu: object, order: np.ndarray, at: np.ndarray) -> None:
        self.lu, self.order, self.at = lu, order, at

    def solve(self, rhs: np.ndarray, trans: str = "N") -> np.ndarray:
        if trans != "N":
            raise ValueError("TopoLU.solve: only trans='N' (the chain's own solve)")
        # np.take: a tenth of the time of fancy indexing of (k, 2) rows
        y = self.lu.solve(np.take(rhs, self.order, axis=0))
        return np.take(y, self.at, axis=0)


def chain_factor(chain: sp.csr_array) -> object:
    """The factorisation of ``I - Q`` (``chain``: ``Q``) the policy iterations solve on.
    A chain of more than :data:`~mitld_lp.solvers.topological.DENSE_LU_STATES` states
    whose strong components have at most :data:`TOPO_MAX_COMPONENT` states each (a
    policy's chain on QVBS ``consensus``: 7,860 states in 7,376 components, the largest
    122) is permuted so that each component's states are contiguous, the components
    in the order SciPy labels them (downstream first: :func:`_one_way` checks that
    the labels order them, else the chain is factorised whole), and factorised by SuperLU
    in that order (``NATURAL``, the diagonal pivoted on): no fill across components, no
    minimum-degree ordering of the whole; 0.8-1.1 ms against 2.8-9 ms at 7,863 states.
    Else :func:`~mitld_lp.solvers.topological.chain_lu`.  Before both, where a
    kernel's load is paid and the largest component has at most
    :data:`~mitld_lp.solvers.topo_chain.MAX_COMPONENT` states, the compiled
    factorisation in the same order (:mod:`~mitld_lp.solvers.topo_chain`).  Each is
    solved to the same answer up to rounding, and every policy evaluation is refined
    twice in extended precision after it."""
    k = chain.shape[0]
    if not TOPO_LU or k <= DENSE_LU_STATES:
        return chain_lu(sp.csc_array(sp.eye_array(k, format="csc") - chain))
    from scipy.sparse import csgraph  # beside scipy.sparse.linalg, which chain_lu needs

    n_comp, label = csgraph.connected_components(chain, directed=True,
                                                 connection="strong")
    largest = int(np.bincount(label).max())
    compiled = (topo_chain.factor(chain, label, n_comp)  # where a kernel's load is paid
                if largest <= topo_chain.MAX_COMPONENT else None)
    if compiled is not None:
        return compiled
    if largest > TOPO_MAX_COMPONENT or not _one_way(chain, label):
        return chain_lu(sp.csc_array(sp.eye_array(k, format="csc") - chain))
    import scipy.sparse.linalg as spla

    # the stable order of the labels (unique: the same permutation whatever the sort);
    # on 16-bit keys NumPy's stable sort is a radix sort, 0.04 ms against 0.44 on
    # consensus 4-4's 7,863 states
    order = np.argsort(label.astype(np.uint16) if n_comp <= 1 << 16 else label,
                       kind="stable")
    at = np.empty(k, dtype=chain.indices.dtype)  # a state's place in the order
    at[order] = np.arange(k, dtype=at.dtype)
    # I - Q in the order, rows gathered and columns renumbered (no SciPy indexing)
    a = sp.csr_array(sp.eye_array(k, format="csr") - chain)
    take = gather_ranges(a.indptr[order], a.indptr[order + 1])
    indptr = np.concatenate([[0], np.cumsum(np.diff(a.indptr)[order])]).astype(a.indptr.dtype)
    permuted = sp.csc_array(sp.csr_array((a.data[take], at[a.indices[take]], indptr),
                                         shape=(k, k)))
    return TopoLU(spla.splu(permuted, permc_spec="NATURAL",
                            options={"SymmetricMode": True}), order, at)


def _one_way(chain: sp.csr_array, label: np.ndarray) -> bool:
    """Every move between components of ``chain`` goes from a higher label to a lower
    one, or every one from a lower to a higher: the labels order the components (so
    the permuted ``I - Q`` is block triangular and its LU fills inside the components
    only).  SciPy numbers them so; checked rather than assumed."""
    src = np.repeat(label, np.diff(chain.indptr))
    dst = label[chain.indices]
    cross = src != dst
    if not cross.any():
        return True
    down = src[cross] > dst[cross]
    return bool(down.all() or not down.any())


def _same_chain(a: sp.csr_array, b: sp.csr_array) -> bool:
    """``a`` and ``b`` the same matrix, stored alike (the test of
    :class:`~mitld_lp.solvers.topological.Factors`' reuse)."""
    return (a.shape == b.shape and a.nnz == b.nnz and np.array_equal(a.indptr, b.indptr)
            and np.array_equal(a.indices, b.indices) and np.array_equal(a.data, b.data))


def _width(block: Block) -> int:
    """The number of choices of every state of ``block`` if they all have the same
    (QVBS ``consensus``'s blocks: 3 or 4 each), else 0."""
    m, n = int(block.choices.shape[0]), int(block.starts.shape[0])
    if n == 0 or m % n:
        return 0
    width = m // n
    same = np.array_equal(block.starts, np.arange(0, m, width))
    return width if same else 0


def _best(scores: np.ndarray, starts: np.ndarray, width: int, sense: Sense
          ) -> np.ndarray:
    """``sense.reduce(scores, starts)``: each state's best score.  Where every state
    has ``width`` choices, the columns of their ``(n, width)`` view folded left to
    right by ``np.maximum`` (``np.minimum``), the order and operands of ``reduceat``'s
    segments (the same floats, a NaN winning as there), in ``width - 1`` whole-array
    calls: 0.09-0.13 ms against ``reduceat``'s 0.8-1.0 ms on ``consensus`` 4-4's
    31,452 choices of four (a loaded machine)."""
    if width == 0:
        return sense.reduce(scores, starts)
    rows = scores.reshape(-1, width)
    op = np.maximum if sense is Sense.MAX else np.minimum
    best = rows[:, 0].copy()
    for j in range(1, width):
        op(best, rows[:, j], out=best)
    return best


def _argbest(scores: np.ndarray, groups: np.ndarray, width: int, sense: Sense
             ) -> np.ndarray:
    """``segmented_argmax(scores, groups, sense=sense)``: each state's first choice of
    best score; where every state has ``width`` choices, by :func:`_best` and the
    least tied index folded over the columns (the same comparisons and the same
    least index as its ``reduceat`` segments)."""
    if width == 0:
        return segmented_argmax(scores, groups, sense=sense)
    rows = scores.reshape(-1, width)
    best = _best(scores, groups[:-1], width, sense)
    floor = -0.0 * np.abs(best)
    # the least tied column, the columns taken last to first (each overwrites the
    # ties of the later ones): arrays a state, not a score and an index a choice
    column = np.full(best.shape[0], width, dtype=np.int64)
    for j in range(width - 1, -1, -1):
        column[sense.gain(rows[:, j], best) >= floor] = j
    first = np.arange(0, scores.shape[0], width, dtype=np.int64)
    first += column
    first[column == width] = np.iinfo(np.int64).max  # no tie (a NaN): reduceat's
    return first


LD_BATCH = 1 << 13
"""Stored entries widened to long double at a time by :func:`ld_product` (its memory
bound, 16 bytes an entry, not its answer)."""


def ld_product(matrix: sp.csr_array, x: np.ndarray, rows: np.ndarray | None = None
               ) -> np.ndarray:
    """``matrix.astype(np.longdouble) @ x`` (of its ``rows`` only, if given: the same
    rows of that product) without a long double copy of ``matrix``: its rows widened
    :data:`LD_BATCH` entries at a time, each batch put in canonical order as SciPy's
    ``astype`` puts the whole (sorted columns, duplicates summed: on a copy of the
    batch's indices, ``matrix`` untouched), so each row's sum adds the same products in
    the same order: the same bits (SciPy sums a row of a CSR product on its own, from
    0, in its stored order).  Returns long double per row."""
    if rows is not None:
        matrix = sp.csr_array(matrix[rows])
    m = matrix.shape[0]
    out = np.empty(m, dtype=np.longdouble)
    indptr = matrix.indptr
    canonical = matrix.has_canonical_format  # then every batch is (SciPy caches it)
    a = 0
    while a < m:
        # whole rows, about LD_BATCH entries (one row at least)
        z = int(np.searchsorted(indptr, indptr[a] + LD_BATCH, side="right")) - 1
        z = min(max(z, a + 1), m)
        lo, hi = int(indptr[a]), int(indptr[z])
        batch = sp.csr_array((matrix.data[lo:hi].astype(np.longdouble),
                              matrix.indices[lo:hi], indptr[a:z + 1] - lo),
                             shape=(z - a, matrix.shape[1]))
        if not canonical and not batch.has_canonical_format:
            batch = sp.csr_array((batch.data, batch.indices.copy(), batch.indptr),
                                 shape=batch.shape)
            batch.sum_duplicates()
        out[a:z] = batch @ x
        a = z
    return out


def _rounds_left(before: int | None, switched: int) -> float:
    """The rounds of policy iteration a budgeted jump forecasts before its fixpoint:
    ``switched`` states switch now, ``before`` did a round earlier (``None``: the first
    round, one more at least); the switches falling at that rate, ``inf`` if they do
    not fall.  Policy iteration on ``bus_scaled`` n128 d3's grid block of 32,768 states
    switches 9,495, 9,187, 7,302, ... states a round (18 rounds went by in its budget of
    3.7 s without a fixpoint); on QVBS ``consensus`` the look-ahead ends in a few."""
    if before is None or switched <= 1:
        return 1.0
    if switched >= before:
        return float("inf")
    return max(1.0, float(np.log(switched) / np.log(before / switched)))


def jump(block: Block, lo: np.ndarray, hi: np.ndarray, tol: float,
         precision: float | None, sense: Sense, first: np.ndarray | None = None,
         allowance: float | None = None, factors: Factors | None = None) -> bool:
    """Try the verified policy jump of :mod:`mitld_lp.solvers.iteration`'s module docs
    on ``block``; update ``lo`` and ``hi`` where it proves better bounds.  ``True`` if
    both bounds were proven.  ``first``: the block's bounds (a lower and an upper
    column) the policy iterations start greedy on, else ``lo`` and ``hi``.
    ``allowance``: the jump's budget in rounds of policy iteration (LUs);
    :class:`Abandoned` (``lo`` and ``hi`` untouched) before a round forecast to take it
    past them.  ``factors``: where the jump's factorisations are kept (and counted),
    new if not given.

    Measured and not done: stopping the policy iterations once no choice gains more
    than ``tol / 64`` over the longest exit time (both bounds are checked whatever the
    policy), redone to the exact fixpoint where the checks then refuse.  On
    ``bus_scaled`` n64 d3 it saves three of the 8,192-state block's fourteen
    factorisations (interval iteration 0.46 -> 0.40 s), nothing on d10; a slippery
    40x40 grid (``experiments/bench_big_component.py``) and one random model in four
    needed the redo, as a choice tied with the policy took far longer to leave than the
    policy's own, which the upper bound's margin must cover."""
    counts = np.diff(np.append(block.starts, block.choices.shape[0]))
    width = _width(block)
    local = np.column_stack([lo[block.states], hi[block.states]])
    # the bound a policy's own values give (a maximum's lower, a minimum's upper), and
    # the one checked over every choice; -1 lowers a bound, +1 raises it
    own, every = (0, 1) if sense is Sense.MAX else (1, 0)
    # each side's exit rewards (Block.exits' columns) made when that side starts and
    # let go when it ends: one float a choice held at a time, not two
    exit_own = _exit(block, (lo, hi)[own])
    seed = local if first is None else first
    start = start_policy(block, exit_own, seed[:, own], sense)
    # the policy iterations below share their factorisations; the block's rows are
    # widened to extended precision a batch at a time where a product reads them
    # (ld_product: no long double copy of the block held)
    factors = Factors() if factors is None else factors
    chosen, v, t = improve_ahead(block, exit_own, start, factors=factors,
                                 sense=sense, allowance=allowance)
    del start
    own_bound = _shifted(v, t, 1 if own else -1, tol, precision,
                         lambda u: evaluate_chain(block.inner, chosen, np.repeat(u, counts),
                                                  factors)[0])
    # the policy's own rows only (the same rows of the whole product)
    own_image = exit_own[chosen] + ld_product(block.inner, own_bound, chosen)
    own_ok = bool(np.all((own_image >= own_bound) if own == 0 else (own_image <= own_bound)))
    # the exit times and the values below are columns of a round's two (long doubles):
    # each copied alone, so the other column is not held through the rest of the jump
    del own_image, exit_own, v
    t = t.copy()
    exit_every = _exit(block, (lo, hi)[every])
    chosen_best, w, _ = improve_ahead(block, exit_every, chosen, factors=factors,
                                      sense=sense, allowance=allowance)
    w = w.copy()
    del _
    # The shift must cover the slowest of the (nearly) optimal choices, not only the
    # policy's: W = u + max over the choices within a quarter of the threshold of P W.
    # loses = -gain(r + P w, w(owner)), made in place in the scores' array
    loses = ld_product(block.inner, w)
    loses += exit_every
    _less_owner(loses, w, counts, width, sense)
    np.negative(loses, out=loses)
    tied = loses < np.repeat(thresholds(np.asarray(w, dtype=np.float64), tol, precision),
                             counts) / 4.0
    del loses

    def slowest(u: np.ndarray) -> np.ndarray:
        return improve_ahead(block, np.repeat(u, counts), chosen_best, tied,
                             factors=factors, allowance=allowance)[1]

    def check(bound: np.ndarray) -> float:
        # max of sign * (r + P bound - bound(owner)), in place: the same floats
        image = ld_product(block.inner, bound)
        image += exit_every
        _less_owner(image, bound, counts, width, Sense.MAX)
        if not every:
            np.negative(image, out=image)
        return float(np.max(image))

    # First the policy's own totals (no solve more): the check below proves the bound
    # whatever W is, so the slowest choices' totals are sought only if it refuses.
    every_ok = False
    if np.array_equal(chosen_best, chosen):
        every_bound = _shifted(w, t, 1 if every else -1, tol, precision,
                               lambda u: evaluate_chain(block.inner, chosen,
                                                        np.repeat(u, counts), factors)[0])
        worst = check(every_bound)
        every_ok = worst <= 0.0
    if not every_ok:
        every_bound = _shifted(w, None, 1 if every else -1, tol, precision, slowest)
        worst = check(every_bound)
        every_ok = worst <= 0.0
    for ok, side, bound in ((own_ok, own, own_bound), (every_ok, every, every_bound)):
        if not ok:
            continue
        if side == 0:
            low64 = np.nextafter(bound.astype(np.float64), -np.inf)
            local[:, 0] = np.maximum(local[:, 0], np.clip(low64, 0.0, 1.0))
        else:
            up64 = np.nextafter(bound.astype(np.float64), np.inf)
            local[:, 1] = np.minimum(local[:, 1], np.clip(up64, 0.0, 1.0))
    lo[block.states], hi[block.states] = local[:, 0], local[:, 1]
    logger.debug("policy jump on %d states: policy's bound %s, every choice's %s "
                 "(excess %.1e; %d LUs)", block.states.size, own_ok, every_ok, worst,
                 factors.factorised)
    return own_ok and every_ok


def _exit(block: Block, bound: np.ndarray) -> np.ndarray:
    """Per choice of ``block``, its exit reward from ``bound`` downstream: the column
    of ``block.exits`` for that bound (the same sums)."""
    return block.to_target + block.outer @ bound


def _less_owner(scores: np.ndarray, values: np.ndarray, counts: np.ndarray, width: int,
                sense: Sense) -> None:
    """``scores`` replaced in place by ``sense.gain(scores, owner's values)`` (for a
    maximum ``scores - values(owner)``, for a minimum ``values(owner) - scores``): the
    same floats as with ``np.repeat(values, counts)``, which is made only where the
    states' choices are not all ``width``."""
    owner = (np.repeat(values, counts) if width == 0 else
             np.asarray(values)[:, None])
    view = scores if width == 0 else scores.reshape(-1, width)
    if sense is Sense.MAX:
        np.subtract(view, owner, out=view)
    else:
        np.subtract(owner, view, out=view)


def start_policy(block: Block, exit_own: np.ndarray, seed: np.ndarray,
                 sense: Sense) -> np.ndarray:
    """The policy :func:`jump` starts from (local choice indices): greedy on ``seed``,
    the block's bound a policy's own values give (a maximum's lower, a minimum's
    upper), with ``exit_own`` that bound's exit rewards per choice."""
    return segmented_argmax(exit_own + block.inner @ seed, block.groups, sense=sense)


def _shifted(x: np.ndarray, steps: np.ndarray | None, sign: int, tol: float,
             precision: float | None, total: Callable[[np.ndarray], np.ndarray]
             ) -> np.ndarray:
    """``x + sign * e * W`` (the iteration's module docs): ``W = total(u)``, the chain's
    expected total of ``u`` (the states' gap thresholds scaled to at most 1) before it
    leaves, and ``e`` so that ``e W`` is at most a quarter of each threshold (over the
    states of positive value; a state of value 0 keeps its bound there).  With
    thresholds all ``tol``, ``u = 1`` and ``W`` is the expected exit time (``steps`` if
    given)."""
    target = thresholds(np.asarray(x, dtype=np.float64), tol, precision)
    scale = float(np.max(target))
    u = target / scale
    flat = bool(np.all(u == 1.0))
    w = steps if flat and steps is not None else total(u)
    positive = np.asarray(x > 0) if not flat else np.ones(x.shape, dtype=bool)
    ratio = (w / u)[positive] if positive.any() else w / u
    eps = (scale / 4.0) / float(np.max(ratio))
    return x + sign * eps * w
