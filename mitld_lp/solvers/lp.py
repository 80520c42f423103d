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
from mitld_lp.solvers.crossover import crossover
from mitld_lp.solvers.graph import Sense, segmented_argmax
from mitld_lp.solvers.lp_backends import Matrices, Raw, unusable_reason
from mitld_lp.solvers.lp_blocks import (
    Answer,
    flow_matrix,
    policy_flow,
    primal_objective,
    sensed,
    solve_decomposed,
)
from mitld_lp.solvers.options import Deadline, Layout, SolveOptions
from mitld_lp.solvers.quotient import lift_policy, quotient_for
from mitld_lp.solvers.reduced import Quotient, greedy_choices, keeping_zero
from mitld_lp.solvers.result import (
    Lifted,
    LPResult,
    Status,
    entry,
    held,
    lifted,
    read_only,
)
from mitld_lp.solvers.shared_levels import handed
from mitld_lp.util.arrays import SLICE_STATES, spread

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
    a_eq = flow_matrix(q.choice_state(), q.n_states, q.matrix)
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


def _origin_states(mdp: MDP, q: Quotient, origin: np.ndarray) -> np.ndarray:
    """``mdp.state_of(origin)`` for the quotient's ``choice_origin``: the product state
    of each reduced choice.  The plain reduced states (outside any end component) are
    numbered first, in the product's order, each with the choices of its one product
    state (:class:`~mitld_lp.solvers.reduced.Quotient`), so their choices' states are
    those states spread by a repeat, one sequential pass; only the collapsed end
    components' choices are searched in the product's row groups (a binary search a
    choice was a tenth of the LP stage on QVBS csma 4-2)."""
    n_plain = q.n_plain
    plain = np.flatnonzero((q.state_map >= 0) & (q.state_map < n_plain))
    if plain.size != n_plain or origin.shape[0] != q.n_choices:
        return mdp.state_of(origin)
    cut = int(q.row_groups[n_plain])
    owner = np.empty(origin.shape[0], dtype=np.int64)
    owner[:cut] = np.repeat(plain, np.diff(q.row_groups[:n_plain + 1]))
    del plain
    owner[cut:] = mdp.state_of(origin[cut:])
    return owner


def _occupancy(mdp: MDP, origin: np.ndarray, y: np.ndarray, q: Quotient | None = None,
               ) -> tuple[np.ndarray, np.ndarray]:
    """The occupancy of every choice of ``mdp`` (``y`` at the choices ``origin``, 0
    elsewhere) and each state's outflow (the sum of its choices' occupancies).

    ``origin`` (``Quotient.choice_origin``) lists a state's choices in increasing order
    (its other entries in any order), so each outflow adds its choices' ``y`` in the
    product's order, as a sum over all of its choices would (the others add +0.0,
    which changes no sum that starts at +0.0): from arrays of the quotient's choices,
    not the product's ``choice_state`` (an int64 a choice)."""
    # the state of each entry of ``y`` (``q``: the quotient whose ``choice_origin``
    # ``origin`` is, :func:`_origin_states`)
    owner = mdp.state_of(origin) if q is None else _origin_states(mdp, q, origin)
    state_flow = np.bincount(owner, weights=y, minlength=mdp.n_states)
    del owner
    occupancy = np.zeros(mdp.n_choices)
    occupancy[origin] = y
    return occupancy, state_flow


def _randomized(mdp: MDP, occupancy: np.ndarray,
                state_flow: np.ndarray | list[np.ndarray], policy: np.ndarray,
                tol: float) -> np.ndarray:
    """The randomised policy of the occupancies (:func:`_occupancy`): ``y(c) /
    sum_{c' of s} y(c')`` at the states whose outflow exceeds the visit threshold,
    ``policy`` elsewhere.  Divided a slice of states at a time (:data:`SLICE_STATES`):
    the product's ``choice_state`` and its gathered flows and masks, a float and an
    int64 a choice each, were the LP stage's peak on QVBS wlan_dl and csma.
    ``state_flow`` may come in a one-element list, emptied here once the division is
    done, so that it is freed before the policy's ones are written; those are written
    a slice of states at a time too (the policy's choices of every state not visited,
    an int64 a state, were the LP stage's peak on QVBS csma 4-2)."""
    flows = state_flow if isinstance(state_flow, list) else [state_flow]
    flow = flows.pop()
    groups = np.asarray(mdp.row_groups)
    seen = flow > _visit_threshold(tol)
    randomized = np.zeros(mdp.n_choices)
    for lo in range(0, mdp.n_states, SLICE_STATES):
        hi = min(lo + SLICE_STATES, mdp.n_states)
        a, b = int(groups[lo]), int(groups[hi])
        np.divide(occupancy[a:b], spread(flow, groups, lo, hi), out=randomized[a:b],
                  where=spread(seen, groups, lo, hi))
    del flow
    for lo in range(0, mdp.n_states, SLICE_STATES):  # not visited: the policy's choice
        mine = policy[lo:lo + SLICE_STATES]
        randomized[mine[~seen[lo:lo + SLICE_STATES] & (mine >= 0)]] = 1.0
    return randomized


def _occupancy_policy(q: Quotient, y: np.ndarray, v: np.ndarray, tol: float) -> np.ndarray:
    """Per reduced state: the choice of largest occupancy where the outflow exceeds the
    visit threshold, the greedy choice on ``v`` elsewhere."""
    outflow = np.add.reduceat(y, q.row_groups[:-1])
    visited = outflow > _visit_threshold(tol)
    by_flow = segmented_argmax(y, q.row_groups)
    return np.where(visited, by_flow, greedy_choices(q, v))


# ---------------------------------------------------------------------------------------
# The two routes
# ---------------------------------------------------------------------------------------


def _solve_monolithic(lp: OccupancyLP, settings: SolveOptions) -> Answer | Raw:
    q = lp.quotient
    raw = sensed(Matrices(lp.a_eq, lp.b_eq, lp.objective), q.sense, settings)
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
    return Answer(raw, y, v, reduced_choice, float(lp.objective @ y),
                   float(lp.b_eq @ np.nan_to_num(raw.v, nan=0.0)), 1)


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
    bounds: tuple[np.ndarray | Lifted, np.ndarray | Lifted] | None = None,
    progress: bool | None = None,
    greedy: bool = True,
    flows: bool = True,
    levels_after: bool = False,
    primal: bool = True,
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
        greedy: with ``bounds`` and ``Layout.BLOCKS``, a block is first answered by
            the bounds' greedy policy where the LP's optimality conditions (its
            values dual feasible over every choice of the block) certify it, without
            a solver call (:mod:`mitld_lp.solvers.greedy_block`); ``False``: every
            block goes to the solver.  Only on the direct Clarabel route (the
            default): a solver named through cvxpy solves every block, as asked.
        flows: ``False``: the result's ``occupancy`` and ``randomized`` are ``None``,
            not made (two floats a choice of the product; a caller that reads only
            the policy and the values, as the plain route does, keeps them out of the
            certificate's peak).  Everything else is the same to the bit.
        levels_after: another model's LP on a quotient sharing this one's matrix,
            order and row groups comes next: the single states' levels are left for it
            (:func:`~mitld_lp.solvers.lp_blocks.solve_decomposed`); the same answers.
        primal: ``False``: the primal point (the policy's occupancy, a flow over the
            quotient's levels) is not made and ``primal_objective`` is NaN (needs
            ``flows=False``); the values, the policy and the dual objective are the
            same to the bit.  For the bound's model of a two-model solve
            (:func:`mitld_lp.routes.plain.solve_models`), whose occupancy and primal
            objective nothing reads: only the controller's model needs its flow.

    An inaccurate Clarabel solve is retried with other settings before it is reported.
    Every failure (missing solver, solver exception, non-optimal termination) comes back
    as a :class:`Status` with the solver's message; nothing is raised for it.
    """
    start = time.perf_counter()
    if flows and not primal:
        raise ValueError("solve_lp: flows=True needs primal=True (the occupancy is the "
                         "primal point)")
    if backend == "auto":
        backend = "direct" if solver.upper() == "CLARABEL" else "cvxpy"
    q = quotient_for(mdp, target, quotient, sense)
    shape = (q.n_states, q.n_choices)
    logger.info(
        "occupancy LP: %d states -> %d reduced states (%d MECs), %d columns",
        mdp.n_states, q.n_states, q.mecs.n_mecs, q.n_choices,
    )
    layout = Layout(layout)
    settings = SolveOptions(solver, backend, tol, precision, Deadline.after(time_limit, start),
                            dict(solver_options or {}), greedy and backend == "direct")

    def failed(raw: Raw) -> LPResult:
        logger.warning("LP not solved: %s", raw.message)
        return LPResult(
            status=raw.status, message=raw.message, value=float("nan"), held_values=None,
            primal_objective=float("nan"), dual_objective=float("nan"), occupancy=None,
            policy=None, randomized=None, solver=solver, backend=backend,
            iterations=raw.iterations, seconds=time.perf_counter() - start, lp_shape=shape,
        )

    unusable = unusable_reason(solver, backend)
    if unusable is not None:
        return failed(Raw(Status.FAILED, unusable))
    if q.n_states == 0 or (q.initial < 0 and not everywhere):
        # Nothing to optimise: the initial state is decided by the graph analysis.
        reason = ("a target state" if q.target[mdp.initial] else
                  "a state of value 1" if q.initial_value == 1.0 else "a prob-0 state")
        answer: Answer | Raw = Answer(
            Raw(Status.OPTIMAL, f"initial state is {reason}: decided by graph analysis, "
                 "no LP solved (values of the other maybe states are nan)"),
            np.zeros(q.n_choices), np.full(q.n_states, np.nan),
            greedy_choices(q, np.full(q.n_states, 1.0 if q.sense is Sense.MAX else 0.0)),
            0.0, 0.0, 0)
    elif layout is Layout.BLOCKS:
        # the start weights made when the flow needs them (a float a state less
        # through the blocks); a quotient of single states whose values and choices
        # the iteration's walk handed over takes them (_from_iteration)
        answer = (bounds is not None and _from_iteration(q, lambda: _start_weights(
            q, everywhere), primal)) or solve_decomposed(
                q, lambda: _start_weights(q, everywhere), settings,
                _reduced_bounds(q, bounds), progress, levels_after=levels_after,
                primal=primal)
    else:  # the whole LP is built only here
        answer = _solve_monolithic(occupancy_lp(mdp, target, everywhere=everywhere,
                                                quotient=q), settings)
    if isinstance(answer, Raw):
        return failed(answer)
    taken = [answer]  # _result empties it: the reduced arrays freed once mapped back
    del answer
    return _result(mdp, q, taken, settings, start, shape, flows, primal)


def _from_iteration(q: Quotient, b_eq: Any, primal: bool = True) -> Answer | None:
    """The decomposed LP's answer on a quotient of single states only (a deadline's
    product) whose values walk the interval iteration made in its own pass over the
    levels and handed over (:func:`~mitld_lp.solvers.shared_levels.walk_handing`: the
    LP's walk, the same sums in the same order, the same choices among ties): those
    values and choices, the known zeros' choices and the policy's flow from ``b_eq()``
    (the primal point, not made where ``primal`` is False) as
    :func:`~mitld_lp.solvers.lp_blocks.solve_decomposed` makes them; the message says
    where the values were made.  None (nothing done) where
    nothing was handed over."""
    blk = q.order
    if bool((blk.size > 1).any()) or q.n_states == 0:
        return None
    taken = handed(q, blk)
    if taken is None:
        return None
    singles, walked = taken
    zero = np.asarray(q.zero)
    states = np.asarray(singles.states, dtype=np.int64)
    live = ~zero[states]
    reduced_choice = (keeping_zero(q, zero_only=True) if zero.any()
                      else np.asarray(q.row_groups[:-1], dtype=np.int64).copy())
    weights = np.zeros(q.n_choices)
    weights[reduced_choice[zero]] = 1.0
    picks = walked.picks[live]
    reduced_choice[states[live]] = picks
    weights[picks] = 1.0
    values = walked.values
    del picks, walked, live, states, taken
    b_eq = b_eq()
    y = policy_flow(q, blk, weights, b_eq, singles, {}) if primal else None
    message = (f"0 block LPs and {q.n_states} single states over {blk.n_levels} levels "
               "(their values walk made in the interval iteration's pass)")
    return Answer(Raw(Status.OPTIMAL, message), y, values, reduced_choice,
                  primal_objective(q, y), float(np.einsum("i,i->", b_eq, values)), 0)


def _reduced_bounds(q: Quotient,
                    bounds: tuple[np.ndarray | Lifted, np.ndarray | Lifted] | None,
                    ) -> tuple[OnReduced | np.ndarray, OnReduced | np.ndarray] | None:
    """Per-state ``bounds`` read on the reduced states (a collapsed end component's
    members share their value, so any member speaks for it): a bound held on this
    quotient (:meth:`Lifted.on`) as its reduced vector, the same floats; else each
    gathered where a block indexes it (:class:`OnReduced`: one index a reduced state
    held, not two floats), a held one lifted first."""
    if bounds is None:
        return None
    on = [b.on(q.state_map) if isinstance(b, Lifted) else None for b in bounds]
    if on[0] is not None and on[1] is not None:
        return on[0], on[1]
    kept = np.flatnonzero(q.state_map >= 0)
    rep = np.zeros(q.n_states, dtype=np.int32 if q.state_map.size < 2**31 else np.int64)
    rep[q.state_map[kept]] = kept
    del kept
    lo, hi = (np.asarray(lifted(b), dtype=np.float64) for b in bounds)
    if lo.shape != q.state_map.shape or hi.shape != q.state_map.shape:
        raise ValueError(f"bounds: expected two arrays of shape {q.state_map.shape}")
    return OnReduced(lo, rep), OnReduced(hi, rep)


class OnReduced:
    """A bound per state of the product read on the reduced states: ``self[index]`` is
    ``bound[rep[index]]`` (``rep``: a member of each reduced state), the same floats as
    the whole reduced array indexed there, gathered only for the states asked (a block's:
    the reduced bounds are not held through the LP stage's peak)."""

    __slots__ = ("bound", "rep")

    def __init__(self, bound: np.ndarray, rep: np.ndarray) -> None:
        self.bound, self.rep = bound, rep

    def __getitem__(self, index: Any) -> np.ndarray:
        return self.bound[self.rep[index]]


def _result(mdp: MDP, q: Quotient, taken: list[Answer], settings: SolveOptions,
            start: float, shape: tuple[int, int], flows: bool = True,
            primal_made: bool = True) -> LPResult:
    """The answer of a route mapped back to ``mdp`` (values, policies, occupancy).
    ``taken``: a list holding the answer, emptied here, so that its reduced arrays are
    freed as soon as they are mapped back (not held through the per-choice ones).
    ``flows``: whether the occupancy and the randomised policy are made, ``primal_made``
    whether the primal objective is reported (NaN where not: :func:`solve_lp`'s
    ``primal``; the whole LP's solver makes its point either way)."""
    answer = taken.pop()
    raw, primal, dual, calls = answer.raw, answer.primal, answer.dual, answer.n_solver_calls
    if not primal_made:
        primal = float("nan")
    v, reduced_choice, y = answer.v, answer.reduced_choice, answer.y
    del answer
    if not flows:  # the flow (a float a reduced choice) freed before the lifts: they
        del y  # were the LP stage's resident peak on bus_scaled n64 d3 with it alive
    # held on the quotient, lifted where read (Lifted: the certificate does not read
    # them; the plain route's records keep a float a reduced state)
    values = held(v, q.state_map, q.qualitative.one)
    del v
    value = q.initial_value if q.initial < 0 else entry(values, mdp.initial)
    policy = lift_policy(mdp, q, reduced_choice)
    del reduced_choice
    occupancy = randomized = None
    if flows:
        occupancy, state_flow = _occupancy(mdp, q.choice_origin, y, q)
        del y
        flow = [state_flow]  # emptied by _randomized: freed there once it is used
        del state_flow
        randomized = read_only(_randomized(mdp, occupancy, flow, policy, settings.tol))
        occupancy = read_only(occupancy)
    seconds = time.perf_counter() - start
    logger.info("LP %s in %.3fs: value %.12g (%s)", raw.status.value, seconds, value,
                raw.message)
    return LPResult(
        status=raw.status,
        message=raw.message,
        value=value,
        held_values=values,
        primal_objective=primal,
        dual_objective=dual,
        occupancy=occupancy,
        policy=read_only(policy),
        randomized=randomized,
        solver=settings.solver if calls else "",
        backend=settings.backend,
        iterations=raw.iterations,
        seconds=seconds,
        lp_shape=shape,
    )
