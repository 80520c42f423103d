r"""The occupancy-measure linear program for maximal reachability, and its duals.

On the MEC quotient :math:`\hat M` of the MDP (see :func:`mitld_lp.mdp.reduce`: target
and prob-0 states removed, maximal end components collapsed), with one variable
:math:`y(c) \ge 0` per reduced choice :math:`c` -- the expected number of times
:math:`c` is taken:

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
"""

from __future__ import annotations

import importlib
import logging
import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import scipy.sparse as sp

from mitld_lp.mdp import MDP, Quotient, lift_policy, reduce
from mitld_lp.solvers.result import LPResult, Status

__all__ = ["OccupancyLP", "occupancy_lp", "solve_lp"]

logger = logging.getLogger(__name__)

Backend = Literal["cvxpy", "direct"]


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


def occupancy_lp(mdp: MDP, target: np.ndarray, *, everywhere: bool = False) -> OccupancyLP:
    """Build the occupancy LP of ``mdp`` for reaching ``target`` (see the module docs).

    ``everywhere=False``: ``b = e_initial`` (the LP of the brief: the objective is the
    optimal probability at the initial state; requires the initial state to be a maybe
    state, else ``b = 0``).  ``everywhere=True``: ``b = 1`` on every reduced state, so the
    duals are the exact value function of every state and the occupancy policy is
    optimal from every state (the objective is then the sum of the values).
    """
    q = reduce(mdp, target)
    n, m = q.n_states, q.n_choices
    owner = q.choice_state()
    exits = sp.csc_array((np.ones(m), (owner, np.arange(m))), shape=(n, m))
    a_eq = sp.csc_array(exits - q.matrix.T)
    a_eq.sum_duplicates()
    a_eq.eliminate_zeros()
    if everywhere:
        b_eq = np.ones(n)
    else:
        b_eq = np.zeros(n)
        if q.initial >= 0:
            b_eq[q.initial] = 1.0
    return OccupancyLP(a_eq, b_eq, np.asarray(q.to_target, dtype=np.float64), q)


# ---------------------------------------------------------------------------------------
# Solving
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


def _solve_cvxpy(lp: OccupancyLP, solver: str, options: dict[str, Any]) -> _Raw:
    cp: Any = importlib.import_module("cvxpy")
    installed = cp.installed_solvers()
    if solver not in installed:
        return _Raw(
            Status.FAILED,
            f"solver {solver!r} is not installed for cvxpy; installed: {', '.join(installed)}",
        )
    m = lp.objective.shape[0]
    y = cp.Variable(m)
    flow = sp.csc_matrix(lp.a_eq) @ y == lp.b_eq
    problem = cp.Problem(cp.Maximize(lp.objective @ y), [flow, y >= 0])
    try:
        with warnings.catch_warnings():  # "may be inaccurate": reported as the status
            warnings.simplefilter("ignore", UserWarning)
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


def _solve_clarabel(lp: OccupancyLP, options: dict[str, Any]) -> _Raw:
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


# ---------------------------------------------------------------------------------------
# Policies from the solution
# ---------------------------------------------------------------------------------------


def segmented_argmax(
    values: np.ndarray, row_groups: np.ndarray, *, tie: float = 0.0,
    prefer: np.ndarray | None = None,
) -> np.ndarray:
    """Per group ``row_groups[i]:row_groups[i+1]`` (all non-empty), the index of the max.

    Entries within ``tie`` of the group's maximum count as tied; among them the one with
    the largest ``prefer`` wins, then the lowest index.  Fully vectorised.
    """
    starts = np.asarray(row_groups[:-1], dtype=np.int64)
    counts = np.diff(row_groups)
    best = np.maximum.reduceat(values, starts)
    tied = values >= np.repeat(best, counts) - tie
    if prefer is not None:
        key = np.where(tied, prefer, -np.inf)
        top = np.maximum.reduceat(key, starts)
        tied &= key >= np.repeat(top, counts)
    idx = np.where(tied, np.arange(values.shape[0]), np.iinfo(np.int64).max)
    return np.minimum.reduceat(idx, starts)


def greedy_choices(q: Quotient, v: np.ndarray, *, tie: float = 1e-12) -> np.ndarray:
    """Per reduced state, the reduced choice maximising ``P(c,target) + sum P(c,s') v(s')``.

    Ties (within ``tie``) go to the choice with the larger one-step probability of
    entering the target, a cheap measure of progress.  On the quotient every policy
    leaves the maybe states almost surely (no end components remain), so a greedy
    policy on exact values is optimal and never loops forever.
    """
    scores = q.to_target + q.matrix @ v
    return segmented_argmax(scores, q.row_groups, tie=tie, prefer=q.to_target)


def _visit_threshold(tol: float) -> float:
    return max(1e-7, 100.0 * tol)


def _lp_policy(
    mdp: MDP, q: Quotient, y: np.ndarray, v: np.ndarray, tol: float
) -> tuple[np.ndarray, np.ndarray]:
    """Deterministic and randomised policies on ``mdp`` from occupancies and duals.

    At a reduced state whose outflow exceeds the visit threshold: the choice of largest
    occupancy; elsewhere the greedy choice on ``v``.  Lifted through the MEC quotient by
    :func:`mitld_lp.mdp.lift_policy`.
    """
    outflow = np.add.reduceat(y, q.row_groups[:-1])
    visited = outflow > _visit_threshold(tol)
    by_flow = segmented_argmax(y, q.row_groups)
    by_value = greedy_choices(q, v)
    reduced_choice = np.where(visited, by_flow, by_value)
    policy = lift_policy(mdp, q, reduced_choice)

    occupancy = np.zeros(mdp.n_choices)
    occupancy[q.choice_origin] = y
    cstate = mdp.choice_state()
    state_flow = np.bincount(cstate, weights=occupancy, minlength=mdp.n_states)
    seen = state_flow > _visit_threshold(tol)
    randomized = np.zeros(mdp.n_choices)
    seen_c = seen[cstate]
    randomized[seen_c] = occupancy[seen_c] / state_flow[cstate[seen_c]]
    acting = np.flatnonzero(~seen & (policy >= 0))
    randomized[policy[acting]] = 1.0
    return policy, randomized


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a)
    a.setflags(write=False)
    return a


def solve_lp(
    mdp: MDP,
    target: np.ndarray,
    *,
    solver: str = "CLARABEL",
    backend: Backend = "cvxpy",
    tol: float = 1e-9,
    everywhere: bool = False,
    solver_options: Mapping[str, Any] | None = None,
) -> LPResult:
    """Maximal probability of reaching ``target`` from ``mdp.initial``, by the occupancy LP.

    Args:
        mdp: the MDP.
        target: ``(n_states,)`` bool mask of the states that count as reached
            (``mdp.target`` for the lower model, ``mdp.target | mdp.truncated`` for the
            upper one).
        solver: with ``backend="cvxpy"`` any LP solver cvxpy has installed, by name
            (``"CLARABEL"``, ``"HIGHS"``, ``"SCS"``, ...); with ``"direct"`` only
            ``"CLARABEL"``.
        backend: ``"cvxpy"`` builds a cvxpy problem; ``"direct"`` calls
            ``clarabel.DefaultSolver`` on the sparse matrices (faster on large models).
        tol: accuracy passed to the solver (gap and feasibility tolerances).
        everywhere: start weight 1 on every reduced state instead of only the initial
            one, so ``values`` and the policy are exact / optimal in every state.
        solver_options: extra keywords for the solver (override the tolerance ones),
            e.g. ``{"max_iter": 50}`` for Clarabel.

    The LP, its dual and how answers map back are in the module docstring.  Every
    failure (missing solver, solver exception, non-optimal termination) comes back as a
    :class:`Status` with the solver's message; nothing is raised for it.
    """
    start = time.perf_counter()
    lp = occupancy_lp(mdp, target, everywhere=everywhere)
    q = lp.quotient
    shape = (q.n_states, q.n_choices)
    logger.info(
        "occupancy LP: %d states -> %d reduced states (%d MECs), %d columns",
        mdp.n_states, q.n_states, q.mecs.n_mecs, q.n_choices,
    )

    def failed(status: Status, message: str, iterations: int = 0) -> LPResult:
        logger.warning("LP not solved: %s", message)
        return LPResult(
            status=status, message=message, value=float("nan"), values=None,
            primal_objective=float("nan"), dual_objective=float("nan"), occupancy=None,
            policy=None, randomized=None, solver=solver, backend=backend,
            iterations=iterations, seconds=time.perf_counter() - start, lp_shape=shape,
        )

    options = {**_tolerance_options(solver, tol), **dict(solver_options or {})}
    if q.n_states == 0 or (q.initial < 0 and not everywhere):
        # Nothing to optimise: the initial state is decided by the graph analysis.
        reason = "a target state" if q.target[mdp.initial] else "a prob-0 state"
        raw = _Raw(
            Status.OPTIMAL,
            f"initial state is {reason}: decided by graph analysis, no LP solved "
            "(values of the other maybe states are nan)",
            np.zeros(q.n_choices),
            np.full(q.n_states, np.nan),
        )
        used_solver = ""
    elif backend == "cvxpy":
        raw = _solve_cvxpy(lp, solver, options)
        used_solver = solver
    elif backend == "direct":
        if solver.upper() != "CLARABEL":
            return failed(Status.FAILED,
                          f"backend 'direct' supports only solver 'CLARABEL', got {solver!r}")
        raw = _solve_clarabel(lp, options)
        used_solver = "CLARABEL"
    else:
        return failed(Status.FAILED,
                      f"unknown backend {backend!r}; expected 'cvxpy' or 'direct'")
    if raw.y is None or raw.v is None:
        return failed(raw.status, raw.message, raw.iterations)

    y = np.maximum(raw.y, 0.0)
    v_red = np.clip(raw.v, 0.0, 1.0)
    values = q.lift(v_red)
    if q.initial < 0:
        value = q.initial_value
    else:
        value = float(values[mdp.initial])
    # Off the visited states (and everywhere if nothing was solved) the greedy fallback
    # needs numbers; an unsolved state gets the trivially dual-feasible value 1.
    policy, randomized = _lp_policy(mdp, q, y, np.nan_to_num(v_red, nan=1.0), tol)
    occupancy = np.zeros(mdp.n_choices)
    occupancy[q.choice_origin] = y
    primal = float(lp.objective @ y)
    dual = float(lp.b_eq @ np.nan_to_num(raw.v, nan=0.0))
    seconds = time.perf_counter() - start
    logger.info("LP %s in %.3fs: value %.12g (%s)", raw.status.value, seconds, value,
                raw.message)
    return LPResult(
        status=raw.status,
        message=raw.message,
        value=value,
        values=_frozen(values),
        primal_objective=primal,
        dual_objective=dual,
        occupancy=_frozen(occupancy),
        policy=_frozen(policy),
        randomized=_frozen(randomized),
        solver=used_solver,
        backend=backend,
        iterations=raw.iterations,
        seconds=seconds,
        lp_shape=shape,
    )
