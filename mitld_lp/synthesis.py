"""``synthesize``: the one place that wires the stages.

    spec --to_dta--> DTA --make_sta--> STA --product(game)--> MDP --solve--> policy

The product is built once; its truncation sink counted as losing gives the *lower*
model, as winning the *upper* model.  Each model is solved (occupancy LP or interval
iteration) and certified:

* the extracted deterministic policy is evaluated exactly on its Markov chain (sparse
  solve): a value the policy really achieves;
* interval iteration gives sound lower and upper bounds on the optimum;
* with the LP, its primal objective, its dual objective (the value function at the
  initial state), the policy's value and the iteration bracket must agree within
  ``certify_tol``.

``lower`` is the exact value of the returned policy in the lower model (truncation
counted as failure): the policy achieves at least that in the real, untruncated world.
``upper`` is the sound upper bound of interval iteration on the upper model: no policy
does better.  So the true optimum lies in ``[lower, upper]``, and
``upper - lower <= epsilon_achieved`` up to the solver tolerance.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Literal, NoReturn, TypeAlias

import numpy as np

from mitld_lp import defaults, report
from mitld_lp.automata.dta import DTA
from mitld_lp.automata.sta import STA, make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.checks import Check, close
from mitld_lp.distributions import FirstOccurrence
from mitld_lp.logic.syntax import Formula
from mitld_lp.mdp import MDP
from mitld_lp.model import Model
from mitld_lp.problem import CONSTRAINED, PLAIN, ROBUST, Posed, pose, settings_from
from mitld_lp.product import product
from mitld_lp.running.controller import Controller
from mitld_lp.util.heap import release_free_memory
from mitld_lp.worlds.game import Game

if TYPE_CHECKING:  # the solver stack is imported when a solve needs it (package docs)
    from mitld_lp.routes.acceptance import Acceptance
    from mitld_lp.routes.constrained import ConstrainedResult
    from mitld_lp.routes.robust import RobustResult
    from mitld_lp.solvers.lp import Backend
    from mitld_lp.solvers.quotient import Quotient
    from mitld_lp.solvers.result import IterationResult, LPResult, Status

__all__ = ["synthesize", "synthesize_constrained", "solve", "build_product", "Built",
           "SynthesisResult", "ModelSolution", "Check"]

log = logging.getLogger(__name__)

#: The product size from which its builder's freed memory is handed back to the system
#: (:mod:`mitld_lp.util.heap`).  Below it the process's heap is tens of megabytes: its holes
#: do not matter, while the pages touched again cost a few percent of a short solve.
TRIM_FROM_TRANSITIONS = 1_000_000

Method = Literal["lp", "vi"]


@dataclass(frozen=True, slots=True, eq=False)
class ModelSolution:
    """The solution of one of the two models (lower: truncation loses; upper: it wins)."""

    which: str
    status: Status
    value: float  # the method's optimum at the initial state
    policy: np.ndarray  # deterministic: a choice row per state, -1 where absorbing
    policy_values: np.ndarray  # exact value of ``policy`` in every state (read-only)
    bracket: tuple[float, float]  # interval iteration's sound bounds at the initial state
    lp: LPResult | None
    iteration: IterationResult
    prob0: np.ndarray  # (n_states,) bool: the states from which the target is unreachable
    checks: tuple[Check, ...]

    @property
    def certified(self) -> bool:
        return all(c.passed for c in self.checks)

    @property
    def quotient(self) -> NoReturn:
        """Gone: the reduction is released before the exact evaluations (its matrix was
        a second copy of most transitions); what the result needs of it is ``prob0``."""
        raise AttributeError("ModelSolution.quotient was removed: the reduction is freed "
                             "once the LPs are solved; use ModelSolution.prob0, or "
                             "mitld_lp.solvers.quotient.reduce(mdp, target) to rebuild it")


@dataclass(frozen=True, slots=True, eq=False)
class SynthesisResult:
    """What :func:`synthesize` returns (see the module docstring for the bracket).

    Each quantity has one name: the answer is ``lower``, ``upper``, ``certified`` and
    ``status`` (read from the two models); the policy, the method's optimum, the LP's
    and the iteration's records are those of ``lower_model`` (and ``upper_model``); the
    truncation points and the epsilon achieved are the ``sta``'s; the sizes are the
    ``dta``'s and the ``mdp``'s.

    ``objective="min"``: the two models solve the complement (``dta`` is its automaton,
    the policy maximises the probability of ``not task``); ``lower`` and ``upper`` are
    read back in the task's terms, ``Pmin(task) = 1 - Pmax(not task)``: ``upper`` is
    then what the returned policy guarantees (at most that probability of the task),
    ``lower`` what no policy beats.
    """

    model: Model
    method: Method
    epsilon: float  # the truncation budget asked for (the model's unless overridden)
    dta: DTA
    sta: STA
    mdp: MDP
    lower_model: ModelSolution
    upper_model: ModelSolution
    controller: Controller
    timings: Mapping[str, float]  # seconds per stage: automaton, product, solve
    acceptance: Acceptance  # the target the bracket is about (its goal, its components)
    solve_cpu: float = float("nan")  # CPU seconds of the solve stage (all threads)
    objective: str = "max"
    route: ClassVar[str] = PLAIN

    @property
    def lower(self) -> float:
        """What the returned policy achieves in the real world: its exact value in the
        lower model (runs past a truncation point count as failures).  For
        ``objective="min"``: no policy makes the task less likely."""
        if self.objective == "min":
            return 1.0 - self.upper_model.bracket[1]
        return float(self.lower_model.policy_values[self.mdp.initial])

    @property
    def upper(self) -> float:
        """No policy does better: interval iteration's sound upper bound on the upper
        model (runs past a truncation point count as successes).  For
        ``objective="min"``: the returned policy keeps the task at most this likely."""
        if self.objective == "min":
            return 1.0 - float(self.lower_model.policy_values[self.mdp.initial])
        return self.upper_model.bracket[1]

    @property
    def value(self) -> float:
        """The method's optimum in the task's terms (the lower model's)."""
        v = self.lower_model.value
        return 1.0 - v if self.objective == "min" else v

    @property
    def status(self) -> Status:
        """``OPTIMAL`` when both solves succeeded, else the first other status."""
        from mitld_lp.solvers.result import Status

        return next((m.status for m in (self.lower_model, self.upper_model)
                     if m.status is not Status.OPTIMAL), Status.OPTIMAL)

    @property
    def certified(self) -> bool:
        """Every check of both models passed."""
        return self.lower_model.certified and self.upper_model.certified

    @property
    def failed_checks(self) -> tuple[Check, ...]:
        """The checks that failed, each once (the two models are one when nothing is
        truncated)."""
        models = (self.lower_model,) if self.upper_model is self.lower_model else (
            self.lower_model, self.upper_model)
        return tuple(c for m in models for c in m.checks if not c.passed)

    @property
    def seconds(self) -> float:
        return float(sum(self.timings.values()))

    def __repr__(self) -> str:
        return (
            f"SynthesisResult(model={self.model.name!r}, lower={self.lower:.7g}, "
            f"upper={self.upper:.7g}, certified={self.certified}, "
            f"status={self.status.value!r}, states={self.mdp.n_states})"
        )

    def _repr_html_(self) -> str:
        return report.html(self)

    def policy_table(self) -> list[dict[str, Any]]:
        """The policy as data (:func:`mitld_lp.report.policy_table`)."""
        return report.policy_table(self)

    def write_policy(self, path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
        """Write :meth:`policy_table` to ``path`` (:func:`mitld_lp.files.write.write_policy`)."""
        from mitld_lp.files.write import write_policy

        return write_policy(self, path, overwrite=overwrite)

    def summary(self) -> dict[str, Any]:
        """A JSON-ready record, the CLI's ``--json`` (:func:`mitld_lp.report.summary`)."""
        return report.summary(self)


@dataclass(frozen=True, slots=True)
class _Settings:
    """How each of the two models is solved and certified (:func:`synthesize`'s
    arguments, typed once)."""

    method: Method
    solver: str
    backend: Backend
    tol: float
    certify_tol: float
    progress: bool
    decompose: bool
    deadline: float  # time.perf_counter() past which the solvers stop; inf: none

    def remaining(self) -> float | None:
        """Seconds left before the deadline (None: no deadline)."""
        if self.deadline == float("inf"):
            return None
        return max(0.0, self.deadline - time.perf_counter())


def _solve_lp(mdp: MDP, quotient: Quotient, it: IterationResult,
              how: _Settings) -> LPResult | None:
    """The occupancy LP of one model (None for method ``"vi"``): it works on the model's
    :class:`Quotient`, made by the one analysis of the product both models share
    (:func:`mitld_lp.solvers.analysis.analyse`), with the bounds of ``it``, its interval
    iteration (both models are iterated in one pass, :func:`_iterate`)."""
    if how.method != "lp":
        return None
    from mitld_lp.solvers.lp import solve_lp

    return solve_lp(mdp, np.asarray(quotient.target), quotient=quotient, solver=how.solver,
                    backend=how.backend, tol=how.tol, decompose=how.decompose,
                    time_limit=how.remaining(), bounds=(it.lower, it.upper),
                    everywhere=quotient.initial < 0)


def _certified(mdp: MDP, target: np.ndarray, prob0: np.ndarray,
               layers: tuple[np.ndarray, np.ndarray], it: IterationResult,
               lp: LPResult | None, which: str, how: _Settings) -> ModelSolution:
    """One model's answer and its certificate (module docs), on the product alone: the
    quotient's matrix is released by then.  An LP that did not come back optimal (after
    its own retries) is replaced by the interval-iteration policy, certified the same way
    (exact value inside the bracket) when it failed numerically (``INACCURATE``,
    ``MAX_ITERATIONS``)."""
    from mitld_lp.solvers.iteration import evaluate_policy
    from mitld_lp.solvers.result import Status, read_only

    certify_tol = how.certify_tol
    checks = [
        Check("iteration converged", it.status is Status.OPTIMAL, it.message),
    ]
    policy, value, status = it.policy, it.value_lower, it.status
    if lp is not None:
        if lp.status is Status.OPTIMAL and lp.policy is not None:
            policy, value, status = lp.policy, lp.value, lp.status
            checks.append(Check("LP solved", True, f"{lp.status.value}: {lp.message}"))
            checks.append(close("LP primal = dual", lp.primal_objective, lp.dual_objective,
                                 certify_tol))
        elif lp.status in (Status.INACCURATE, Status.MAX_ITERATIONS) and (
                it.status is Status.OPTIMAL):
            # A numerical failure after the LP's own retries: the answer is the converged
            # iteration's, certified below like method "vi"; the LP's word is kept.
            checks.append(Check("LP replaced by the iteration policy", True,
                                f"{lp.status.value}: {lp.message}"))
        else:  # a usage error (solver not installed), a time limit, or no fallback
            status = lp.status
            checks.append(Check("LP solved", False, f"{lp.status.value}: {lp.message}"))
    values = read_only(evaluate_policy(mdp, target, policy, layers=layers))
    exact = float(values[mdp.initial])
    lo, hi = it.value_lower, it.value_upper
    checks.append(Check(
        "policy value within iteration bracket",
        lo - certify_tol <= exact <= hi + certify_tol,
        f"policy {exact:.10g} in [{lo:.10g}, {hi:.10g}] +- {certify_tol:g}",
    ))
    checks.append(close("policy value = optimum", exact, value, certify_tol))
    checks.append(close("optimum = iteration upper bound", value, hi, certify_tol))
    checks.append(_bellman(mdp, target, values, certify_tol))
    return ModelSolution(which, status, value, policy, values, (lo, hi), lp, it, prob0,
                         tuple(checks))


def _iterate(mdp: MDP, quotients: list[Quotient], how: _Settings) -> list[IterationResult]:
    """Interval iteration of the models in one pass over their shared quotient.  When the
    graph analysis decides the initial state, every component is still brought below the
    tolerance (``gap="max"``), as the LP then solves every state (``everywhere``): the
    certified policy is optimal in every state the Bellman check reads, not only where
    the initial state leads."""
    from mitld_lp.solvers.iteration import interval_iterations

    decided = quotients[0].initial < 0
    return interval_iterations(mdp, quotients, tol=how.tol, progress=how.progress,
                               time_limit=how.remaining(),
                               gap="max" if decided else "initial")


def _bellman(mdp: MDP, target: np.ndarray, values: np.ndarray, tol: float) -> Check:
    """The policy is optimal from every state, not only where it goes: no choice of any
    state does better against the policy's exact values ``V`` than ``V`` itself,
    ``max_c P(c) . V <= V(s) + tol`` (one sweep).  Then ``V`` is a pre-fixed point of
    the Bellman operator, so ``V >= V*`` (the least one), and ``V <= V*`` as a policy's
    values: the policy is optimal in every state."""
    v = np.where(target, 1.0, values)
    best = np.maximum.reduceat(mdp.matrix @ v, mdp.row_groups[:-1])
    gap = np.where(target, 0.0, best - v)
    worst = int(np.argmax(gap)) if gap.size else 0
    over = float(gap[worst]) if gap.size else 0.0
    return Check("policy optimal in every state (Bellman)", over <= tol,
                 f"max_s (max_c P(c).V - V(s)) = {over:.2e} (tol {tol:g})"
                 + (f" at state {mdp.states[worst]}" if over > tol else ""))


def _keeping(mdp: MDP, accept: Acceptance, solution: ModelSolution) -> ModelSolution:
    """For a task with a safety part: ``solution`` whose policy plays, in the accepting
    end components, an internal choice (never one that can leave them), with the check
    that no state of them escapes under the policy.  Unchanged for a co-safe task."""
    if accept.components is None:
        return solution
    from mitld_lp.solvers.accepting import escapes, keep_inside

    policy = keep_inside(accept.components, solution.policy)
    leaving = np.flatnonzero(escapes(mdp, policy, accept.goal))
    check = Check(
        "policy stays in the accepting end components",
        leaving.size == 0,
        f"{int(accept.goal.sum())} states in {accept.components.mecs.n_mecs} components; "
        + (f"states {leaving[:10].tolist()} can leave" if leaving.size else "none can leave"),
    )
    return replace(solution, policy=policy, checks=(*solution.checks, check))


@dataclass(frozen=True, slots=True, eq=False)
class Built:
    """What :func:`build_product` returns: the automaton, the STA and the product MDP,
    with the seconds each construction took (``automaton``, ``product``)."""

    dta: DTA
    sta: STA
    mdp: MDP
    timings: Mapping[str, float]


def build_product(
    game: Game[Any],
    formula: Formula,
    laws: Mapping[str, FirstOccurrence],
    *,
    epsilon: float = defaults.EPSILON,
    clock_reduction: bool = True,
    truncation: Mapping[str, int] | None = None,
    max_states: int = defaults.MAX_STATES,
    max_automaton_states: int = defaults.MAX_AUTOMATON_STATES,
    max_memory: int | None = None,
    progress: bool | None = None,
    complement: bool = False,
) -> Built:
    """The stages up to the MDP: ``to_dta(formula)`` (its complement with
    ``complement``, for a minimised task), ``make_sta`` with the events' ``laws`` and
    the truncation budget ``epsilon`` (or the fixed ``truncation`` points), then the
    reachable ``product`` with ``game``.  Budgets, each checked before the work that
    would exceed it: no state space built here has more than ``max_states`` states; the
    automaton, whose states cost thousands of times more than the product's, also no
    more than ``max_automaton_states`` (:mod:`mitld_lp.defaults`); the product needs at
    most ``max_memory`` bytes (default: half the machine's memory)."""
    t0 = time.perf_counter()
    dta = to_dta(formula, max_states=min(max_states, max_automaton_states))
    if complement:
        dta = dta.complement()
    sta = make_sta(dta, laws, epsilon, clock_reduction=clock_reduction, truncation=truncation)
    t1 = time.perf_counter()
    mdp = product(game, sta, max_states=max_states, max_memory=max_memory, progress=progress)
    t2 = time.perf_counter()
    return Built(dta, sta, mdp, {"automaton": t1 - t0, "product": t2 - t1})


def build_posed(posed: Posed, *, progress: bool | None = None) -> Built:
    """:func:`build_product` of a posed problem's task with its settings."""
    model, s = posed.model, posed.settings
    assert s.max_states is not None and s.max_automaton_states is not None  # resolved
    return build_product(
        model.game, model.spec, model.distributions,
        epsilon=model.epsilon if s.epsilon is None else s.epsilon,
        clock_reduction=s.clock_reduction, truncation=s.truncation_map,
        max_states=s.max_states, max_automaton_states=s.max_automaton_states,
        max_memory=s.max_memory, progress=progress, complement=posed.minimise)


Result: TypeAlias = "SynthesisResult | ConstrainedResult | RobustResult"


def synthesize(
    model: Model,
    *,
    epsilon: float | None = None,
    method: Method = "lp",
    solver: str = defaults.SOLVER,
    backend: Backend = "auto",
    clock_reduction: bool = True,
    truncation: Mapping[str, int] | None = None,
    max_states: int | None = None,
    max_automaton_states: int | None = None,
    max_memory: int | None = None,
    tol: float = defaults.TOL,
    certify_tol: float = defaults.CERTIFY_TOL,
    progress: bool = False,
    decompose: bool | None = None,
    time_limit: float | None = None,
    constraints: Iterable[Any] = (),
    then: str | None = None,
    objective: str | None = None,
) -> Result:
    """Maximise (or, with ``objective="min"`` or the model's own objective, minimise)
    the probability that the model's world satisfies its MITLD spec.

    ``model``: a :class:`Model`, loaded from a file (:func:`mitld_lp.load_model`) or
    made from any game with :meth:`Model.from_game`; ``epsilon`` overrides its
    truncation budget.  ``method``: ``"lp"`` (occupancy LP through Clarabel, called
    directly, or through cvxpy with ``backend="cvxpy"``, which also takes any other
    ``solver`` cvxpy has) or ``"vi"`` (interval iteration alone).  Interval
    iteration always runs, as the cross-check.  ``truncation`` fixes truncation points
    per event instead of ``epsilon``.  The budgets are :func:`build_product`'s (``None``:
    the model file's ``[budgets]``, else the defaults).  ``decompose``: the LP block by
    block in topological order (``None``, the default, or ``True``) or as one LP
    (``False``).  ``time_limit``: seconds for the solve stage; past it the status is
    ``TIME_LIMIT``.  ``constraints`` / ``then`` (and the model's constraints): the
    constrained synthesis (:mod:`mitld_lp.routes.constrained`); a law known only within a band:
    the robust synthesis (:mod:`mitld_lp.routes.robust`).

    The problem is posed once (:func:`mitld_lp.problem.pose`): a combination no route
    solves, or an option its route cannot honour, raises
    :class:`~mitld_lp.problem.ProblemError` naming it.
    """
    settings = settings_from(
        method=method, solver=solver, backend=backend, clock_reduction=clock_reduction,
        decompose=decompose, time_limit=time_limit, max_states=max_states,
        max_automaton_states=max_automaton_states, max_memory=max_memory, epsilon=epsilon,
        truncation=truncation, tol=tol, certify_tol=certify_tol, progress=progress)
    return solve(pose(model, constraints, then=then, settings=settings, objective=objective))


def solve(posed: Posed) -> Result:
    """Solve a posed problem on its route (:mod:`mitld_lp.problem`)."""
    if posed.route == ROBUST:
        from mitld_lp.routes.robust import synthesize_robust

        return synthesize_robust(posed)
    if posed.route == CONSTRAINED:
        return _constrained(posed)
    return _solve_plain(posed)


def _constrained(posed: Posed, costs: Mapping[str, float] | None = None,
                 seed: int | None = 0) -> ConstrainedResult:
    """The constrained route: the occupancy LP with constraint rows, and for a law known
    only within a band its sound robust bracket (:mod:`mitld_lp.routes.robust_constrained`)."""
    if posed.robust:
        from mitld_lp.routes.robust_constrained import solve_robust_constrained

        return solve_robust_constrained(posed, costs=costs, seed=seed)
    from mitld_lp.routes.constrained import solve_constrained

    return solve_constrained(posed, costs=costs, seed=seed)


def synthesize_constrained(
    model: Model,
    constraints: Iterable[Any] = (),
    *,
    then: str | None = None,
    costs: Mapping[str, float] | None = None,
    seed: int | None = 0,
    **options: Any,
) -> ConstrainedResult:
    """Maximise the task's probability subject to ``constraints`` (texts or records;
    the model's own ``constraints`` come first), then, with ``then`` (``"min-steps"``
    or ``"min-cost"``), minimise the expected steps / cost among the policies within
    :data:`~mitld_lp.routes.constraints.LEXICOGRAPHIC_TOL` of that probability; by the
    constrained LP even with no constraint (docs/constraints.md).  ``costs``: per action
    (default the model's ``[costs]``, 1 for any action not named).  ``seed`` seeds the
    controller's generator.  ``options``: :func:`synthesize`'s settings (epsilon,
    budgets, truncation, ...), each honoured or refused by name (:func:`pose`)."""
    posed = pose(model, constraints, then=then, settings=settings_from(**options),
                 constrained=True)
    return _constrained(posed, costs, seed)


def _solve_plain(posed: Posed) -> SynthesisResult:
    """The plain route: point laws, no constraints, any supported task class."""
    model, s = posed.model, posed.settings
    eps = model.epsilon if s.epsilon is None else s.epsilon
    built = build_posed(posed, progress=s.progress or None)
    mdp = built.mdp
    timings: dict[str, float] = dict(built.timings)

    t0, c0 = time.perf_counter(), time.process_time()
    how = _Settings(s.method, s.solver, s.backend, s.tol, s.certify_tol,  # type: ignore[arg-type]
                    s.progress, s.decompose is not False,
                    float("inf") if s.time_limit is None else t0 + s.time_limit)
    from mitld_lp.routes.acceptance import acceptance
    from mitld_lp.solvers.analysis import analyse

    # The builder's freed temporaries go back to the system (mitld_lp.util.heap).
    if mdp.n_transitions >= TRIM_FROM_TRANSITIONS:
        release_free_memory()
    accept = acceptance(mdp, built.dta)
    quotients = analyse(mdp, accept.goal, mdp.truncated)
    quotients = quotients[:1] if quotients[1] is quotients[0] else list(quotients)
    its = _iterate(mdp, quotients, how)
    lps = [_solve_lp(mdp, q, it, how) for q, it in zip(quotients, its, strict=True)]
    # The certificates work on the product: the reduced matrix (a second copy of most
    # transitions) is released before the exact evaluations, where memory peaks.
    kept = [(np.asarray(q.target), q.prob0, q.layers) for q in quotients]
    del quotients
    solutions = [_certified(mdp, *k, it, lp, which, how) for k, it, lp, which in
                 zip(kept, its, lps, ("lower", "upper"), strict=False)]
    low, high = solutions[0], solutions[-1]  # one model when nothing is truncated
    kept_low = _keeping(mdp, accept, low)
    if high is low:
        high = kept_low
    low = kept_low
    timings["solve"] = time.perf_counter() - t0
    solve_cpu = time.process_time() - c0

    result = SynthesisResult(
        model=model,
        method=s.method,  # type: ignore[arg-type]
        epsilon=eps,
        dta=built.dta,
        sta=built.sta,
        mdp=mdp,
        lower_model=low,
        upper_model=high,
        controller=Controller(model.game, built.sta, mdp, low.policy,
                              hopeless=high.prob0),
        timings=timings,
        acceptance=accept,
        solve_cpu=solve_cpu,
        objective=posed.problem.objective,
    )
    log.info("synthesis: [%g, %g], certified=%s", result.lower, result.upper, result.certified)
    return result
