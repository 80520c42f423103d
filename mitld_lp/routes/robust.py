"""Robust synthesis: the policy that maximises the worst-case probability of the task when
some event's law is a band (docs/semantics.md, "Laws known roughly").

    spec --to_dta--> DTA --make_sta--> STA --robust_product--> interval MDP
         --vertex_rows--> robust game --robust interval iteration--> bracket, policy

Each of the two models (truncation losing / winning) is solved and certified:

* robust interval iteration brackets the robust optimum ``V* = max_robot min_nature``
  on every state (:func:`mitld_lp.solvers.robust.robust_interval_iteration`);
* a robot policy is read off its lower bound, and the policy's own robust value (what it
  guarantees against every adversary) is bracketed by the same iteration on the game
  the policy leaves (its lower bound is the ``lower`` reported: sound, as every value of
  the iteration from below) and computed again by the LP of
  :mod:`mitld_lp.solvers.robust_lp` (Clarabel); the two must agree;
* the policy's value must lie in the bracket and reach its upper bound, and be a fixed
  point of the robust Bellman operator (one sweep: then it is the least fixed point,
  the robust value).

``lower`` is the policy's exact robust value in the lower model: whatever law of the band
the events follow, even one chosen step by step against the robot, the policy achieves
at least that.  ``upper`` is the iteration's upper bound in the upper model: no policy
guarantees more.  With bands that are points every step is today's
:func:`mitld_lp.synthesis.synthesize` (and the model takes that route).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp import defaults
from mitld_lp.automata.dta import DTA, SAFE
from mitld_lp.automata.sta import make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.checks import Check, close
from mitld_lp.controllers.kinds import Controller
from mitld_lp.distributions import FirstOccurrence
from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.model import Model
from mitld_lp.problem import CONSTRAINED, ROBUST, Posed, ProblemError, pose, settings_from
from mitld_lp.product import robust_product
from mitld_lp.product.imdp import IntervalMDP, point_mdp, vertex_rows
from mitld_lp.result import Result, from_models
from mitld_lp.routes.acceptance import Acceptance
from mitld_lp.routes.stages import Built, build_posed
from mitld_lp.solvers.result import Status, read_only
from mitld_lp.solvers.robust import (
    RobustIteration,
    bellman_residual,
    robust_interval_iteration,
    robust_policy,
)
from mitld_lp.solvers.robust_graph import RobustGame
from mitld_lp.solvers.robust_lp import PolicyLP, policy_lp

__all__ = ["is_robust", "synthesize_robust", "solve_robust", "RobustModelSolution",
           "robust_game", "interval_model", "interval_export"]

log = logging.getLogger(__name__)


def is_robust(laws: Mapping[str, FirstOccurrence]) -> bool:
    """Whether some law is a band (the task is then solved robustly)."""
    return any(law.is_ambiguous for law in laws.values())


def robust_game(imdp: IntervalMDP) -> RobustGame:
    """The robust game of ``imdp``: nature's rows are the vertex distributions."""
    v = vertex_rows(imdp)
    return RobustGame(v.matrix, v.groups, imdp.row_groups)


@dataclass(frozen=True, slots=True, eq=False)
class RobustModelSolution:
    """The robust solution of one model (lower: truncation loses; upper: it wins)."""

    which: str
    status: Status
    value: float  # the policy's robust value at the initial state (from below)
    iteration: RobustIteration  # the robust optimum's bracket on every state
    policy: np.ndarray  # a choice per state, -1 where absorbing
    policy_values: np.ndarray  # the policy's robust value per state, from below (read-only)
    evaluation: RobustIteration  # the policy's robust value by iteration
    lp: PolicyLP | None  # the policy's robust value by the LP (method "lp")
    bracket: tuple[float, float]  # the robust optimum's bracket at the initial state
    checks: tuple[Check, ...]

    @property
    def certified(self) -> bool:
        return all(c.passed for c in self.checks)


def _solve(game: RobustGame, imdp: IntervalMDP, target: np.ndarray, which: str,
           method: str, tol: float, certify_tol: float,
           deadline: float) -> RobustModelSolution:
    def remaining() -> float | None:
        return None if deadline == float("inf") else max(0.0, deadline - time.perf_counter())

    s0 = imdp.initial
    it = robust_interval_iteration(game, target, tol=tol, time_limit=remaining())
    choice = robust_policy(game, target, it.lower, tie=max(tol, 1e-12))
    ev = robust_interval_iteration(game.restrict(choice), target, tol=tol,
                                   time_limit=remaining())
    checks = [Check("robust iteration converged", it.status is Status.OPTIMAL, it.message),
              Check("policy evaluation converged", ev.status is Status.OPTIMAL, ev.message)]
    values = ev.lower
    status = it.status if it.status is not Status.OPTIMAL else ev.status
    lp = None
    if method == "lp":
        lp = policy_lp(game, target, choice, tol=tol, time_limit=remaining())
        checks.append(Check("policy LP solved", lp.status is Status.OPTIMAL,
                            f"{lp.status.value}: {lp.message}"))
        if lp.values is not None:
            checks.append(close("policy LP = policy iteration", float(lp.values[s0]),
                                 float(ev.lower[s0]), certify_tol))
    lo, hi = float(it.lower[s0]), float(it.upper[s0])
    v0 = float(values[s0])
    checks.append(Check("policy value within robust bracket",
                        lo - certify_tol <= v0 <= hi + certify_tol,
                        f"policy {v0:.10g} in [{lo:.10g}, {hi:.10g}] +- {certify_tol:g}"))
    checks.append(close("policy value = robust optimum (upper bound)", v0, hi, certify_tol))
    residual = bellman_residual(game, target, values)
    checks.append(Check("policy values are a robust Bellman fixed point",
                        residual <= certify_tol,
                        f"max |B V - V| = {residual:.2e} (tol {certify_tol:g})"))
    absorbing = np.asarray(imdp.choice_actions)[choice] == ABSORB
    return RobustModelSolution(which, status, v0, it, read_only(np.where(absorbing, -1, choice)),
                               read_only(np.asarray(values, dtype=np.float64)), ev, lp,
                               (lo, hi), tuple(checks))


def _goal(game: RobustGame, imdp: IntervalMDP, dta: DTA,
          reached: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """The robust reachability target of the task and the choices that stay in it: for a
    co-safe task the states ``reached`` (its accepting state, and truncation in the upper
    model), nothing to stay by; for a task with a safety part the states from which the
    robot keeps the run for ever among persistent states (or ``reached``) whatever law
    of the bands nature plays (:func:`mitld_lp.solvers.robust_graph.keeping`), which
    satisfies the task, with the choice that keeps it there."""
    if SAFE not in dta.kinds:
        return reached, None
    from mitld_lp.routes.acceptance import persistent_states
    from mitld_lp.solvers.robust_graph import keeping

    inside, stay = keeping(game, persistent_states(imdp, dta) | reached)  # type: ignore[arg-type]
    return inside, stay


def _kept(solution: RobustModelSolution, game: RobustGame, goal: np.ndarray,
          stay: np.ndarray | None) -> RobustModelSolution:
    """A task with a safety part: ``solution`` whose policy plays, on the goal, a choice
    that keeps the run there whatever nature plays, with the check that it does."""
    if stay is None:
        return solution
    from dataclasses import replace

    policy = np.array(solution.policy)
    keep = goal & (policy >= 0)
    policy[keep] = stay[keep]
    rows_ok = _rows_kept(game, goal, policy[keep])
    check = Check("policy keeps the task's safety part whatever the bands",
                  bool(rows_ok), f"{int(keep.sum())} states kept")
    return replace(solution, policy=read_only(policy), checks=(*solution.checks, check))


def _rows_kept(game: RobustGame, goal: np.ndarray, choices: np.ndarray) -> bool:
    """Whether every vertex row of ``choices`` has its support in ``goal``."""
    from mitld_lp.solvers.robust_graph import gather

    if choices.size == 0:
        return True
    rows = gather(game.vertex_groups[choices], game.vertex_groups[choices + 1])
    sub = game.matrix[rows]
    return bool(goal[sub.indices].all())


def synthesize_robust(model: Model | Posed, **options: Any) -> Result:
    """The robust synthesis (module docstring) of a posed problem, or of ``model`` with
    :func:`mitld_lp.synthesis.synthesize`'s keyword ``options`` (posed here:
    :class:`~mitld_lp.problem.ProblemError` for a combination it does not solve), also
    when every law is a point (the robust route's answer then equals the plain one).
    ``method="lp"``: the policy's value by the LP and by iteration; ``"vi"``: by
    iteration only.  :func:`mitld_lp.synthesize` takes this route by itself for a
    problem with a band."""
    posed = model if isinstance(model, Posed) else pose(model, settings=settings_from(**options))
    if posed.route == CONSTRAINED:
        raise ProblemError("synthesize_robust: a task with constraints is not solved "
                           "robustly")
    return solve_robust(posed, build_posed(posed, progress=posed.settings.progress,
                                           robust=True))


def solve_robust(posed: Posed, built: Built) -> Result:
    """The robust route on its built interval MDP (:func:`mitld_lp.synthesis.solve`)."""
    model, s = posed.model, posed.settings
    eps = model.epsilon if s.epsilon is None else s.epsilon
    imdp, dta, sta = built.mdp, built.dta, built.sta
    assert isinstance(imdp, IntervalMDP)
    t2 = time.perf_counter()
    game = robust_game(imdp)
    deadline = float("inf") if s.time_limit is None else t2 + s.time_limit
    target, stay = _goal(game, imdp, dta, np.asarray(imdp.target, dtype=bool))
    low = _kept(_solve(game, imdp, target, "lower", s.method, s.tol, s.certify_tol,
                       deadline), game, target, stay)
    if imdp.truncated.any():
        upper_goal, upper_stay = _goal(game, imdp, dta, imdp.target | imdp.truncated)
        high = _kept(_solve(game, imdp, upper_goal, "upper", s.method, s.tol,
                            s.certify_tol, deadline), game, upper_goal, upper_stay)
    else:
        high = low
    timings = {**built.timings, "solve": time.perf_counter() - t2}
    controller = Controller(model.game, sta, structure_mdp(imdp), low.policy,
                            hopeless=high.iteration.prob0)
    bands = {e: str(c.distribution) for e, c in sorted(sta.clocks.items())
             if c.distribution.is_ambiguous}
    result = Result(
        route=ROBUST, model=model, objective=posed.problem.objective, method=s.method,
        epsilon=eps, sta=sta, mdp=imdp, dta=dta, controller=controller, timings=timings,
        acceptance=Acceptance(np.asarray(target, dtype=bool), None), goal=read_only(target),
        bands=bands, **from_models(low, high, imdp.initial, posed.problem.objective))
    log.info("robust synthesis: [%g, %g], certified=%s", result.lower, result.upper,
             result.certified)
    return result


def interval_model(
    model: Model,
    *,
    epsilon: float | None = None,
    clock_reduction: bool = True,
    max_states: int = defaults.MAX_STATES,
    max_automaton_states: int = defaults.MAX_AUTOMATON_STATES,
    max_memory: int | None = None,
) -> IntervalMDP:
    """The interval MDP that :func:`synthesize_robust` solves for ``model`` (for export:
    :func:`interval_export`)."""
    return _interval(model, epsilon, clock_reduction, max_states, max_automaton_states,
                     max_memory)[0]


def interval_export(
    model: Model,
    *,
    upper: bool = False,
    epsilon: float | None = None,
    clock_reduction: bool = True,
    max_states: int = defaults.MAX_STATES,
    max_automaton_states: int = defaults.MAX_AUTOMATON_STATES,
    max_memory: int | None = None,
) -> tuple[IntervalMDP, np.ndarray]:
    """The interval MDP of :func:`interval_model` and the states its DRN marks
    ``target`` (:func:`mitld_lp.solvers.robust_export.write_interval_drn`): the set whose
    robust reachability probability is the bracket's end, as :func:`solve_robust` solves
    it -- the task's accepting states (and, with ``upper``, the truncated ones), or for
    a task with a safety part the states from which the robot keeps it whatever law of
    the bands nature plays (:func:`_goal`).  Storm's ``Pmax=? [F "target"]`` on the file
    is then ``lower`` (``upper`` with ``upper=True``), or at most it with several
    ambiguous events at once (docs/robust.md)."""
    imdp, dta = _interval(model, epsilon, clock_reduction, max_states, max_automaton_states,
                          max_memory)
    reached = imdp.target | imdp.truncated if upper else imdp.target
    goal, _ = _goal(robust_game(imdp), imdp, dta, np.asarray(reached, dtype=bool))
    return imdp, np.asarray(goal, dtype=bool)


def _interval(model: Model, epsilon: float | None, clock_reduction: bool, max_states: int,
              max_automaton_states: int, max_memory: int | None) -> tuple[IntervalMDP, DTA]:
    eps = model.epsilon if epsilon is None else defaults.check_epsilon(epsilon)
    dta = to_dta(model.spec, max_states=min(max_states, max_automaton_states))
    sta = make_sta(dta, model.distributions, eps, clock_reduction=clock_reduction)
    return robust_product(model.game, sta, max_states=max_states, max_memory=max_memory), dta


def structure_mdp(imdp: IntervalMDP) -> MDP:
    """An MDP with ``imdp``'s states and choices whose row of each choice is its first
    branch (the structure a controller reads; no value is computed on it)."""
    return point_mdp(imdp, sp.csr_array(imdp.branches[imdp.branch_groups[:-1]]))
