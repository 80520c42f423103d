r"""The occupancy-measure linear program for maximal reachability, and its duals.

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

**Block by block** (``decompose=True``, the default): the quotient's strongly connected
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

import importlib
import logging
import time
import warnings
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from mitld_lp import defaults
from mitld_lp.mdp import MDP
from mitld_lp.quiet import native_quiet
from mitld_lp.solvers.quotient import (
    Quotient,
    greedy_choices,
    lift_policy,
    quotient_for,
    segmented_argmax,
)
from mitld_lp.solvers.result import LPResult, Status, read_only
from mitld_lp.solvers.topological import (
    Block,
    Blocks,
    blocks,
    gather_ranges,
    improve_policy,
    solve_single_states,
)

__all__ = ["OccupancyLP", "occupancy_lp", "solve_lp"]

logger = logging.getLogger(__name__)

Backend = Literal["auto", "cvxpy", "direct"]


@dataclass(frozen=True, slots=True, eq=False)
class _Matrices:
    """An LP ``max objective'y  s.t.  a_eq y = b_eq, y >= 0`` as a backend sees it."""

    a_eq: sp.csc_array
    b_eq: np.ndarray
    objective: np.ndarray


@dataclass(frozen=True, slots=True, eq=False)
class OccupancyLP:
    """The occupancy LP in matrix form: ``max c'y  s.t.  A y = b, y >= 0``.

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
    ``mdp`` for ``target`` if the caller has it (else it is computed).
    """
    q = quotient_for(mdp, target, quotient)
    n = q.n_states
    a_eq = _flow_matrix(q.choice_state(), n, q.matrix)
    if everywhere:
        b_eq = np.ones(n)
    else:
        b_eq = np.zeros(n)
        if q.initial >= 0:
            b_eq[q.initial] = 1.0
    return OccupancyLP(a_eq, b_eq, np.asarray(q.to_target, dtype=np.float64), q)


# ---------------------------------------------------------------------------------------
# Solving one LP
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _Raw:
    """What a backend returns, in the LP's own (reduced) coordinates."""

    status: Status
    message: str
    y: np.ndarray | None = None
    v: np.ndarray | None = None
    iterations: int = 0


def _tolerance_options(solver: str, tol: float) -> dict[str, Any]:
    """The solver-specific keywords that set the requested accuracy."""
    if solver == "CLARABEL":
        return {"tol_gap_abs": tol, "tol_gap_rel": tol, "tol_feas": tol}
    if solver == "HIGHS":
        tol = max(tol, 1e-10)  # HiGHS rejects feasibility tolerances below 1e-10
        return {"primal_feasibility_tolerance": tol, "dual_feasibility_tolerance": tol}
    if solver == "SCS":
        return {"eps_abs": tol, "eps_rel": tol}
    if solver in ("ECOS", "ECOS_BB"):
        return {"abstol": tol, "reltol": tol, "feastol": tol}
    return {}


def _time_options(solver: str, seconds: float) -> dict[str, Any]:
    """The solver-specific keyword for a wall-clock limit (none for other solvers)."""
    if solver in ("CLARABEL", "HIGHS"):
        return {"time_limit": max(seconds, 1e-3)}
    return {}


_CVXPY_STATUS = {
    "optimal": Status.OPTIMAL,
    "optimal_inaccurate": Status.INACCURATE,
    "infeasible": Status.INFEASIBLE,
    "infeasible_inaccurate": Status.INFEASIBLE,
    "unbounded": Status.UNBOUNDED,
    "unbounded_inaccurate": Status.UNBOUNDED,
    "user_limit": Status.MAX_ITERATIONS,
}


def _is_fatal(exc: BaseException) -> bool:
    return isinstance(exc, KeyboardInterrupt | SystemExit | GeneratorExit | MemoryError)


def _solve_cvxpy(lp: _Matrices, solver: str, options: dict[str, Any]) -> _Raw:
    cp: Any = importlib.import_module("cvxpy")
    m = lp.objective.shape[0]
    y = cp.Variable(m)
    flow = sp.csc_matrix(lp.a_eq) @ y == lp.b_eq
    problem = cp.Problem(cp.Maximize(lp.objective @ y), [flow, y >= 0])
    try:
        with warnings.catch_warnings():  # "may be inaccurate": reported as the status
            warnings.simplefilter("ignore", UserWarning)
            with native_quiet(solver.lower()):  # HiGHS's banner is no answer
                problem.solve(solver=solver, **options)
    except BaseException as exc:  # a solver error must become a status, not a crash
        if _is_fatal(exc):
            raise
        return _Raw(Status.FAILED, f"cvxpy/{solver}: {type(exc).__name__}: {exc}")
    status = _CVXPY_STATUS.get(str(problem.status), Status.FAILED)
    stats = problem.solver_stats
    iterations = int(stats.num_iters) if stats is not None and stats.num_iters else 0
    message = f"cvxpy/{solver}: {problem.status}"
    if not status.has_solution or y.value is None or flow.dual_value is None:
        return _Raw(status if status != Status.OPTIMAL else Status.FAILED, message, None, None,
                    iterations)
    v = np.asarray(flow.dual_value, dtype=np.float64).reshape(-1)
    return _Raw(status, message, np.asarray(y.value, dtype=np.float64), v, iterations)


_CLARABEL_STATUS = {
    "Solved": Status.OPTIMAL,
    "AlmostSolved": Status.INACCURATE,
    "PrimalInfeasible": Status.INFEASIBLE,
    "AlmostPrimalInfeasible": Status.INFEASIBLE,
    "DualInfeasible": Status.UNBOUNDED,
    "AlmostDualInfeasible": Status.UNBOUNDED,
    "MaxIterations": Status.MAX_ITERATIONS,
    "MaxTime": Status.TIME_LIMIT,
}


def _solve_clarabel(lp: _Matrices, options: dict[str, Any]) -> _Raw:
    r"""Call Clarabel on the matrices directly (no cvxpy canonicalisation).

    Clarabel's form is ``min q'x + x'Px/2  s.t.  Ax + s = b, s in K`` with dual
    ``Px + q + A'z = 0, z in K*``.  Here ``x = y``, ``q = -objective``, ``P = 0``,
    ``A = [A_eq; -I]``, ``b = [b_eq; 0]``, ``K = {0}^n x R_+^m``.  The dual equation reads
    ``A_eq' z_eq = objective + z_nn >= objective``: ``z_eq`` is the value function ``v``.
    """
    clarabel: Any = importlib.import_module("clarabel")
    n, m = lp.b_eq.shape[0], lp.objective.shape[0]
    a = sp.vstack([lp.a_eq, -sp.eye_array(m, format="csc")], format="csc")
    b = np.concatenate([lp.b_eq, np.zeros(m)])
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    for key, val in options.items():
        if not hasattr(settings, key):
            return _Raw(Status.FAILED, f"clarabel: unknown setting {key!r}")
        setattr(settings, key, val)
    try:
        solver = clarabel.DefaultSolver(
            sp.csc_matrix((m, m)),
            -lp.objective,
            sp.csc_matrix(a),
            b,
            [clarabel.ZeroConeT(n), clarabel.NonnegativeConeT(m)],
            settings,
        )
        solution = solver.solve()
    except BaseException as exc:  # includes pyo3's PanicException
        if _is_fatal(exc):
            raise
        return _Raw(Status.FAILED, f"clarabel: {type(exc).__name__}: {exc}")
    word = str(solution.status)
    status = _CLARABEL_STATUS.get(word, Status.FAILED)
    message = f"clarabel: {word}"
    iterations = int(solution.iterations)
    if not status.has_solution:
        return _Raw(status, message, None, None, iterations)
    x = np.asarray(solution.x, dtype=np.float64)
    z = np.asarray(solution.z, dtype=np.float64)
    return _Raw(status, message, x, z[:n], iterations)


def _unusable(solver: str, backend: str) -> str | None:
    """Why ``solver`` cannot be run through ``backend``, or ``None`` if it can (checked
    before any work: the block route may need no solver call at all)."""
    if backend == "direct":
        if solver.upper() != "CLARABEL":
            return f"backend 'direct' supports only solver 'CLARABEL', got {solver!r}"
        return None
    if backend != "cvxpy":
        return f"unknown backend {backend!r}; expected 'cvxpy' or 'direct'"
    installed = importlib.import_module("cvxpy").installed_solvers()
    if solver not in installed:
        return (f"solver {solver!r} is not installed for cvxpy; "
                f"installed: {', '.join(installed)}")
    return None


def _run_backend(lp: _Matrices, solver: str, backend: str, options: dict[str, Any]) -> _Raw:
    """One solve of ``lp`` by ``backend`` / ``solver`` (every failure a status)."""
    if backend == "cvxpy":
        return _solve_cvxpy(lp, solver, options)
    return _solve_clarabel(lp, options)


@dataclass(frozen=True, slots=True)
class _Settings:
    """How every LP of one :func:`solve_lp` call is solved."""

    solver: str
    backend: str
    tol: float
    extra: Mapping[str, Any]
    deadline: float  # time.perf_counter() value, inf without a time limit

    def options(self, *, polished: bool = False) -> dict[str, Any]:
        """The solver's keywords; ``polished``: the answer will be made exact by policy
        iteration, so Clarabel's iterative refinement of each KKT solve (1.2-1.9x of its
        time) buys nothing (the values returned are the same to the last digit)."""
        opts = _tolerance_options(self.solver, self.tol)
        if polished and self.solver.upper() == "CLARABEL":
            opts["iterative_refinement_enable"] = False
        if np.isfinite(self.deadline):
            opts.update(_time_options(self.solver, self.deadline - time.perf_counter()))
        return {**opts, **dict(self.extra)}


def _retries(settings: _Settings) -> Iterator[tuple[str, dict[str, Any]]]:
    """Other ways to solve an LP that came back inaccurate (Clarabel only; the user's
    own ``solver_options`` are kept in every one)."""
    if settings.solver.upper() != "CLARABEL":
        return
    base = settings.options()
    yield settings.backend, {**base, "static_regularization_constant": 1e-7,
                             "iterative_refinement_max_iter": 50,
                             "max_iter": 400, **dict(settings.extra)}
    other = "direct" if settings.backend == "cvxpy" else "cvxpy"
    yield other, {**base, "equilibrate_max_iter": 50, "max_iter": 400, **dict(settings.extra)}


_DUAL_SLACK = 1e-7
"""A solve whose duals violate a constraint ``v(s) >= r(c) + sum P(c, s') v(s')`` by more
than this is not taken as optimal, whatever the solver says (a badly conditioned LP,
e.g. a component left once in a million steps, can come back "solved" and wrong)."""


def _checked(lp: _Matrices, raw: _Raw) -> _Raw:
    """``raw`` demoted to ``INACCURATE`` if its duals are not feasible (``A' v >= c``)."""
    if raw.status is not Status.OPTIMAL or raw.v is None:
        return raw
    violation = float(np.max(lp.objective - lp.a_eq.T @ raw.v, initial=0.0))
    if violation <= _DUAL_SLACK:
        return raw
    return _Raw(Status.INACCURATE, f"{raw.message}, but its duals violate a Bellman "
                f"inequality by {violation:.1e}", raw.y, raw.v, raw.iterations)


def _solve_one(lp: _Matrices, settings: _Settings, *, retry: bool = True) -> _Raw:
    """Solve ``lp``; with ``retry``, an inaccurate answer (by the solver's word or by
    :func:`_checked`) is retried with other settings (see :func:`_retries`) and the
    first accurate one is kept, else the first answer.  (A block of the topological
    route is not retried: its answer is polished exactly instead.)"""
    if time.perf_counter() >= settings.deadline:
        return _Raw(Status.TIME_LIMIT, "time limit reached before the solve")
    raw = _run_backend(lp, settings.solver, settings.backend,
                       settings.options(polished=not retry))
    if not retry:
        return raw
    raw = _checked(lp, raw)
    if raw.status is not Status.INACCURATE:
        return raw
    for backend, options in _retries(settings):
        if time.perf_counter() >= settings.deadline:
            break
        again = _checked(lp, _run_backend(lp, settings.solver, backend, options))
        logger.info("inaccurate LP retried (%s, %s): %s", backend, sorted(options),
                    again.message)
        if again.status is Status.OPTIMAL:
            return _Raw(again.status, f"{again.message} (retried after: {raw.message})",
                        again.y, again.v, raw.iterations + again.iterations)
    return raw


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
    for level in range(blk.n_levels - 1, -1, -1):
        states = blk.states_at(level)
        lo, hi = q.row_groups[states], q.row_groups[states + 1]
        choices = gather_ranges(lo, hi)
        rows = sp.csr_array(q.matrix[choices])
        owner_local = np.repeat(np.arange(states.size), hi - lo)
        w = weights[choices]
        single = blk.single(states)
        stay = np.bincount(owner_local, weights=w * blk.self_loop[choices],
                           minlength=states.size)
        x[states[single]] /= 1.0 - stay[single]
        if not single.all():
            inner = np.flatnonzero(~single)
            block = states[inner]
            pick = np.isin(owner_local, inner)
            local = np.full(states.size, -1, dtype=np.int64)
            local[inner] = np.arange(inner.size)
            sub = rows[np.flatnonzero(pick)]
            mix = sp.csr_array((w[pick], (local[owner_local[pick]], np.arange(sub.shape[0]))),
                               shape=(inner.size, sub.shape[0]))
            moves = sp.csc_array((mix @ sub[:, block]).T)
            a = sp.csc_array(sp.eye_array(inner.size, format="csc") - moves)
            x[block] = np.asarray(spla.spsolve(a, x[block]), dtype=np.float64).ravel()
        # Push the flow out of this level (its own columns were solved above).
        y = w * x[states[owner_local]]
        coo = rows.tocoo()
        out = blk.level[blk.component[coo.col]] != level
        np.add.at(x, coo.col[out], coo.data[out] * y[coo.row[out]])
    owner = q.choice_state()
    return np.maximum(weights * x[owner], 0.0)


# ---------------------------------------------------------------------------------------
# The two routes
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _Answer:
    """What a route found, in reduced coordinates, before it is mapped back."""

    raw: _Raw  # status, message, iterations (y, v unused)
    y: np.ndarray  # occupancy per reduced choice, from b
    v: np.ndarray  # value per reduced state (nan where unknown)
    reduced_choice: np.ndarray  # the deterministic policy on the quotient
    primal: float
    dual: float
    n_solver_calls: int


def _solve_monolithic(lp: OccupancyLP, settings: _Settings) -> _Answer | _Raw:
    raw = _solve_one(_Matrices(lp.a_eq, lp.b_eq, lp.objective), settings)
    if raw.y is None or raw.v is None:
        return raw
    q = lp.quotient
    y = np.maximum(raw.y, 0.0)
    v = np.clip(raw.v, 0.0, 1.0)
    # Off the visited states (and everywhere if nothing was solved) the greedy fallback
    # needs numbers; an unsolved state gets the trivially dual-feasible value 1.
    reduced_choice = _crossover(
        q, _occupancy_policy(q, y, np.nan_to_num(v, nan=1.0), settings.tol))
    return _Answer(raw, y, v, reduced_choice, float(lp.objective @ y),
                   float(lp.b_eq @ np.nan_to_num(raw.v, nan=0.0)), 1)


def _crossover(q: Quotient, start: np.ndarray) -> np.ndarray:
    """``start`` (a reduced choice per state) made optimal in every state, not only
    where it goes: the one LP's occupancies say nothing where the optimal policy never
    goes, and its duals there are any feasible upper bounds.  Level by level downstream
    first, single states exactly and each block by policy iteration from ``start`` with
    the exact values below as exit rewards (what the decomposed route's polish does)."""
    blk = blocks(q)
    values = np.zeros(q.n_states)
    chosen = np.array(start, dtype=np.int64)
    local = np.zeros(q.n_choices, dtype=np.int64)
    for level in range(blk.n_levels):
        states = blk.states_at(level)
        single = blk.single(states)
        upd = solve_single_states(q, blk, states[single], values)
        chosen[upd.states] = upd.choices
        rest = states[~single]
        if rest.size == 0:
            continue
        block = Block.of(q, rest)
        local[block.choices] = np.arange(block.choices.size)
        pick, v, _ = improve_policy(block, block.to_target + block.outer @ values,
                                    local[chosen[rest]])
        values[rest] = np.clip(np.asarray(v, dtype=np.float64), 0.0, 1.0)
        chosen[rest] = block.choices[pick]
    return chosen


def _block_lp(block: Block, values: np.ndarray) -> _Matrices:
    """The occupancy LP of ``block`` with the values downstream as exit rewards and
    ``b = 1`` on all of it."""
    exit_reward = block.to_target + block.outer @ values
    n = block.states.size
    owner = np.repeat(np.arange(n), np.diff(block.groups))
    return _Matrices(_flow_matrix(owner, n, block.inner), np.ones(n), exit_reward)


@dataclass(frozen=True, slots=True, eq=False)
class _Polished:
    """A block's answer after the crossover: exact values of an optimal policy."""

    chosen: np.ndarray  # local choice per state
    values: np.ndarray
    weights: np.ndarray  # per local choice: the occupancy policy on its tight choices
    optimal: bool  # no choice improves on ``values`` by more than the tie tolerance


def _polish(block: Block, lp: _Matrices, y: np.ndarray, tol: float) -> _Polished:
    """Crossover by policy iteration: the policy of largest occupancy is evaluated
    exactly on the block's chain and improved until no choice gains; an interior-point
    answer is accurate to its tolerance times the block's expected exit time (a block
    left once in a million steps loses six digits), the policy's exact value is not.
    The randomised policy keeps the LP's occupancies on the choices that are tight at
    the exact values (to ``tol`` over the block's expected exit time)."""
    groups = block.groups
    counts = np.diff(groups)
    start = segmented_argmax(y, groups)
    chosen, v_ld, exit_time = improve_policy(block, lp.objective, start)
    v = np.asarray(v_ld, dtype=np.float64)
    slack = np.asarray(np.repeat(v_ld, counts)
                       - (lp.objective + block.inner.astype(np.longdouble) @ v_ld),
                       dtype=np.float64)
    # A choice that loses ``slack`` per step loses up to slack * (expected steps in the
    # block) in all: ties are judged on that scale.
    tie = tol / float(np.max(exit_time))
    kept = np.where(slack <= tie, y, 0.0)
    kept_flow = np.add.reduceat(kept, groups[:-1])
    weights = np.zeros_like(y)
    has = np.repeat(kept_flow > 0, counts)
    weights[has] = kept[has] / np.repeat(kept_flow, counts)[has]
    lone = np.flatnonzero(kept_flow <= 0)
    weights[chosen[lone]] = 1.0
    return _Polished(chosen, np.clip(v, 0.0, 1.0), weights,
                     bool(np.min(slack, initial=0.0) >= -tie))


def _solve_decomposed(q: Quotient, b_eq: np.ndarray, settings: _Settings) -> _Answer | _Raw:
    """Level by level (module docs): exact single-state updates, one LP per level of
    non-trivial components, each answer polished by :func:`_polish`; the occupancy of
    the resulting randomised policy from ``b_eq`` is the primal point, the values the
    dual one."""
    blk: Blocks = blocks(q)
    values = np.zeros(q.n_states)
    weights = np.zeros(q.n_choices)
    reduced_choice = np.zeros(q.n_states, dtype=np.int64)
    worst = _Raw(Status.OPTIMAL, "")
    iterations = calls = 0
    for level in range(blk.n_levels):
        states = blk.states_at(level)
        single = blk.single(states)
        upd = solve_single_states(q, blk, states[single], values)
        reduced_choice[upd.states] = upd.choices
        weights[upd.choices] = 1.0
        rest = states[~single]
        if rest.size == 0:
            continue
        block = Block.of(q, rest)
        lp = _block_lp(block, values)
        raw = _solve_one(lp, settings, retry=False)
        iterations += raw.iterations
        calls += 1
        if raw.y is None or raw.v is None:
            return _Raw(raw.status, f"{raw.message} (block LP of level {level}, "
                        f"{rest.size} states)", iterations=iterations)
        polished = _polish(block, lp, np.maximum(raw.y, 0.0), settings.tol)
        if not polished.optimal and worst.status is Status.OPTIMAL:
            worst = _Raw(Status.INACCURATE, f"level {level}: {raw.message}, policy "
                         "iteration did not settle")
        elif raw.status is not Status.OPTIMAL:
            logger.info("block LP of level %d: %s; exact after policy iteration", level,
                        raw.message)
        values[rest] = polished.values
        reduced_choice[rest] = block.choices[polished.chosen]
        weights[block.choices] = polished.weights
    y = _policy_flow(q, blk, weights, b_eq)
    message = (f"{calls} block LPs and {q.n_states - int(np.sum(blk.size[blk.size > 1]))} "
               f"single states over {blk.n_levels} levels"
               + (f"; {worst.message}" if worst.message else ""))
    if calls:
        solver_word = "cvxpy/" + settings.solver if settings.backend == "cvxpy" else "clarabel"
        message = f"{solver_word}: {message}"
    return _Answer(_Raw(worst.status, message, iterations=iterations), y, values,
                   reduced_choice, float(q.to_target @ y), float(b_eq @ values), calls)


def solve_lp(
    mdp: MDP,
    target: np.ndarray,
    *,
    quotient: Quotient | None = None,
    solver: str = defaults.SOLVER,
    backend: Backend = "auto",
    tol: float = defaults.TOL,
    everywhere: bool = False,
    decompose: bool = True,
    time_limit: float | None = None,
    solver_options: Mapping[str, Any] | None = None,
) -> LPResult:
    """Maximal probability of reaching ``target`` from ``mdp.initial``, by the occupancy LP.

    Args:
        mdp: the MDP.
        target: ``(n_states,)`` bool mask of the states that count as reached
            (``mdp.target`` for the lower model, ``mdp.target | mdp.truncated`` for the
            upper one).
        quotient: ``reduce(mdp, target)`` if the caller already has it.
        solver: with ``backend="cvxpy"`` any LP solver cvxpy has installed, by name
            (``"CLARABEL"``, ``"HIGHS"``, ``"SCS"``, ...); with ``"direct"`` only
            ``"CLARABEL"``.
        backend: ``"cvxpy"`` builds a cvxpy problem; ``"direct"`` calls
            ``clarabel.DefaultSolver`` on the sparse matrices (the same solver without
            cvxpy's canonicalisation and its ~1 s import); ``"auto"`` (default) is
            ``"direct"`` for Clarabel and ``"cvxpy"`` for any other solver.
        tol: accuracy passed to the solver (gap and feasibility tolerances).
        everywhere: start weight 1 on every reduced state instead of only the initial
            one, so ``values`` and the policy are exact / optimal in every state.
        decompose: solve block by block in topological order (module docs); ``False``
            solves the one monolithic LP (the one :func:`write_lp` exports).
        time_limit: seconds; past it the result has status ``TIME_LIMIT``.
        solver_options: extra keywords for the solver (override the tolerance ones),
            e.g. ``{"max_iter": 50}`` for Clarabel.

    An inaccurate Clarabel solve is retried with other settings before it is reported.
    Every failure (missing solver, solver exception, non-optimal termination) comes back
    as a :class:`Status` with the solver's message; nothing is raised for it.
    """
    start = time.perf_counter()
    if backend == "auto":
        backend = "direct" if solver.upper() == "CLARABEL" else "cvxpy"
    lp = occupancy_lp(mdp, target, everywhere=everywhere, quotient=quotient)
    q = lp.quotient
    shape = (q.n_states, q.n_choices)
    logger.info(
        "occupancy LP: %d states -> %d reduced states (%d MECs), %d columns",
        mdp.n_states, q.n_states, q.mecs.n_mecs, q.n_choices,
    )
    settings = _Settings(solver, backend, tol, dict(solver_options or {}),
                         start + time_limit if time_limit is not None else np.inf)

    def failed(raw: _Raw) -> LPResult:
        logger.warning("LP not solved: %s", raw.message)
        return LPResult(
            status=raw.status, message=raw.message, value=float("nan"), values=None,
            primal_objective=float("nan"), dual_objective=float("nan"), occupancy=None,
            policy=None, randomized=None, solver=solver, backend=backend,
            iterations=raw.iterations, seconds=time.perf_counter() - start, lp_shape=shape,
        )

    unusable = _unusable(solver, backend)
    if unusable is not None:
        return failed(_Raw(Status.FAILED, unusable))
    if q.n_states == 0 or (q.initial < 0 and not everywhere):
        # Nothing to optimise: the initial state is decided by the graph analysis.
        reason = "a target state" if q.target[mdp.initial] else "a prob-0 state"
        answer: _Answer | _Raw = _Answer(
            _Raw(Status.OPTIMAL, f"initial state is {reason}: decided by graph analysis, "
                 "no LP solved (values of the other maybe states are nan)"),
            np.zeros(q.n_choices), np.full(q.n_states, np.nan),
            greedy_choices(q, np.ones(q.n_states)), 0.0, 0.0, 0)
    elif decompose:
        answer = _solve_decomposed(q, lp.b_eq, settings)
    else:
        answer = _solve_monolithic(lp, settings)
    if isinstance(answer, _Raw):
        return failed(answer)
    return _result(mdp, q, answer, settings, start, shape)


def _result(mdp: MDP, q: Quotient, answer: _Answer, settings: _Settings, start: float,
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
