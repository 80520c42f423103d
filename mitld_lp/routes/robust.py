"""Robust synthesis: the policy that maximises the worst-case probability of the task when
some event's law is a band (docs/semantics.md, "Laws known roughly").

    spec --to_dta--> DTA --make_sta--> STA --robust_product--> interval MDP
         --vertex_rows--> robust game --robust interval iteration--> bracket, policy

Each of the two models (truncation losing / winning) is solved and certified:

* robust interval iteration brackets the robust optimum ``V* = max_robot min_nature``
  on every state (:func:`mitld_lp.solvers.robust.robust_interval_iteration`);
* a robot policy is read off its lower bound, and its own robust value (what it
  guarantees against every adversary) is computed by the same iteration on the game
  the policy leaves, and by the LP of :mod:`mitld_lp.solvers.robust_lp` (Clarabel) for
  method ``lp``;
* the certificate (:mod:`mitld_lp.solvers.certify`), in exact arithmetic: against the
  policy, nature is an MDP's minimiser over the vertex rows, so the policy's robust
  value is bounded from below by a checked sub-fixed point of nature's minimum; the
  robust optimum from above by a checked pre-fixed point of ``max_c min_rows``; and the
  policy is within the precision of the optimum in every state.

``lower`` is the lower model's bound on the policy's value: whatever law of the band
the events follow, even one chosen step by step against the robot, the policy achieves
at least that.  ``upper`` is the upper model's bound on the robust optimum: no policy
guarantees more.  With bands that are points every step is today's
:func:`mitld_lp.synthesis.synthesize` (and the model takes that route).

``Settings.bands = "best"`` reads the bands optimistically (PRISM's ``Pmaxmax``, Storm's
cooperative resolution): nature picks the law of the bands best for the robot, so it
plays on the robot's side and the game is one MDP whose choices are the pairs (robot
choice, vertex row) (:func:`cooperative`).  The same iteration, policy and certificate
solve it (nature has one row a choice there), the bracket is on ``max_robot
max_nature``, and the controller is the robot's half of the pair: it reaches ``lower``
only when the events follow the law its other half names, and guarantees nothing under
a law of nature's choosing.  For ``objective = "min"`` the complement is maximised, so
nature helps the robot minimise the task's probability.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp import defaults, report
from mitld_lp.automata.dta import DTA, SAFE
from mitld_lp.automata.sta import make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.checks import Check
from mitld_lp.controllers.kinds import Controller
from mitld_lp.distributions import FirstOccurrence
from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.model import Model
from mitld_lp.problem import Posed, ProblemError, pose_on, settings_from
from mitld_lp.product import robust_product
from mitld_lp.product.imdp import IntervalMDP, point_mdp
from mitld_lp.report import bracket_text
from mitld_lp.result import Part, Result, from_models
from mitld_lp.routes.acceptance import Acceptance
from mitld_lp.routes.route import Route
from mitld_lp.routes.stages import Built, build_interval
from mitld_lp.solvers.result import Status, read_only
from mitld_lp.solvers.robust import (
    RobustIteration,
    robust_interval_iteration,
    robust_policy,
)
from mitld_lp.solvers.robust_graph import RobustGame, cooperative, robust_game
from mitld_lp.solvers.robust_lp import PolicyLP, policy_lp
from mitld_lp.util.clock import Deadline

__all__ = ["RobustRoute", "RobustPart", "POINTS_TOO", "is_robust", "synthesize_robust",
           "solve_robust", "RobustModelSolution", "robust_game", "interval_model",
           "interval_export"]

log = logging.getLogger(__name__)


#: What an answer with the bands read for their best law says of its controller.
OPTIMISTIC = ("the bands read for the robot's best law (Pmaxmax): the bracket is the best "
              "case over the bands; the controller reaches it only when the events follow "
              "the law that helps it, and guarantees nothing under a law of nature's "
              "choosing (Settings.bands = 'worst' gives the guarantee)")


def is_robust(laws: Mapping[str, FirstOccurrence]) -> bool:
    """Whether some law is a band (the task is then solved robustly)."""
    return any(law.is_ambiguous for law in laws.values())


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
    # the certificate's bounds at the initial state: the policy's value against every law
    # of the bands from below, the robust optimum from above (mitld_lp.solvers.certify)
    bounds: tuple[float, float] = (float("nan"), float("nan"))
    sense: str = "max"

    @property
    def certified(self) -> bool:
        return all(c.passed for c in self.checks)


def _solve(game: RobustGame, imdp: IntervalMDP, target: np.ndarray, which: str,
           method: str, tol: float, deadline: Deadline, layers: tuple[np.ndarray, np.ndarray],
           eta: float, precision: float, complement: bool,
           choice_of: np.ndarray | None = None) -> RobustModelSolution:
    """One model's robust optimum, the policy read off its lower bound, the policy's own
    robust value, and the certificate: the policy's value against every law of the
    bands bounded from below, the robust optimum from above, both in exact arithmetic
    (:func:`_certificate`).  ``choice_of``: the interval MDP's choice of each of
    ``game``'s (the cooperative game's, :func:`cooperative`; None: the same)."""
    s0 = imdp.initial
    it = robust_interval_iteration(game, target, tol=tol, time_limit=deadline.left())
    choice = robust_policy(game, target, it.lower, tie=max(tol, 1e-12))
    ev = robust_interval_iteration(game.restrict(choice), target, tol=tol,
                                   time_limit=deadline.left())
    checks = [Check("robust iteration converged", it.status is Status.OPTIMAL, it.message),
              Check("policy evaluation converged", ev.status is Status.OPTIMAL, ev.message)]
    values = ev.lower
    status = it.status if it.status is not Status.OPTIMAL else ev.status
    lp = None
    if method == "lp":
        lp = policy_lp(game, target, choice, tol=tol, time_limit=deadline.left())
        checks.append(Check("policy LP solved", lp.status is Status.OPTIMAL,
                            f"{lp.status.value}: {lp.message}"))
    lower, upper, proved = _certificate(game, s0, target, choice, it, ev, layers, eta,
                                        precision, complement)
    checks.extend(proved)
    robot = choice if choice_of is None else choice_of[choice]
    absorbing = np.asarray(imdp.choice_actions)[robot] == ABSORB
    return RobustModelSolution(which, status, float(values[s0]), it,
                               read_only(np.where(absorbing, -1, robot)),
                               read_only(np.asarray(values, dtype=np.float64)), ev, lp,
                               (float(it.lower[s0]), float(it.upper[s0])), tuple(checks),
                               bounds=(lower, upper))


def _certificate(game: RobustGame, s0: int, target: np.ndarray, choice: np.ndarray,
                 it: RobustIteration, ev: RobustIteration,
                 layers: tuple[np.ndarray, np.ndarray], eta: float, precision: float,
                 complement: bool) -> tuple[float, float, list[Check]]:
    """The robust bounds in exact arithmetic (:mod:`mitld_lp.solvers.certify`): the
    policy's value against every law of the bands is the minimum over nature's vertex
    rows of the game the policy leaves (nature an MDP's minimiser, memoryless optimal),
    bounded from below; the robust optimum is the least fixed point of ``max_c min_rows``,
    bounded from above by a checked pre-fixed point; and the policy within the
    precision of the optimum in every state."""
    from mitld_lp.solvers.certify import (
        RowModel,
        chain,
        everywhere,
        optimum_lower,
        optimum_upper,
        rounding,
    )

    played = game.restrict(choice)
    nature = RowModel(played.matrix, played.vertex_groups, s0)
    # nature's strategy: in each state the vertex row worst for the policy's values
    scores = played.matrix @ np.asarray(ev.lower, dtype=np.float64)
    groups = played.vertex_groups
    worst = np.minimum.reduceat(scores, groups[:-1])
    rows = np.arange(scores.shape[0])
    first = np.where(scores <= np.repeat(worst, np.diff(groups)), rows, rows.shape[0])
    strategy = np.minimum.reduceat(first, groups[:-1])
    strategy = np.where(target, -1, strategy)
    rnd = rounding(played.matrix, eta)
    ch = chain(nature, target, strategy, rnd, layers)
    low = optimum_lower(nature, ch, rnd, zero=np.asarray(ev.prob0, dtype=bool),
                        one=np.asarray(ev.prob1, dtype=bool), layers=layers,
                        fallback=ev.lower)
    whole = RowModel(game.matrix, game.row_groups, s0)
    high = optimum_upper(whole, ch, rounding(game.matrix, eta),
                         zero=np.asarray(it.prob0, dtype=bool), layers=layers,
                         fallback=it.upper, nature=game.vertex_groups)
    named = [Check(f"{c.name.replace('the optimum', 'the robust optimum')}" if c is
                   high.check else "lower bound: the policy's value against every law of "
                   "the bands", c.passed, c.detail) for c in (low.check, high.check)]
    named.append(everywhere(low.vector, high.vector, s0, precision, complement=complement))
    return low.value, high.value, named


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
          stay: np.ndarray | None, choice_of: np.ndarray | None = None
          ) -> RobustModelSolution:
    """A task with a safety part: ``solution`` whose policy plays, on the goal, a choice
    that keeps the run there whatever nature plays (on the cooperative game: the law
    its row names), with the check that it does.  ``choice_of`` as for :func:`_solve`."""
    if stay is None:
        return solution
    from dataclasses import replace

    policy = np.array(solution.policy)
    keep = goal & (policy >= 0)
    rows_ok = _rows_kept(game, goal, stay[keep])
    policy[keep] = stay[keep] if choice_of is None else choice_of[stay[keep]]
    check = Check("policy keeps the task's safety part whatever the bands" if choice_of
                  is None else "policy keeps the task's safety part under the best law "
                  "of the bands", bool(rows_ok), f"{int(keep.sum())} states kept")
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
    if isinstance(model, Posed):
        if model.problem.constrained:
            raise ProblemError("synthesize_robust: a task with constraints is not solved "
                               "robustly")
        posed = model
    else:
        posed = pose_on((POINTS_TOO,), model, settings=settings_from(**options))
    return POINTS_TOO.solve(posed, POINTS_TOO.build(posed, posed.settings.progress))


def solve_robust(posed: Posed, built: Built) -> Result:
    """The robust route on its built interval MDP (:func:`mitld_lp.synthesis.solve`)."""
    model, s = posed.model, posed.settings
    eps = model.epsilon if s.epsilon is None else s.epsilon
    imdp, dta, sta = built.mdp, built.dta, built.sta
    assert isinstance(imdp, IntervalMDP)
    t2 = time.perf_counter()
    game = robust_game(imdp)
    choice_of = None
    if s.bands == "best":  # nature on the robot's side: max over both (module docs)
        choice_of, game = game.row_choice(), cooperative(game)
    deadline = Deadline.after(s.time_limit, t2)
    from mitld_lp.solvers.certify import RowModel, model_eta, support_layers

    target, stay = _goal(game, imdp, dta, np.asarray(imdp.target, dtype=bool))
    # the components and levels of the game's support graph (every vertex row)
    layers = support_layers(RowModel(game.matrix, game.vertex_groups[game.row_groups],
                                     imdp.initial))
    eta = model_eta(sta)
    low = _kept(_solve(game, imdp, target, "lower", s.method, s.tol, deadline, layers, eta,
                       s.precision, posed.minimise, choice_of), game, target, stay,
                choice_of)
    if imdp.truncated.any():
        upper_goal, upper_stay = _goal(game, imdp, dta, imdp.target | imdp.truncated)
        high = _kept(_solve(game, imdp, upper_goal, "upper", s.method, s.tol, deadline,
                            layers, eta, s.precision, posed.minimise, choice_of), game,
                     upper_goal, upper_stay, choice_of)
    else:
        high = low
    timings = {**built.timings, "solve": time.perf_counter() - t2}
    controller = Controller(model.game, sta, structure_mdp(imdp), low.policy,
                            hopeless=high.iteration.prob0)
    bands = {e: str(c.distribution) for e, c in sorted(sta.clocks.items())
             if c.distribution.is_ambiguous}
    result = Result(
        route=RobustRoute.name, model=model, objective=posed.problem.objective, method=s.method,
        epsilon=eps, sta=sta, mdp=imdp, dta=dta, controller=controller, timings=timings,
        part=RobustPart(low, high, Acceptance(np.asarray(target, dtype=bool), None),
                        read_only(target), reading=s.bands,
                        message="" if s.bands == "worst" else OPTIMISTIC),
        bands=bands, **from_models(low, high, imdp.initial, posed.problem.objective,
                                   s.precision, truncated=bool(imdp.truncated.any())))
    log.info("robust synthesis (the %s law of the bands): %s, certified=%s",  # outward,
             s.bands, bracket_text(result.lower, result.upper), result.certified)
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
                     max_memory, False)[0]


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
                          max_memory, upper)
    reached = imdp.target | imdp.truncated if upper else imdp.target
    goal, _ = _goal(robust_game(imdp), imdp, dta, np.asarray(reached, dtype=bool))
    return imdp, np.asarray(goal, dtype=bool)


def _interval(model: Model, epsilon: float | None, clock_reduction: bool, max_states: int,
              max_automaton_states: int, max_memory: int | None,
              upper: bool) -> tuple[IntervalMDP, DTA]:
    """The interval MDP and automaton of ``model``; a band that needs its tail bounded
    (:mod:`mitld_lp.routes.robust_tail`) with its outer tail, or with ``upper`` its
    inner one (truncated past its step where it has none)."""
    eps = model.epsilon if epsilon is None else defaults.check_epsilon(epsilon)
    dta = to_dta(model.spec, max_states=min(max_states, max_automaton_states))
    laws, cut = model.distributions, None
    from mitld_lp.routes.robust_tail import tail_of

    tail = tail_of(model, eps, None)
    if tail is not None:  # a band's tail: outer for lower, inner (or a cut) for upper
        side = tail.inner if upper else tail.outer
        laws = {**laws, **side}
        cut = {a: K + 1 for a, K in tail.steps.items() if a not in side} or None
    sta = make_sta(dta, laws, eps, clock_reduction=clock_reduction, truncation=cut)
    return robust_product(model.game, sta, max_states=max_states, max_memory=max_memory), dta


@dataclass(frozen=True, slots=True, eq=False)
class RobustPart(Part):
    """The robust route's part of the answer: the two solved models (robust iteration,
    the policy's robust LP), the target and the states that satisfy the task whatever
    law of the bands nature plays; the model solved is an interval MDP.  ``reading``:
    the bands read for the robot's ``"worst"`` law or its ``"best"``
    (:data:`mitld_lp.defaults.BANDS`)."""

    lower_model: RobustModelSolution = field()  # required (Part's default is for the other routes)
    upper_model: RobustModelSolution = field()
    acceptance: Acceptance = field()
    goal: np.ndarray = field()
    reading: str = "worst"
    message: str = ""
    interval = True

    def summary(self, result: Result) -> dict[str, Any]:
        return report.robust_summary(result)


class RobustRoute(Route):
    """Some law known only within a band, no constraints: robust interval iteration on
    the interval MDP, the policy's robust LP (Clarabel) for method lp.  ``points``: it
    claims problems with point laws too (:func:`synthesize_robust`)."""

    name = "robust"
    optimistic = True

    def __init__(self, *, points: bool = False) -> None:
        self.points = points

    def claims(self, posed: Posed) -> bool:
        return ((posed.robust or self.points) and not posed.problem.constrained
                and not posed.sensed)

    def refusal(self, posed: Posed) -> list[str]:
        s = posed.settings
        refused = [f"robust route: {why}" for what, why in posed.beyond_points().items()
                   if what != "band"]
        if s.solver != "CLARABEL" or s.backend == "cvxpy":
            refused.append(f"solver {s.solver} / backend {s.backend} with a law known only "
                           "within a band: the robust policy LP is solved by Clarabel "
                           "directly")
        if s.decompose is True:
            refused.append("decompose with a law known only within a band: robust "
                           "synthesis has no block LPs")
        return refused

    def build(self, posed: Posed, progress: bool | None = None) -> Built:
        from mitld_lp.routes.robust_tail import policy_side

        return build_interval(policy_side(posed), progress)

    def solve(self, posed: Posed, built: Built, *, costs: Any = None,
              seed: int | None = 0) -> Result:
        from mitld_lp.routes.robust_tail import solve_tailed

        return solve_tailed(self, posed, built, solve_robust)


#: The robust route claiming point laws too (:func:`synthesize_robust`).
POINTS_TOO = RobustRoute(points=True)


def structure_mdp(imdp: IntervalMDP) -> MDP:
    """An MDP with ``imdp``'s states and choices whose row of each choice is its first
    branch (the structure a controller reads; no value is computed on it)."""
    return point_mdp(imdp, sp.csr_array(imdp.branches[imdp.branch_groups[:-1]]))
