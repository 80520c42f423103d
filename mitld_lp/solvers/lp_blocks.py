"""The occupancy LP block by block (the default layout of :mod:`mitld_lp.solvers.lp`):
the quotient's strongly connected components level by level, downstream first, each
level's non-trivial components one LP whose choices are pruned by sound bounds
(:func:`may_be_optimal`, :func:`tightened`) and whose single-choice states are
eliminated when it is large (:func:`solve_block`), each answer polished to exact values;
and what both layouts share: the flow matrix ``E - P^T`` (:func:`flow_matrix`), an LP
in either sense (:func:`sensed`), a route's answer (:class:`Answer`) and a randomised
policy's occupancy (:func:`policy_flow`)."""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.chain_levels import ChainLevels, chain_solve, offer
from mitld_lp.solvers.crossover import polish
from mitld_lp.solvers.eliminate import eliminate, worth_eliminating
from mitld_lp.solvers.graph import Blocks, Level, Sense, segmented_argmax
from mitld_lp.solvers.greedy_block import certified_greedy
from mitld_lp.solvers.lp_backends import Matrices, Raw, solve_one
from mitld_lp.solvers.options import SolveOptions
from mitld_lp.solvers.reduced import Quotient, keeping_zero
from mitld_lp.solvers.result import Status
from mitld_lp.solvers.rows import gather_ranges, row_entries
from mitld_lp.solvers.settled_levels import settled_by_bounds
from mitld_lp.solvers.shared_levels import RUNS_MIN_LEVELS, shared_levels
from mitld_lp.solvers.topological import (
    Block,
    SingleLevels,
    blocks,
    solve_single_states,
)
from mitld_lp.util.progress import tracked

__all__ = ["Answer", "block_lp", "exit_reward", "flow_matrix", "may_be_optimal",
           "policy_flow", "primal_objective", "product_states", "sensed", "solve_block",
           "solve_decomposed", "tightened"]

logger = logging.getLogger(__name__)


def flow_matrix(owner: np.ndarray, n_states: int, moves: sp.csr_array) -> sp.csc_array:
    """``E - P^T`` for choices owned by ``owner`` moving by ``moves`` (rows: choices)."""
    m = owner.shape[0]
    exits = sp.csc_array((np.ones(m), (owner, np.arange(m))), shape=(n_states, m))
    a_eq = sp.csc_array(exits - moves.T)
    a_eq.sum_duplicates()
    a_eq.eliminate_zeros()
    return a_eq


@dataclass(frozen=True, slots=True)
class Answer:
    """What a route found, in reduced coordinates, before it is mapped back."""

    raw: Raw  # status, message, iterations (y, v unused)
    y: np.ndarray | None  # occupancy per reduced choice, from b (None: not made)
    v: np.ndarray  # value per reduced state (nan where unknown)
    reduced_choice: np.ndarray  # the deterministic policy on the quotient
    primal: float
    dual: float
    n_solver_calls: int


def sensed(matrices: Matrices, sense: Sense, settings: SolveOptions, *,
            retry: bool = True) -> Raw:
    """:func:`~mitld_lp.solvers.lp_backends.solve_one` of an LP in ``sense``: a minimum as
    the maximum of the negated objective, its duals negated back."""
    if sense is Sense.MAX:
        return solve_one(matrices, settings, retry=retry)
    raw = solve_one(Matrices(matrices.a_eq, matrices.b_eq, -matrices.objective), settings,
                    retry=retry)
    return raw if raw.v is None else Raw(raw.status, raw.message, raw.y, -raw.v,
                                         raw.iterations)


def policy_flow(q: Quotient, blk: Blocks, weights: np.ndarray, b: np.ndarray,
                singles: SingleLevels | None = None,
                walks: dict[int, Walked] | None = None
                ) -> np.ndarray:
    r"""Occupancy of the randomised policy ``weights`` (per reduced choice, summing to 1
    per state) from the start weights ``b``: ``x = b + P_w^T x`` with
    ``P_w = sum_c w(c) P_hat(c, .)``, then ``y(c) = w(c) x(owner(c))``.

    Solved in topological order, upstream first: the flow into a level comes only from
    higher levels, so a single state gets ``x(s) = (b(s) + inflow(s)) / (1 - w'p)`` and a
    non-trivial component the policy's own chain there, level by level over that chain's
    components (:func:`~mitld_lp.solvers.chain_levels.chain_solve`: 0.1 s on QVBS
    ``zeroconf`` 1000-4's block of 213,268 states, where one LU of it took 0.7 s).  The
    policy's chain leaves the quotient almost surely, so every one of these systems is
    invertible.
    ``singles``: the single states of every level with their compiled walk
    (:class:`~mitld_lp.solvers.topological.SingleLevels` with kernels), which then
    takes each run of levels between two non-trivial components in one call.
    ``walks``: per level index, a non-trivial level's states (in the walk's order), the
    walk of ``weights``' chain on them that solved its values
    (:class:`~mitld_lp.solvers.greedy_block.Greedy`) and the entries of their choices
    that leave the level (:class:`Walked`); its flow is that walk's transposed solve
    (the same components and factorisations), not a new one, and only those entries
    push it out (the same products added in the same order as the level's whole rows
    with their own entries masked out).
    """
    x = np.asarray(b, dtype=np.float64).copy()  # b, then inflow added level by level
    walk: Iterator[Level] = (blk.walk(upstream_first=True)
                             if singles is None
                             else _flow_runs(blk, singles, weights, x))
    for level in walk:
        kept = None if walks is None else walks.get(level.index)
        if (kept is not None and level.single.size == 0
                and np.array_equal(kept.states, level.rest)):
            x[level.rest] = kept.walk.solve_transposed(x[level.rest])
            kept.push(q, weights, x)
            continue
        states = np.concatenate([level.single, level.rest])
        n_single = level.single.size
        lo, hi = q.row_groups[states], q.row_groups[states + 1]
        choices = gather_ranges(lo, hi)
        owner_local = np.repeat(np.arange(states.size), hi - lo)
        w = weights[choices]
        walked = kept is not None and np.array_equal(kept.states, level.rest)
        if walked or level.rest.size == 0:
            # only the choices the policy takes carry flow: one of a deterministic
            # state's several (the others add +0.0 terms to the sums below, which
            # change no sum of non-negative terms: the same bits without their
            # entries); a cyclic level's chain is built from all of them, as before
            taken = w != 0.0
            if not taken.all():
                choices, owner_local, w = choices[taken], owner_local[taken], w[taken]
            del taken
        stay = np.bincount(owner_local, weights=w * blk.self_loop[choices],
                           minlength=states.size)
        x[level.single] /= 1.0 - stay[:n_single]
        if walked:
            x[level.rest] = kept.walk.solve_transposed(x[level.rest])
        elif level.rest.size:
            block = level.rest  # the tail of ``states``: local index = owner - n_single
            pick = owner_local >= n_single
            sub = sp.csr_array(q.matrix[choices[pick]])
            mix = sp.csr_array((w[pick], (owner_local[pick] - n_single,
                                          np.arange(sub.shape[0]))),
                               shape=(block.size, sub.shape[0]))
            moves = sp.csc_array((mix @ sub[:, block]).T)
            x[block] = chain_solve(moves, x[block])
        # Push the flow out of this level (its own columns were solved above).
        y = w * x[states[owner_local]]
        row, col, val = row_entries(q.matrix, choices)
        out = blk.level[blk.component[col]] != level.index
        np.add.at(x, col[out], val[out] * y[row[out]])
    # y(c) = w(c) x(owner(c)): x spread over the choices and multiplied in place, not the
    # int64 owner of every choice and three float copies a choice (the LP stage's peak
    # on QVBS zeroconf_dl); the same products, in the same operand order
    y = np.repeat(x, np.diff(np.asarray(q.row_groups)))
    np.multiply(weights, y, out=y)
    return np.maximum(y, 0.0, out=y)


@dataclass(frozen=True, slots=True, eq=False)
class Walked:
    """A level settled whole by its greedy policy, kept for :func:`policy_flow`: its
    states (in the block's order), the walk of the policy's chain on them, and its
    choices' entries that leave it (the block's ``outer`` entries, in their order: row
    by row, each row's in its stored order): the local choice (its position among the
    block's choices), column and value of each."""

    states: np.ndarray
    walk: ChainLevels
    row: np.ndarray
    col: np.ndarray
    val: np.ndarray

    @staticmethod
    def of(block: Block, walk: ChainLevels) -> Walked:
        outer = block.outer
        row = np.repeat(np.arange(outer.shape[0], dtype=np.int64), np.diff(outer.indptr))
        # the outer matrix's own arrays (Block.of makes them; the block is dropped
        # once walked), not copies of them
        return Walked(block.states, walk, row, outer.indices, outer.data)

    def push(self, q: Quotient, weights: np.ndarray, x: np.ndarray) -> None:
        """Add the flow ``x`` of the level's states (solved) along its exits: each
        exit's value times its choice's weight times its state's flow, added into
        ``x`` at its column in the entries' order (:func:`policy_flow`'s products and
        order, without the level's inner entries, which it masks out)."""
        if self.row.size == 0:
            return
        lo, hi = q.row_groups[self.states], q.row_groups[self.states + 1]
        first = np.cumsum(hi - lo) - (hi - lo)  # each state's first local choice
        # each local choice's state, then each entry's by a gather (not a binary
        # search an entry over the level's states)
        owner = np.repeat(np.arange(self.states.size), hi - lo)[self.row]
        choice = lo[owner] + (self.row - first[owner])
        y = weights[choice] * x[self.states[owner]]
        np.add.at(x, self.col, self.val * y)


#: The fewest choices of a block the bounds' greedy policy may answer
#: (:mod:`mitld_lp.solvers.greedy_block`): below it the block goes to the LP solver, so
#: an ordinary product (the bundled case's blocks have a few hundred choices: 192 over
#: two blocks) is the solver's occupancy LP with its own duals, the interval iteration
#: an independent cross-check; above it the interior-point method's cost (6 s an
#: iteration on QVBS zeroconf 1000-4's 400,806 choices) is what the certificate of the
#: greedy policy saves.  It was 10,000: QVBS consensus 4-4's block of 5,892 choices then
#: went to Clarabel, its bounds pruned and its answer polished (0.03 s of the stage's
#: 0.07 s), where the greedy policy's check settles it whole; the policy there is then
#: the greedy one, another optimum within the certificate's precision, and the
#: certified bracket is the same to the bit.
GREEDY_MIN_CHOICES = 1_000

_TAKEN = np.zeros(0)
"""A greedy block's ``to_target`` while its array holds the exit rewards
(:func:`solve_decomposed`): empty, so that a read of it as the target's column fails."""


def _block_levels(blk: Blocks) -> np.ndarray:
    """The levels holding a non-trivial component, increasing (``np.unique`` of them,
    without its import of ``numpy.ma``: 15 ms of a process's first call)."""
    marked = np.zeros(blk.n_levels, dtype=bool)
    marked[blk.level[blk.size > 1]] = True
    return np.flatnonzero(marked)


def _flow_runs(blk: Blocks, singles: SingleLevels, weights: np.ndarray,
               x: np.ndarray) -> Iterator[Level]:
    """:func:`policy_flow`'s walk with the single states done a run of levels at a time
    (:meth:`~mitld_lp.solvers.topological.SingleLevels.flow`: their order and
    arithmetic the level walk's): yielded are the levels with a non-trivial component,
    their single states done and ``single`` empty."""
    empty = np.zeros(0, dtype=np.int64)
    done = blk.n_levels  # the levels from ``done`` up are pushed out
    for index in _block_levels(blk)[::-1].tolist():
        # down to this level's single states, which come first
        singles.flow(index, done, blk.self_loop, weights, x)
        done = index
        rest = blk.states_at(index)
        yield Level(index, rest, empty, rest[~blk.single(rest)])
    singles.flow(0, done, blk.self_loop, weights, x)


def _value_runs(q: Quotient, blk: Blocks, singles: SingleLevels, values: np.ndarray,
                reduced_choice: np.ndarray, weights: np.ndarray) -> Iterator[Level]:
    """:func:`solve_decomposed`'s walk with the single states (but ``q.zero``) solved a
    run of levels at a time as :func:`~mitld_lp.solvers.topological.
    solve_single_states` solves them (:meth:`~mitld_lp.solvers.topological.
    SingleLevels.values`): yielded are the runs, each ending at a level with a
    non-trivial component (its states not in ``q.zero`` the ``rest``) or the last,
    ``states`` as many as were solved (for the progress bar), ``single`` empty."""
    empty = np.zeros(0, dtype=np.int64)
    done = last = 0
    marks = _block_levels(blk).tolist() + [blk.n_levels - 1]
    # the states not in ``q.zero`` up to each mark's level's end, counted once (no
    # count a state held through the walk)
    live = np.cumsum(~q.zero[blk.by_level])[blk.level_starts[np.add(marks, 1)] - 1]
    live_at = dict(zip(marks, live.tolist(), strict=True))
    del live
    for index in marks:
        if index < done:  # the last level had a component: nothing after it
            continue
        singles.values(done, index + 1, q.to_target, q.zero, values, reduced_choice,
                       weights)
        rest = blk.states_at(index)
        rest = rest[~blk.single(rest) & ~q.zero[rest]]
        count = live_at[index] - (live_at[last] if done else 0)
        done, last = index + 1, index
        # ``states`` only counts them (the progress bar): a read-only view of one
        # int64 of that size, no array of a state each held through the walk
        yield Level(index, np.broadcast_to(np.int64(0), (count,)), empty, rest)


def block_lp(block: Block, values: np.ndarray, reward: np.ndarray | None = None
             ) -> Matrices:
    """The occupancy LP of ``block`` with the values downstream as exit rewards
    (``reward``, if the caller has them: :func:`exit_reward`) and ``b = 1`` on all of
    it."""
    n = block.states.size
    owner = np.repeat(np.arange(n), np.diff(block.groups))
    return Matrices(flow_matrix(owner, n, block.inner), np.ones(n),
                    exit_reward(block, values) if reward is None else reward)


def exit_reward(block: Block, values: np.ndarray) -> np.ndarray:
    """Per choice of ``block``: what it collects on leaving it, the values downstream
    (``values``) and the target (the LP's objective, :func:`block_lp`)."""
    return block.to_target + block.outer @ values


def may_be_optimal(block: Block, reward: np.ndarray, lo: np.ndarray,
                    hi: np.ndarray, sense: Sense = Sense.MAX) -> np.ndarray:
    r"""The block's choices that can be optimal, given sound bounds ``lo <= v* <= hi``
    on its states: for a maximum, a choice whose upper Q-bound :math:`r(c) +
    \sum_{s'} P(c, s') hi(s')` is below its state's lower bound is not (it loses to the
    optimum); for a minimum, one whose lower Q-bound is above its state's upper bound.
    Each state keeps its choice of best such Q-bound, so rounding never empties a
    state."""
    groups = block.groups
    if sense is Sense.MAX:
        q_hi = reward + block.inner @ hi
        keep = q_hi >= np.repeat(lo * (1.0 - _PRUNE_MARGIN), np.diff(groups))
        keep[segmented_argmax(q_hi, groups)] = True
        return keep
    q_lo = reward + block.inner @ lo
    keep = q_lo <= np.repeat(hi * (1.0 + _PRUNE_MARGIN), np.diff(groups))
    keep[segmented_argmax(q_lo, groups, sense=sense)] = True
    return keep


_PRUNE_MARGIN = 1e-9
"""A choice is left out only if its upper Q-bound is below the state's lower bound by
more than this fraction of it (rounding in the bounds is ~1e-16 of a value; values on
a block can be 1e-19, so an absolute margin would keep every choice there); what is
left out is checked afterwards anyway (:func:`~mitld_lp.solvers.crossover.polish`
improves over every choice of the block)."""


def tightened(block: Block, reward: np.ndarray, lo: np.ndarray,
               hi: np.ndarray, sense: Sense = Sense.MAX) -> tuple[np.ndarray, np.ndarray]:
    """Sound bounds on the block's values made tight enough to prune: both swept (the
    Bellman operator in ``sense`` with the exact exit rewards ``reward``, each bound
    kept if the sweep does not improve it) in rounds of :data:`_TIGHTEN_ROUND` sweeps
    until a round leaves out no further choice, at most :data:`_TIGHTEN_MAX` sweeps.
    The iteration stops at an absolute gap, which says nothing on a block whose values
    are far below it (1e-19 to 1e-9 on the bus blocks of
    ``experiments/bench_sweeps.py``): there only relative precision tells the choices
    apart, and a sweep costs a small fraction of the LP it shrinks.  The sweeps run
    over the choices not yet left out (action elimination): an optimal choice is never
    left out, so the best over the rest is still beyond the optimum on the side a
    policy's value is not (a maximum's upper, a minimum's lower bound), and any choice's
    value is beyond it on the other."""
    lo, hi = np.array(lo, dtype=np.float64), np.array(hi, dtype=np.float64)
    owner = np.repeat(np.arange(lo.size), np.diff(block.groups))
    keep = may_be_optimal(block, reward, lo, hi, sense)
    kept = int(np.count_nonzero(keep))
    for _ in range(_TIGHTEN_MAX // _TIGHTEN_ROUND):
        alive = np.flatnonzero(keep)
        inner, r = sp.csr_array(block.inner[alive]), reward[alive]
        # each state keeps a choice, so its first one left starts its group
        starts = np.flatnonzero(np.diff(owner[alive], prepend=-1))
        for _ in range(_TIGHTEN_ROUND):
            np.maximum(lo, sense.reduce(r + inner @ lo, starts), out=lo)
            np.minimum(hi, sense.reduce(r + inner @ hi, starts), out=hi)
        keep = may_be_optimal(block, reward, lo, hi, sense)
        now = int(np.count_nonzero(keep))
        if now >= kept:
            break
        kept = now
    return lo, hi


_TIGHTEN_ROUND = 25
_TIGHTEN_MAX = 500


def solve_block(block: Block, lp: Matrices, columns: np.ndarray, sense: Sense,
                 settings: SolveOptions, entries: int,
                 ) -> tuple[Raw, np.ndarray | None, np.ndarray | None, int]:
    """One block's LP over its ``columns``: its single-choice states eliminated first
    when the block (in a quotient of ``entries``) is large enough
    (:mod:`mitld_lp.solvers.eliminate`), else whole.
    Returns the solver's answer, the occupancy per block column and the value per block
    state (``None`` if it failed), and the states the LP had."""
    reduced = None
    if worth_eliminating(entries, block.inner.nnz,
                         int(np.diff(block.inner.indptr)[columns].sum())):
        keep = np.zeros(block.choices.size, dtype=bool)
        keep[columns] = True
        reduced = eliminate(block.inner, lp.objective, block.groups, keep)
    rows = block.states.size if reduced is None else reduced.n_m
    if rows == 0:  # every state eliminated: the block's one policy, solved exactly
        raw = Raw(Status.OPTIMAL, "every state eliminated", np.zeros(0), np.zeros(0))
    else:
        raw = sensed(Matrices(sp.csc_array(lp.a_eq[:, columns]), lp.b_eq,
                               lp.objective[columns]) if reduced is None else
                      Matrices(flow_matrix(reduced.owner, rows, reduced.moves),
                               reduced.b_eq, reduced.objective), sense, settings,
                      retry=False)
    if raw.y is None or raw.v is None:
        return raw, None, None, rows
    if reduced is None:
        y = np.zeros(block.choices.size)
        y[columns] = np.maximum(raw.y, 0.0)
        return raw, y, raw.v, rows
    y, v = reduced.lift(np.maximum(raw.y, 0.0), raw.v)
    return raw, y, v, rows


def solve_decomposed(q: Quotient, b_eq: np.ndarray | Callable[[], np.ndarray],
                      settings: SolveOptions,
                      bounds: tuple[np.ndarray, np.ndarray] | None,
                      progress: bool | None = None, *, levels_after: bool = False,
                      primal: bool = True) -> Answer | Raw:
    """Level by level (module docs): exact single-state updates, one LP per level of
    non-trivial components, each answer polished by
    :func:`~mitld_lp.solvers.crossover.polish`; the occupancy of the resulting
    randomised policy from ``b_eq`` (or what it returns, if a function: called only
    for the flow) is the primal point, the values the dual one.  With
    sound ``bounds`` on the reduced states' values, a block's LP has
    only the columns of the choices that may be optimal (:func:`may_be_optimal`); the
    polish then checks every choice of the block against the exact values, so the
    values are those of the whole LP (its duals satisfy every constraint).

    Measured and not done: Clarabel takes no starting point (it computes its own
    initial iterate), so the iteration's bounds cannot warm-start it; handing it the
    dual (value) LP, whose KKT system is a third smaller, took 6-7 interior-point
    iterations instead of 5 and 1.1-1.2x the time on the two block LPs of
    ``bus_scaled`` n128 d3 (faer); bounds tightened further by the exact-self-loop
    sweeps of :mod:`mitld_lp.solvers.kernels` (compiled or not) kept 9,335 columns where
    the plain sweeps keep 9,339 of 32,768 on n64 d3: the columns left are near-ties
    whose gains, 1e-17 to 1e-10, no bracket of width 1e-9 separates.  The kept columns'
    own graph split further (n64 d3: the 8,192-state block into 89 components, the
    largest 3,772, over 35 levels) and solved as one LP per level of it: 0.145 s of
    Clarabel in 33 calls against 0.179 s in one, 20% for a second layering inside the
    block.  On QVBS consensus (4-4) the columns left are ties, not near-ties: with the
    exact optimal values, 37,368 of the 38,496 kept columns of its largest block are
    within 1e-15 of optimal (the symmetric processes), so no bound prunes them.

    ``bounds`` may be anything a block's states index to give their floats (the
    reduced bounds, or :class:`mitld_lp.solvers.lp.OnReduced` gathering them from the
    product's states).

    The states left with one column are eliminated before the solver when the block
    is large (:mod:`mitld_lp.solvers.eliminate`, :func:`solve_block`): the LP is
    over the states that keep a choice, and its answer is lifted back to the whole
    block before the polish.

    ``levels_after``: another LP on a quotient of the same matrix, order and row groups
    follows (the other truncation model's): the single states' levels
    (:func:`~mitld_lp.solvers.shared_levels.shared_levels`) are left kept for it, not
    taken here and built again there (the sensed case's second LP rebuilt them, at its
    peak).

    ``primal=False``: the policy's flow (the primal point) is not made: the answer's
    ``y`` is None and its ``primal`` NaN, the rest the same to the bit (the bound's
    model of a two-model solve: nothing reads its occupancy or its primal
    objective)."""
    blk: Blocks = blocks(q)
    values = np.zeros(q.n_states)
    weights = np.zeros(q.n_choices)
    # a state known to have value 0 takes a choice that keeps it 0 and is not solved
    reduced_choice = (keeping_zero(q, zero_only=True) if q.zero.any()
                      else np.asarray(q.row_groups[:-1], dtype=np.int64).copy())
    weights[reduced_choice[q.zero]] = 1.0
    worst = Raw(Status.OPTIMAL, "")
    iterations = calls = n_columns = n_kept = n_eliminated = n_greedy = 0
    walks: dict[int, Walked] = {}  # greedy chains, for the flow
    told: list[tuple[ChainLevels, np.ndarray]] = []  # walks offered with their states
    todo = q.n_states - int(np.count_nonzero(q.zero))  # the states the levels hold
    # the single states a run of levels at a time (no skip: the flow's walk too)
    # (shared_levels: the iteration's, where it built them for this quotient)
    singles = (shared_levels(q, blk, last=not levels_after)
               if blk.n_levels >= RUNS_MIN_LEVELS
               else None)
    walk = (blk.walk(skip=q.zero) if singles is None else
            iter(()) if settled_by_bounds(q, blk, singles, bounds, values, reduced_choice,
                                          weights) else
            _value_runs(q, blk, singles, values, reduced_choice, weights))
    for level in tracked(walk, progress, lambda lv: lv.states.size,
                         total=todo, desc="block LPs", unit=" states", leave=False):
        upd = solve_single_states(q, blk, level.single, values)
        reduced_choice[upd.states] = upd.choices
        weights[upd.choices] = 1.0
        rest = level.rest
        if rest.size == 0:
            continue
        block = Block.of(q, rest)
        greedy = None
        if not (bounds is None or not settings.greedy
                or block.choices.size < GREEDY_MIN_CHOICES):
            # the exit rewards summed into the block's own copy of the target's column
            # (the sums of exit_reward): not a second float a choice through the
            # greedy check's peak; the block takes a fresh copy back if the LP runs
            reward = block.to_target
            reward += block.outer @ values
            # the block's choices in 4 bytes each through the greedy check's peak (it
            # reads their count only; the one-hot writes below index by them), not 8;
            # the LP takes them back in int64
            narrow = q.n_choices < 2**31 - 1
            block = replace(block, to_target=_TAKEN,
                            choices=(block.choices.astype(np.int32) if narrow
                                     else block.choices))
            greedy = certified_greedy(block, reward,
                                      bounds[0 if q.sense is Sense.MAX else 1], q.sense,
                                      settings.tol, settings.precision, of_quotient=True)
            if greedy is None:
                choices = block.choices.astype(np.int64)
                block = replace(block, to_target=q.to_target[choices], choices=choices)
                del choices
        else:
            reward = exit_reward(block, values)
        if greedy is not None:  # the LP's optimality conditions hold (where not: left)
            picked = block.choices[greedy.chosen]
            values[rest], reduced_choice[rest] = greedy.values, picked
            # its one-hot weights written where they go (no float a block choice)
            weights[block.choices] = 0.0
            weights[picked] = 1.0
            n_greedy += greedy.n_settled
            del picked
            # the certificate's chain there, where the policy ends up the same: told
            # its product states where the block settles whole (the LP's policy there
            # is the walk's; the certificate drops it once its states show it cannot
            # serve), else kept by its levels (:func:`~mitld_lp.solvers.chain_levels.
            # offer`)
            if greedy.left.size:
                offer(greedy.walk)
            else:  # told its states once the flow is made (not held through the levels)
                told.append((greedy.walk, rest))
            if greedy.left.size == 0:  # no LP: its flow matrix is never built
                walks[level.index] = Walked.of(block, greedy.walk)
                continue
            rest = rest[greedy.left]
            block = reward = greedy = None  # type: ignore[assignment]  # freed first
            block = Block.of(q, rest)
            reward = exit_reward(block, values)
        lp = block_lp(block, values, reward)
        tight = (None if bounds is None else
                 tightened(block, lp.objective, bounds[0][rest], bounds[1][rest],
                            q.sense))
        columns = (np.arange(block.choices.size) if tight is None else
                   np.flatnonzero(may_be_optimal(block, lp.objective, *tight, q.sense)))
        raw, y, duals, left = solve_block(block, lp, columns, q.sense, settings,
                                               q.matrix.nnz)
        iterations += raw.iterations
        calls += 1
        n_columns += block.choices.size
        n_kept += columns.size
        n_eliminated += rest.size - left
        if y is None or duals is None:
            return Raw(raw.status, f"{raw.message} (block LP of level {level.index}, "
                        f"{rest.size} states)", iterations=iterations)
        polished = polish(block, lp, y, duals, columns, settings.tol,
                          None if tight is None else tight[0 if q.sense is Sense.MAX else 1],
                          sense=q.sense, precision=settings.precision)
        if not polished.optimal and worst.status is Status.OPTIMAL:
            worst = Raw(Status.INACCURATE, f"level {level.index}: {raw.message}, policy "
                         "iteration did not settle")
        elif raw.status is not Status.OPTIMAL:
            logger.info("block LP of level %d: %s; exact after policy iteration",
                        level.index, raw.message)
        values[rest] = polished.values
        reduced_choice[rest] = block.choices[polished.chosen]
        weights[block.choices] = polished.weights
    # the last block's LP, bounds and answers are not the flow's: freed before it, and
    # so are the reduced states' bounds (two floats a state, this function's own: the
    # caller passes them as a temporary) and the last level (its arrays)
    block = lp = reward = greedy = tight = columns = y = duals = polished = None  # type: ignore[assignment]
    pruned = bounds is not None
    bounds = level = upd = rest = None  # type: ignore[assignment]
    if callable(b_eq):  # made only now: not held through the levels' peaks
        b_eq = b_eq()
    y = policy_flow(q, blk, weights, b_eq, singles, walks) if primal else None
    del weights, walks
    for walk, rest in told:  # (the flow's walks freed first: the stage's peak)
        offer(walk, product_states(q, rest))
    del told
    message = (f"{calls} block LPs and {q.n_states - int(np.sum(blk.size[blk.size > 1]))} "
               f"single states over {blk.n_levels} levels"
               + (f" ({n_kept} of {n_columns} block columns may be optimal by the bounds)"
                  if pruned and calls else "")
               + (f"; {n_eliminated} single-choice block states eliminated"
                  if n_eliminated else "")
               + (f"; {n_greedy} block states by the bounds' greedy policy, certified"
                  if n_greedy else "")
               + (f"; {worst.message}" if worst.message else ""))
    if calls:
        solver_word = "cvxpy/" + settings.solver if settings.backend == "cvxpy" else "clarabel"
        message = f"{solver_word}: {message}"
    # the objectives by NumPy's own sum of products, not BLAS's dot: a threaded BLAS
    # wakes its threads for it (5-12 ms of process time for 31,503 choices on QVBS
    # zeroconf_dl on a loaded machine, where the sum is 0.05 ms; the report's figures
    # only, which may move in their last bits)
    return Answer(Raw(worst.status, message, iterations=iterations), y, values,
                   reduced_choice, primal_objective(q, y),
                   float(np.einsum("i,i->", b_eq, values)), calls)


def product_states(q: Quotient, states: np.ndarray) -> np.ndarray | None:
    """The product states of the reduced ``states`` (increasing), increasing, in 4 bytes
    each where they fit; None where one of them is not one product state's (an end
    component collapsed; the plain reduced states are numbered in the product's order,
    :class:`~mitld_lp.solvers.reduced.Quotient`).  A mark a reduced state and one a
    product state, not the product states of every plain state (QVBS zeroconf
    1000-6-false: 550,097 of 786,928, 8 bytes each at the LP stage's traced peak)."""
    if states.size == 0 or int(states[-1]) >= q.n_plain:
        return None
    m = np.asarray(q.state_map)
    marked = np.zeros(q.n_states + 1, dtype=bool)  # the last: a removed state's (-1)
    marked[states] = True
    got = np.flatnonzero(marked[m])
    if got.size and int(got[-1]) < np.iinfo(np.int32).max:
        got = got.astype(np.int32)
    return got if got.size == states.size else None


def primal_objective(q: Quotient, y: np.ndarray | None) -> float:
    """The flow ``y``'s reward ``sum_c y(c) P_hat(c, target)``, NaN where no flow was made
    (``primal=False``: :func:`solve_decomposed`)."""
    return float("nan") if y is None else float(np.einsum("i,i->", q.to_target, y))
