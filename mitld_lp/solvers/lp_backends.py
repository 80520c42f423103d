"""One LP handed to a solver: ``max objective'y  s.t.  a_eq y = b_eq, y >= 0`` through
Clarabel directly or through cvxpy (any LP solver it has), with the requested accuracy
and time, its duals checked for feasibility, and an inaccurate answer retried with other
settings.  What the LP means is :mod:`mitld_lp.solvers.lp`'s business."""

from __future__ import annotations

import importlib
import logging
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.clarabel_lp import clarabel_has_faer, is_fatal, solve_clarabel
from mitld_lp.solvers.options import SolveOptions
from mitld_lp.solvers.result import Status
from mitld_lp.util.quiet import native_quiet

__all__ = ["Matrices", "Raw", "solve_one", "solver_keywords", "unusable_reason"]

logger = logging.getLogger("mitld_lp.solvers.lp")


@dataclass(frozen=True, slots=True, eq=False)
class Matrices:
    """An LP ``max objective'y  s.t.  a_eq y = b_eq, y >= 0`` as a backend sees it."""

    a_eq: sp.csc_array
    b_eq: np.ndarray
    objective: np.ndarray



# ---------------------------------------------------------------------------------------
# Solving one LP
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Raw:
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


def _solve_cvxpy(lp: Matrices, solver: str, options: dict[str, Any]) -> Raw:
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
        if is_fatal(exc):
            raise
        return Raw(Status.FAILED, f"cvxpy/{solver}: {type(exc).__name__}: {exc}")
    status = _CVXPY_STATUS.get(str(problem.status), Status.FAILED)
    stats = problem.solver_stats
    iterations = int(stats.num_iters) if stats is not None and stats.num_iters else 0
    message = f"cvxpy/{solver}: {problem.status}"
    if not status.has_solution or y.value is None or flow.dual_value is None:
        return Raw(status if status != Status.OPTIMAL else Status.FAILED, message, None, None,
                    iterations)
    v = np.asarray(flow.dual_value, dtype=np.float64).reshape(-1)
    return Raw(status, message, np.asarray(y.value, dtype=np.float64), v, iterations)


def _solve_clarabel(lp: Matrices, options: dict[str, Any]) -> Raw:
    r"""Call Clarabel on the matrices directly (no cvxpy canonicalisation).

    Clarabel's form is ``min q'x + x'Px/2  s.t.  Ax + s = b, s in K`` with dual
    ``Px + q + A'z = 0, z in K*``.  Here ``x = y``, ``q = -objective``, ``P = 0``,
    ``A = [A_eq; -I]``, ``b = [b_eq; 0]``, ``K = {0}^n x R_+^m``.  The dual equation reads
    ``A_eq' z_eq = objective + z_nn >= objective``: ``z_eq`` is the value function ``v``.
    """
    n, m = lp.b_eq.shape[0], lp.objective.shape[0]
    a = sp.vstack([lp.a_eq, -sp.eye_array(m, format="csc")], format="csc")
    b = np.concatenate([lp.b_eq, np.zeros(m)])
    answer = solve_clarabel(-lp.objective, a, b, zero=n, nonneg=m, settings=options)
    v = None if answer.z is None else answer.z[:n]
    return Raw(answer.status, answer.message, answer.x, v, answer.iterations)


def unusable_reason(solver: str, backend: str) -> str | None:
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


def _run_backend(lp: Matrices, solver: str, backend: str, options: dict[str, Any]) -> Raw:
    """One solve of ``lp`` by ``backend`` / ``solver`` (every failure a status)."""
    if backend == "cvxpy":
        return _solve_cvxpy(lp, solver, options)
    return _solve_clarabel(lp, options)


def solver_keywords(options: SolveOptions, *, polished: bool = False) -> dict[str, Any]:
    """The solver's keywords for ``options``; ``polished``: the answer will be made exact
    by policy iteration, so Clarabel's iterative refinement of each KKT solve (1.2-1.9x
    of its time) buys nothing (the values returned are the same to the last digit), and
    its KKT systems are factorised by faer's supernodal LDL on one thread (0.7-0.8x of
    QDLDL's time on the bus blocks; ``experiments/bench_sweeps.py``)."""
    opts = _tolerance_options(options.solver, options.tol)
    if polished and options.solver.upper() == "CLARABEL":
        opts["iterative_refinement_enable"] = False
        if clarabel_has_faer():
            opts.update(direct_solve_method="faer", max_threads=1)
    left = options.deadline.left()
    if left is not None:
        opts.update(_time_options(options.solver, left))
    return {**opts, **dict(options.extra)}


def _retries(options: SolveOptions) -> Iterator[tuple[str, dict[str, Any]]]:
    """Other ways to solve an LP that came back inaccurate (Clarabel only; the user's
    own ``solver_options`` are kept in every one)."""
    if options.solver.upper() != "CLARABEL":
        return
    base = solver_keywords(options)
    yield options.backend, {**base, "static_regularization_constant": 1e-7,
                            "iterative_refinement_max_iter": 50,
                            "max_iter": 400, **dict(options.extra)}
    other = "direct" if options.backend == "cvxpy" else "cvxpy"
    yield other, {**base, "equilibrate_max_iter": 50, "max_iter": 400, **dict(options.extra)}


_DUAL_SLACK = 1e-7
"""A solve whose duals violate a constraint ``v(s) >= r(c) + sum P(c, s') v(s')`` by more
than this is not taken as optimal, whatever the solver says (a badly conditioned LP,
e.g. a component left once in a million steps, can come back "solved" and wrong)."""


def _checked(lp: Matrices, raw: Raw) -> Raw:
    """``raw`` demoted to ``INACCURATE`` if its duals are not feasible (``A' v >= c``)."""
    if raw.status is not Status.OPTIMAL or raw.v is None:
        return raw
    violation = float(np.max(lp.objective - lp.a_eq.T @ raw.v, initial=0.0))
    if violation <= _DUAL_SLACK:
        return raw
    return Raw(Status.INACCURATE, f"{raw.message}, but its duals violate a Bellman "
                f"inequality by {violation:.1e}", raw.y, raw.v, raw.iterations)


def solve_one(lp: Matrices, options: SolveOptions, *, retry: bool = True) -> Raw:
    """Solve ``lp``; with ``retry``, an inaccurate answer (by the solver's word or by
    :func:`_checked`) is retried with other settings (see :func:`_retries`) and the
    first accurate one is kept, else the first answer.  (A block of the topological
    route is not retried: its answer is polished exactly instead.)"""
    if options.deadline.passed():
        return Raw(Status.TIME_LIMIT, "time limit reached before the solve")
    raw = _run_backend(lp, options.solver, options.backend,
                       solver_keywords(options, polished=not retry))
    if not retry:
        return raw
    raw = _checked(lp, raw)
    if raw.status is not Status.INACCURATE:
        return raw
    for backend, keywords in _retries(options):
        if options.deadline.passed():
            break
        again = _checked(lp, _run_backend(lp, options.solver, backend, keywords))
        logger.info("inaccurate LP retried (%s, %s): %s", backend, sorted(keywords),
                    again.message)
        if again.status is Status.OPTIMAL:
            return Raw(again.status, f"{again.message} (retried after: {raw.message})",
                        again.y, again.v, raw.iterations + again.iterations)
    return raw
