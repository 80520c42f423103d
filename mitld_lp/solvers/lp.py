r"""The occupancy-measure linear program for maximal (or minimal) reachability, and its
duals.

On the MEC quotient :math:`\hat M` of the MDP (see
:func:`mitld_lp.solvers.quotient.reduce`: target and prob-0 states removed, maximal end
components collapsed), with one variable :math:`y(c) \ge 0` per reduced choice
:math:`c` -- the expected number of times :math:`c` is taken:

.. math::

    \max_{y \ge 0} \; \sum_c y(c)\, \hat P(c, \mathit{target})
    \quad\text{s.t.}\quad
    \sum_{c \in \mathit{Act}(s)} y(c) - \sum_{c'} y(c')\, \hat P(c', s) = b(s)
    \quad \text{for every reduced state } s,

with :math:`b = e_{\mathit{initial}}` (or :math:`b = \mathbf 1` with
``everywhere=True``).  Flow into target and into prob-0 states leaves the system: it is
not a variable and has no constraint; only the flow into target is rewarded.  The
quotient has no end components, so every policy leaves it almost surely and the
feasible set is a bounded polytope (without the collapse, a self-loop could carry
unbounded flow).

The dual is the value LP

.. math::

    \min_v \; \sum_s b(s)\, v(s)
    \quad\text{s.t.}\quad
    v(s) \ge \hat P(c, \mathit{target}) + \sum_{s'} \hat P(c, s')\, v(s')
    \quad \text{for every choice } c \text{ of } s,

so the equality multipliers are the value function: every dual-feasible :math:`v` is an
upper bound on the optimal reach probability, and at an optimum :math:`v(s)` is exact on
every state with :math:`b(s) > 0` or positive occupancy.

**A minimum** (a quotient of ``sense`` :attr:`~mitld_lp.solvers.graph.Sense.MIN`, whose
prob-0 states are ``Prob0E`` and which has no end component either) is the same LP with
:math:`\min` for :math:`\max`; its dual is :math:`\max_v \sum_s b(s) v(s)` subject to
:math:`v(s) \le \hat P(c, \mathit{target}) + \sum_{s'} \hat P(c, s') v(s')`.  It is
handed to the solver as the maximum of the negated rewards, whose duals are the negated
values.

**Block by block** (``layout=Layout.BLOCKS``, the default): the quotient's strongly connected
components are solved level by level, downstream first
(:mod:`mitld_lp.solvers.topological`).  A single-state component is solved exactly; the
non-trivial components of one level form one LP of the same form restricted to their
states, where a choice's objective is its *exit reward*
:math:`\hat P(c, \mathit{target}) + \sum_{s' \text{ solved}} \hat P(c, s')\, v(s')` and
:math:`b = \mathbf 1` on every state of the block, so the block's duals are exact values
on all of it.  The components of one level are independent, so one LP per level is the
same as one per component (its matrix is block diagonal) with one solver call instead
of many.  The interior-point method then never sees the fill-in of the whole graph.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import scipy.sparse as sp

from mitld_lp import defaults
from mitld_lp.mdp import MDP
from mitld_lp.solvers.crossover import crossover, polish
from mitld_lp.solvers.eliminate import eliminate, worth_eliminating
from mitld_lp.solvers.graph import Blocks, Sense, gather_ranges, row_entries, segmented_argmax
from mitld_lp.solvers.lp_backends import Matrices, Raw, solve_one, unusable_reason
from mitld_lp.solvers.options import Deadline, Layout, SolveOptions
from mitld_lp.solvers.quotient import lift_policy, quotient_for
from mitld_lp.solvers.reduced import Quotient, greedy_choices, keeping_zero
from mitld_lp.solvers.result import LPResult, Status, read_only
from mitld_lp.solvers.topological import Block, blocks, solve_single_states, transient_solve
from mitld_lp.util.progress import tracked

__all__ = ["Layout", "OccupancyLP", "occupancy_lp", "solve_lp"]

logger = logging.getLogger(__name__)

Backend = Literal["auto", "cvxpy", "direct"]


@dataclass(frozen=True, slots=True, eq=False)
class OccupancyLP:
    """The occupancy LP in matrix form: ``max c'y  s.t.  A y = b, y >= 0`` (``min`` when
    the quotient's sense is a minimum).

    Attributes:
        a_eq: ``(n_reduced_states, n_reduced_choices)`` CSC, ``A = E - P_hat^T`` where
            ``E[s, c] = 1`` iff reduced choice ``c`` belongs to reduced state ``s``.
        b_eq: ``(n_reduced_states,)`` the start weights ``b``.
        objective: ``(n_reduced_choices,)`` ``P_hat(c, target)``.
        quotient: the reduction the LP lives on (maps answers back).
    """

    a_eq: sp.csc_array
    b_eq: np.ndarray
    objective: np.ndarray
    quotient: Quotient


def _flow_matrix(owner: np.ndarray, n_states: int, moves: sp.csr_array) -> sp.csc_array:
    """``E - P^T`` for choices owned by ``owner`` moving by ``moves`` (rows: choices)."""
    m = owner.shape[0]
    exits = sp.csc_array((np.ones(m), (owner, np.arange(m))), shape=(n_states, m))
    a_eq = sp.csc_array(exits - moves.T)
    a_eq.sum_duplicates()
    a_eq.eliminate_zeros()
    return a_eq


def occupancy_lp(
    mdp: MDP, target: np.ndarray, *, everywhere: bool = False, quotient: Quotient | None = None
) -> OccupancyLP:
    """Build the (monolithic) occupancy LP of ``mdp`` for reaching ``target``.

    ``everywhere=False``: ``b = e_initial`` (the objective is the optimal probability at
    the initial state; requires the initial state to be a maybe state, else ``b = 0``).
    ``everywhere=True``: ``b = 1`` on every reduced state, so the duals are the exact
    value function of every state and the occupancy policy is optimal from every state
    (the objective is then the sum of the values).  ``quotient``: the reduction of
    ``mdp`` for ``target`` if the caller has it (else it is computed, for a maximum).
    """
    q = quotient_for(mdp, target, quotient, quotient.sense if quotient else Sense.MAX)
    a_eq = _flow_matrix(q.choice_state(), q.n_states, q.matrix)
    return OccupancyLP(a_eq, _start_weights(q, everywhere),
                       np.asarray(q.to_target, dtype=np.float64), q)


def _start_weights(q: Quotient, everywhere: bool) -> np.ndarray:
    """``b``: 1 on every reduced state, or on the initial one (if it is one)."""
    if everywhere:
        return np.ones(q.n_states)
    b_eq = np.zeros(q.n_states)
    if q.initial >= 0:
        b_eq[q.initial] = 1.0
    return b_eq


# ---------------------------------------------------------------------------------------
# Policies from the solution
# ---------------------------------------------------------------------------------------


def _visit_threshold(tol: float) -> float:
    return max(1e-7, 100.0 * tol)


def _randomized(
    mdp: MDP, q: Quotient, occupancy: np.ndarray, policy: np.ndarray, tol: float
) -> np.ndarray:
    """The randomised policy of the occupancies: ``y(c) / sum_{c' of s} y(c')`` at the
    states whose outflow exceeds the visit threshold, ``policy`` elsewhere."""
    cstate = mdp.choice_state()
    state_flow = np.bincount(cstate, weights=occupancy, minlength=mdp.n_states)
    seen = state_flow > _visit_threshold(tol)
    randomized = np.zeros(mdp.n_choices)
    seen_c = seen[cstate]
    randomized[seen_c] = occupancy[seen_c] / state_flow[cstate[seen_c]]
    acting = np.flatnonzero(~seen & (policy >= 0))
    randomized[policy[acting]] = 1.0
    return randomized


def _occupancy_policy(q: Quotient, y: np.ndarray, v: np.ndarray, tol: float) -> np.ndarray:
    """Per reduced state: the choice of largest occupancy where the outflow exceeds the
    visit threshold, the greedy choice on ``v`` elsewhere."""
    outflow = np.add.reduceat(y, q.row_groups[:-1])
    visited = outflow > _visit_threshold(tol)
    by_flow = segmented_argmax(y, q.row_groups)
    return np.where(visited, by_flow, greedy_choices(q, v))


def _policy_flow(q: Quotient, blk: Blocks, weights: np.ndarray, b: np.ndarray) -> np.ndarray:
    r"""Occupancy of the randomised policy ``weights`` (per reduced choice, summing to 1
    per state) from the start weights ``b``: ``x = b + P_w^T x`` with
    ``P_w = sum_c w(c) P_hat(c, .)``, then ``y(c) = w(c) x(owner(c))``.

    Solved in topological order, upstream first: the flow into a level comes only from
    higher levels, so a single state gets ``x(s) = (b(s) + inflow(s)) / (1 - w'p)`` and a
    non-trivial component one sparse solve of its own size.  The policy's chain leaves
    the quotient almost surely, so every one of these systems is invertible.
    """
    x = np.asarray(b, dtype=np.float64).copy()  # b, then inflow added level by level
    for level in blk.walk(upstream_first=True):
        states = np.concatenate([level.single, level.rest])
        n_single = level.single.size
        lo, hi = q.row_groups[states], q.row_groups[states + 1]
        choices = gather_ranges(lo, hi)
        owner_local = np.repeat(np.arange(states.size), hi - lo)
        w = weights[choices]
        stay = np.bincount(owner_local, weights=w * blk.self_loop[choices],
                           minlength=states.size)
        x[level.single] /= 1.0 - stay[:n_single]
        if level.rest.size:
            block = level.rest  # the tail of ``states``: local index = owner - n_single
            pick = owner_local >= n_single
            sub = sp.csr_array(q.matrix[choices[pick]])
            mix = sp.csr_array((w[pick], (owner_local[pick] - n_single,
                                          np.arange(sub.shape[0]))),
                               shape=(block.size, sub.shape[0]))
            moves = sp.csc_array((mix @ sub[:, block]).T)
            x[block] = transient_solve(moves, x[block])
        # Push the flow out of this level (its own columns were solved above).
        y = w * x[states[owner_local]]
        row, col, val = row_entries(q.matrix, choices)
        out = blk.level[blk.component[col]] != level.index
        np.add.at(x, col[out], val[out] * y[row[out]])
    owner = q.choice_state()
    return np.maximum(weights * x[owner], 0.0)


# ---------------------------------------------------------------------------------------
# The two routes
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _Answer:
    """What a route found, in reduced coordinates, before it is mapped back."""

    raw: Raw  # status, message, iterations (y, v unused)
    y: np.ndarray  # occupancy per reduced choice, from b
    v: np.ndarray  # value per reduced state (nan where unknown)
    reduced_choice: np.ndarray  # the deterministic policy on the quotient
    primal: float
    dual: float
    n_solver_calls: int


def _sensed(matrices: Matrices, sense: Sense, settings: SolveOptions, *,
            retry: bool = True) -> Raw:
    """:func:`~mitld_lp.solvers.lp_backends.solve_one` of an LP in ``sense``: a minimum as
    the maximum of the negated objective, its duals negated back."""
    if sense is Sense.MAX:
        return solve_one(matrices, settings, retry=retry)
    raw = solve_one(Matrices(matrices.a_eq, matrices.b_eq, -matrices.objective), settings,
                    retry=retry)
    return raw if raw.v is None else Raw(raw.status, raw.message, raw.y, -raw.v,
                                         raw.iterations)


def _solve_monolithic(lp: OccupancyLP, settings: SolveOptions) -> _Answer | Raw:
    q = lp.quotient
    raw = _sensed(Matrices(lp.a_eq, lp.b_eq, lp.objective), q.sense, settings)
    if raw.y is None or raw.v is None:
        return raw
    y = np.maximum(raw.y, 0.0)
    v = np.clip(raw.v, 0.0, 1.0)
    # Off the visited states (and everywhere if nothing was solved) the greedy fallback
    # needs numbers; an unsolved state gets the trivially dual-feasible value (1 for a
    # maximum, 0 for a minimum).
    unsolved = 1.0 if q.sense is Sense.MAX else 0.0
    reduced_choice = crossover(
        q, _occupancy_policy(q, y, np.nan_to_num(v, nan=unsolved), settings.tol))
    return _Answer(raw, y, v, reduced_choice, float(lp.objective @ y),
                   float(lp.b_eq @ np.nan_to_num(raw.v, nan=0.0)), 1)


def _block_lp(block: Block, values: np.ndarray) -> Matrices:
    """The occupancy LP of ``block`` with the values downstream as exit rewards and
    ``b = 1`` on all of it."""
    exit_reward = block.to_target + block.outer @ values
    n = block.states.size
    owner = np.repeat(np.arange(n), np.diff(block.groups))
    return Matrices(_flow_matrix(owner, n, block.inner), np.ones(n), exit_reward)


def _may_be_optimal(block: Block, reward: np.ndarray, lo: np.ndarray,
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


def _tightened(block: Block, reward: np.ndarray, lo: np.ndarray,
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
    keep = _may_be_optimal(block, reward, lo, hi, sense)
    kept = int(np.count_nonzero(keep))
    for _ in range(_TIGHTEN_MAX // _TIGHTEN_ROUND):
        alive = np.flatnonzero(keep)
        inner, r = sp.csr_array(block.inner[alive]), reward[alive]
        # each state keeps a choice, so its first one left starts its group
        starts = np.flatnonzero(np.diff(owner[alive], prepend=-1))
        for _ in range(_TIGHTEN_ROUND):
            np.maximum(lo, sense.reduce(r + inner @ lo, starts), out=lo)
            np.minimum(hi, sense.reduce(r + inner @ hi, starts), out=hi)
        keep = _may_be_optimal(block, reward, lo, hi, sense)
        now = int(np.count_nonzero(keep))
        if now >= kept:
            break
        kept = now
    return lo, hi


_TIGHTEN_ROUND = 25
_TIGHTEN_MAX = 500


def _solve_block(block: Block, lp: Matrices, columns: np.ndarray, sense: Sense,
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
        raw = _sensed(Matrices(sp.csc_array(lp.a_eq[:, columns]), lp.b_eq,
                               lp.objective[columns]) if reduced is None else
                      Matrices(_flow_matrix(reduced.owner, rows, reduced.moves),
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


def _solve_decomposed(q: Quotient, b_eq: np.ndarray, settings: SolveOptions,
                      bounds: tuple[np.ndarray, np.ndarray] | None,
                      progress: bool | None = None
                      ) -> _Answer | Raw:
    """Level by level (module docs): exact single-state updates, one LP per level of
    non-trivial components, each answer polished by
    :func:`~mitld_lp.solvers.crossover.polish`; the occupancy of the resulting
    randomised policy from ``b_eq`` is the primal point, the values the dual one.  With
    sound ``bounds`` on the reduced states' values, a block's LP has
    only the columns of the choices that may be optimal (:func:`_may_be_optimal`); the
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

    The states left with one column are eliminated before the solver when the block
    is large (:mod:`mitld_lp.solvers.eliminate`, :func:`_solve_block`): the LP is
    over the states that keep a choice, and its answer is lifted back to the whole
    block before the polish."""
    blk: Blocks = blocks(q)
    values = np.zeros(q.n_states)
    weights = np.zeros(q.n_choices)
    # a state known to have value 0 takes a choice that keeps it 0 and is not solved
    reduced_choice = (keeping_zero(q) if q.zero.any()
                      else np.asarray(q.row_groups[:-1], dtype=np.int64).copy())
    weights[reduced_choice[q.zero]] = 1.0
    worst = Raw(Status.OPTIMAL, "")
    iterations = calls = n_columns = n_kept = n_eliminated = 0
    todo = q.n_states - int(np.count_nonzero(q.zero))  # the states the levels hold
    for level in tracked(blk.walk(skip=q.zero), progress, lambda lv: lv.states.size,
                         total=todo, desc="block LPs", unit=" states", leave=False):
        upd = solve_single_states(q, blk, level.single, values)
        reduced_choice[upd.states] = upd.choices
        weights[upd.choices] = 1.0
        rest = level.rest
        if rest.size == 0:
            continue
        block = Block.of(q, rest)
        lp = _block_lp(block, values)
        tight = (None if bounds is None else
                 _tightened(block, lp.objective, bounds[0][rest], bounds[1][rest],
                            q.sense))
        columns = (np.arange(block.choices.size) if tight is None else
                   np.flatnonzero(_may_be_optimal(block, lp.objective, *tight, q.sense)))
        raw, y, duals, left = _solve_block(block, lp, columns, q.sense, settings,
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
    y = _policy_flow(q, blk, weights, b_eq)
    message = (f"{calls} block LPs and {q.n_states - int(np.sum(blk.size[blk.size > 1]))} "
               f"single states over {blk.n_levels} levels"
               + (f" ({n_kept} of {n_columns} block columns may be optimal by the bounds)"
                  if bounds is not None and calls else "")
               + (f"; {n_eliminated} single-choice block states eliminated"
                  if n_eliminated else "")
               + (f"; {worst.message}" if worst.message else ""))
    if calls:
        solver_word = "cvxpy/" + settings.solver if settings.backend == "cvxpy" else "clarabel"
        message = f"{solver_word}: {message}"
    return _Answer(Raw(worst.status, message, iterations=iterations), y, values,
                   reduced_choice, float(q.to_target @ y), float(b_eq @ values), calls)


def solve_lp(
    mdp: MDP,
    target: np.ndarray,
    *,
    quotient: Quotient | None = None,
    sense: Sense = Sense.MAX,
    solver: str = defaults.SOLVER,
    backend: Backend = "auto",
    tol: float = defaults.TOL,
    precision: float | None = defaults.PRECISION,
    everywhere: bool = False,
    layout: Layout | str = Layout.BLOCKS,
    time_limit: float | None = None,
    solver_options: Mapping[str, Any] | None = None,
    bounds: tuple[np.ndarray, np.ndarray] | None = None,
    progress: bool | None = None,
) -> LPResult:
    """Maximal (``sense=Sense.MIN``: minimal) probability of reaching ``target`` from
    ``mdp.initial``, by the occupancy LP.

    Args:
        mdp: the MDP.
        target: ``(n_states,)`` bool mask of the states that count as reached
            (``mdp.target`` for the lower model, ``mdp.target | mdp.truncated`` for the
            upper one).
        quotient: ``reduce(mdp, target, sense=sense)`` if the caller already has it.
        sense: maximise or minimise (a given ``quotient`` must have been reduced for
            it).
        solver: with ``backend="cvxpy"`` any LP solver cvxpy has installed, by name
            (``"CLARABEL"``, ``"HIGHS"``, ``"SCS"``, ...); with ``"direct"`` only
            ``"CLARABEL"``.
        backend: ``"cvxpy"`` builds a cvxpy problem; ``"direct"`` calls
            ``clarabel.DefaultSolver`` on the sparse matrices (the same solver without
            cvxpy's canonicalisation and its ~1 s import); ``"auto"`` (default) is
            ``"direct"`` for Clarabel and ``"cvxpy"`` for any other solver.
        tol: accuracy passed to the solver (gap and feasibility tolerances).
        precision: relative precision beside ``tol`` with which the exact values of the
            crossover tell tight choices apart (the randomised policy's support).
        everywhere: start weight 1 on every reduced state instead of only the initial
            one, so ``values`` and the policy are exact / optimal in every state.
        layout: :attr:`Layout.BLOCKS` solves block by block in topological order
            (module docs); :attr:`Layout.WHOLE` the one monolithic LP (the one
            :func:`write_lp` exports).  Its value's name (``"blocks"``, ``"whole"``)
            will do.
        time_limit: seconds; past it the result has status ``TIME_LIMIT``.
        solver_options: extra keywords for the solver (override the tolerance ones),
            e.g. ``{"max_iter": 50}`` for Clarabel.
        bounds: sound lower and upper bounds on the optimal value of every state
            (``(n_states,)`` each, interval iteration's ``lower`` and ``upper``): with
            ``Layout.BLOCKS``, a block's LP leaves out the choices they prove suboptimal
            (every choice is still checked against the exact values afterwards, so a
            wrong bound costs time, never the answer).
        progress: a bar over the blocks' states (:mod:`mitld_lp.util.progress`:
            ``None`` on a terminal only).

    An inaccurate Clarabel solve is retried with other settings before it is reported.
    Every failure (missing solver, solver exception, non-optimal termination) comes back
    as a :class:`Status` with the solver's message; nothing is raised for it.
    """
    start = time.perf_counter()
    if backend == "auto":
        backend = "direct" if solver.upper() == "CLARABEL" else "cvxpy"
    q = quotient_for(mdp, target, quotient, sense)
    b_eq = _start_weights(q, everywhere)
    shape = (q.n_states, q.n_choices)
    logger.info(
        "occupancy LP: %d states -> %d reduced states (%d MECs), %d columns",
        mdp.n_states, q.n_states, q.mecs.n_mecs, q.n_choices,
    )
    layout = Layout(layout)
    settings = SolveOptions(solver, backend, tol, precision, Deadline.after(time_limit, start),
                            dict(solver_options or {}))

    def failed(raw: Raw) -> LPResult:
        logger.warning("LP not solved: %s", raw.message)
        return LPResult(
            status=raw.status, message=raw.message, value=float("nan"), values=None,
            primal_objective=float("nan"), dual_objective=float("nan"), occupancy=None,
            policy=None, randomized=None, solver=solver, backend=backend,
            iterations=raw.iterations, seconds=time.perf_counter() - start, lp_shape=shape,
        )

    unusable = unusable_reason(solver, backend)
    if unusable is not None:
        return failed(Raw(Status.FAILED, unusable))
    if q.n_states == 0 or (q.initial < 0 and not everywhere):
        # Nothing to optimise: the initial state is decided by the graph analysis.
        reason = "a target state" if q.target[mdp.initial] else "a prob-0 state"
        answer: _Answer | Raw = _Answer(
            Raw(Status.OPTIMAL, f"initial state is {reason}: decided by graph analysis, "
                 "no LP solved (values of the other maybe states are nan)"),
            np.zeros(q.n_choices), np.full(q.n_states, np.nan),
            greedy_choices(q, np.full(q.n_states, 1.0 if q.sense is Sense.MAX else 0.0)),
            0.0, 0.0, 0)
    elif layout is Layout.BLOCKS:
        answer = _solve_decomposed(q, b_eq, settings, _reduced_bounds(q, bounds), progress)
    else:  # the whole LP is built only here
        answer = _solve_monolithic(occupancy_lp(mdp, target, everywhere=everywhere,
                                                quotient=q), settings)
    if isinstance(answer, Raw):
        return failed(answer)
    return _result(mdp, q, answer, settings, start, shape)


def _reduced_bounds(q: Quotient, bounds: tuple[np.ndarray, np.ndarray] | None,
                   ) -> tuple[np.ndarray, np.ndarray] | None:
    """Per-state ``bounds`` read on the reduced states (a collapsed end component's
    members share their value, so any member speaks for it)."""
    if bounds is None:
        return None
    kept = np.flatnonzero(q.state_map >= 0)
    rep = np.zeros(q.n_states, dtype=np.int64)
    rep[q.state_map[kept]] = kept
    lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
    if lo.shape != q.state_map.shape or hi.shape != q.state_map.shape:
        raise ValueError(f"bounds: expected two arrays of shape {q.state_map.shape}")
    return lo[rep], hi[rep]


def _result(mdp: MDP, q: Quotient, answer: _Answer, settings: SolveOptions, start: float,
            shape: tuple[int, int]) -> LPResult:
    """The answer of a route mapped back to ``mdp`` (values, policies, occupancy)."""
    values = q.lift(answer.v)
    value = q.initial_value if q.initial < 0 else float(values[mdp.initial])
    policy = lift_policy(mdp, q, answer.reduced_choice)
    occupancy = np.zeros(mdp.n_choices)
    occupancy[q.choice_origin] = answer.y
    randomized = _randomized(mdp, q, occupancy, policy, settings.tol)
    seconds = time.perf_counter() - start
    raw = answer.raw
    logger.info("LP %s in %.3fs: value %.12g (%s)", raw.status.value, seconds, value,
                raw.message)
    return LPResult(
        status=raw.status,
        message=raw.message,
        value=value,
        values=read_only(values),
        primal_objective=answer.primal,
        dual_objective=answer.dual,
        occupancy=read_only(occupancy),
        policy=read_only(policy),
        randomized=read_only(randomized),
        solver=settings.solver if answer.n_solver_calls else "",
        backend=settings.backend,
        iterations=raw.iterations,
        seconds=seconds,
        lp_shape=shape,
    )
