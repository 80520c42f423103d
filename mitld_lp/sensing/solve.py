"""The ``sensed`` route: the optimum over the policies that act on observations only, on
the information-state product (:mod:`mitld_lp.sensing.belief`), certified as the plain
route's answer is.

The information-state MDP is an ordinary MDP with a reachability target, so the
existing solvers apply unchanged: one analysis of both truncation models, interval
iteration of both in one pass, the occupancy LP of each (method ``lp``), the policy's
exact value on its Markov chain.  ``lower`` is that exact value in the lower model
(truncated hypotheses lose): an observation-based policy achieves it in the real world;
``upper`` is interval iteration's sound upper bound on the upper model: no
observation-based policy does better.  The width is at most the truncation's epsilon
achieved, up to the solver's tolerance.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from mitld_lp import report
from mitld_lp.automata.dta import DTA
from mitld_lp.automata.sta import STA
from mitld_lp.automata.translate import to_dta
from mitld_lp.checks import Check, close
from mitld_lp.mdp import MDP
from mitld_lp.model import Model
from mitld_lp.problem import SENSED, Posed
from mitld_lp.sensing.belief import Belief, InfoState, belief_product
from mitld_lp.sensing.observe import SensedController
from mitld_lp.sensing.sensors import Sensor, partial
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.iteration import evaluate_policy, interval_iterations
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.result import IterationResult, LPResult, Status, read_only
from mitld_lp.worlds.names import state_record

__all__ = ["SensedResult", "SensedSolution", "solve_sensed"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True, eq=False)
class SensedSolution:
    """One truncation model's solution (the fields of the plain route's
    ``ModelSolution``, which the summary reads)."""

    which: str
    status: Status
    value: float
    policy: np.ndarray
    policy_values: np.ndarray
    bracket: tuple[float, float]
    lp: LPResult | None
    iteration: IterationResult
    prob0: np.ndarray
    checks: tuple[Check, ...]

    @property
    def certified(self) -> bool:
        return all(c.passed for c in self.checks)


@dataclass(frozen=True, slots=True, eq=False)
class SensedResult:
    """The answer of the ``sensed`` route (module docs): the bracket ``[lower, upper]`` on
    the optimum over observation-based policies, its certificate, the controller that
    acts on :class:`~mitld_lp.sensing.observe.Observation` records."""

    model: Model
    method: str
    epsilon: float
    dta: DTA
    belief: Belief
    lower_model: SensedSolution
    upper_model: SensedSolution
    controller: SensedController
    timings: Mapping[str, float]
    objective: str = "max"
    route: ClassVar[str] = SENSED

    @property
    def mdp(self) -> MDP:
        return self.belief.mdp

    @property
    def sta(self) -> STA:
        return self.belief.sta

    @property
    def sensors(self) -> Mapping[str, Sensor]:
        return self.belief.sensors

    @property
    def lower(self) -> float:
        return float(self.lower_model.policy_values[self.mdp.initial])

    @property
    def upper(self) -> float:
        return float(self.upper_model.bracket[1])

    @property
    def value(self) -> float:
        return self.lower_model.value

    @property
    def status(self) -> Status:
        return next((m.status for m in (self.lower_model, self.upper_model)
                     if m.status is not Status.OPTIMAL), Status.OPTIMAL)

    @property
    def certified(self) -> bool:
        return self.lower_model.certified and self.upper_model.certified

    @property
    def failed_checks(self) -> tuple[Check, ...]:
        models = ((self.lower_model,) if self.upper_model is self.lower_model
                  else (self.lower_model, self.upper_model))
        return tuple(c for m in models for c in m.checks if not c.passed)

    @property
    def seconds(self) -> float:
        return float(sum(self.timings.values()))

    def __repr__(self) -> str:
        return (f"SensedResult(model={self.model.name!r}, lower={self.lower:.7g}, "
                f"upper={self.upper:.7g}, certified={self.certified}, "
                f"status={self.status.value!r}, states={self.mdp.n_states})")

    def summary(self) -> dict[str, Any]:
        """The JSON record of every route (:func:`mitld_lp.report.summary`)."""
        return report.summary(self)

    def policy_table(self) -> list[dict[str, Any]]:
        """One row per information state still undecided, with the columns of the
        plain route's table (:data:`mitld_lp.report.POLICY_COLUMNS`):
        ``automaton_state`` the obligations the hypotheses still alive leave (joined by
        ``" ; "``), ``pending`` the events not known to have happened (sensed and not
        reported, or unsensed and pending), ``value`` the policy's exact value from
        there (truncated hypotheses lose)."""
        mdp, low = self.mdp, self.lower_model
        obligations = self.dta.states
        rows = []
        for i, s in enumerate(mdp.states):
            if not isinstance(s, InfoState) or low.policy[i] < 0:
                continue
            unknown = (set(self.belief.sensed) - s.reported) | s.pending
            rows.append({
                "game_state": state_record(self.model.game, s.world),
                "automaton_state": " ; ".join(sorted({str(obligations[q])
                                                      for _, q in s.hypotheses})),
                "pending": sorted(unknown), "clock": s.clock,
                "action": mdp.action_name(int(low.policy[i])),
                "value": float(low.policy_values[i]), "accepting_component": False})
        return rows


def solve_sensed(posed: Posed) -> SensedResult:
    """Solve a problem posed on the ``sensed`` route (module docs)."""
    model, s = posed.model, posed.settings
    assert posed.route == SENSED and s.max_states is not None
    assert s.max_automaton_states is not None
    eps = model.epsilon if s.epsilon is None else s.epsilon
    t0 = time.perf_counter()
    dta = to_dta(model.spec, max_states=min(s.max_states, s.max_automaton_states))
    t1 = time.perf_counter()
    belief = belief_product(model.game, dta, model.distributions, partial(model.sensors),
                            eps, clock_reduction=s.clock_reduction,
                            truncation=s.truncation_map, max_states=s.max_states,
                            max_memory=s.max_memory)
    t2 = time.perf_counter()
    mdp = belief.mdp
    deadline = float("inf") if s.time_limit is None else t2 + s.time_limit

    def remaining() -> float | None:
        return None if deadline == float("inf") else max(0.0, deadline - time.perf_counter())

    quotients = list(analyse(mdp, mdp.target, mdp.truncated))
    if quotients[1] is quotients[0]:
        quotients = quotients[:1]
    its = interval_iterations(mdp, quotients, tol=s.tol, progress=s.progress,
                              time_limit=remaining(),
                              gap="max" if quotients[0].initial < 0 else "initial")
    solutions = []
    for q, it, which in zip(quotients, its, ("lower", "upper"), strict=False):
        target = np.asarray(q.target)
        lp = None
        if s.method == "lp":
            lp = solve_lp(mdp, target, quotient=q, solver=s.solver,
                          backend=s.backend,  # type: ignore[arg-type]
                          tol=s.tol, decompose=s.decompose is not False,
                          time_limit=remaining(), bounds=(it.lower, it.upper),
                          everywhere=q.initial < 0)
        solutions.append(_certified(mdp, target, q.prob0, it, lp, which, s.certify_tol))
    low, high = solutions[0], solutions[-1]
    t3 = time.perf_counter()
    result = SensedResult(
        model=model, method=s.method, epsilon=eps, dta=dta, belief=belief,
        lower_model=low, upper_model=high,
        controller=SensedController.from_belief(model.game, belief, low.policy),
        timings={"automaton": t1 - t0, "product": t2 - t1, "solve": t3 - t2})
    log.info("sensed synthesis: [%g, %g], certified=%s", result.lower, result.upper,
             result.certified)
    return result


def _certified(mdp: MDP, target: np.ndarray, prob0: np.ndarray, it: IterationResult,
               lp: LPResult | None, which: str, tol: float) -> SensedSolution:
    """One model's answer and its checks: the LP's policy (else the iteration's),
    evaluated exactly, inside the iteration's bracket and equal to the optimum."""
    checks = [Check("iteration converged", it.status is Status.OPTIMAL, it.message)]
    policy, value, status = it.policy, it.value_lower, it.status
    if lp is not None:
        if lp.status is Status.OPTIMAL and lp.policy is not None:
            policy, value, status = lp.policy, lp.value, lp.status
            checks.append(Check("LP solved", True, f"{lp.status.value}: {lp.message}"))
            checks.append(close("LP primal = dual", lp.primal_objective, lp.dual_objective,
                                tol))
        elif lp.status in (Status.INACCURATE, Status.MAX_ITERATIONS) and (
                it.status is Status.OPTIMAL):
            checks.append(Check("LP replaced by the iteration policy", True,
                                f"{lp.status.value}: {lp.message}"))
        else:
            status = lp.status
            checks.append(Check("LP solved", False, f"{lp.status.value}: {lp.message}"))
    values = read_only(evaluate_policy(mdp, target, policy))
    exact = float(values[mdp.initial])
    lo, hi = it.value_lower, it.value_upper
    checks.append(Check("policy value within iteration bracket",
                        lo - tol <= exact <= hi + tol,
                        f"policy {exact:.10g} in [{lo:.10g}, {hi:.10g}] +- {tol:g}"))
    checks.append(close("policy value = optimum", exact, value, tol))
    checks.append(close("optimum = iteration upper bound", value, hi, tol))
    return SensedSolution(which, status, value, policy, values, (lo, hi), lp, it, prob0,
                          tuple(checks))
