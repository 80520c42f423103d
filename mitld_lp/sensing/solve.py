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
from dataclasses import dataclass

import numpy as np

from mitld_lp.checks import Check, close
from mitld_lp.mdp import MDP
from mitld_lp.problem import SENSED, Posed
from mitld_lp.result import Result, from_models
from mitld_lp.routes.stages import Built
from mitld_lp.sensing.observe import SensedController
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.iteration import evaluate_policy, interval_iterations
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.result import IterationResult, LPResult, Status, read_only

__all__ = ["SensedSolution", "solve_sensed"]

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


def solve_sensed(posed: Posed, built: Built) -> Result:
    """Solve a problem posed on the ``sensed`` route (module docs) on its built
    information-state product (:func:`mitld_lp.synthesis.solve`)."""
    model, s = posed.model, posed.settings
    assert posed.route == SENSED and built.belief is not None
    eps = model.epsilon if s.epsilon is None else s.epsilon
    belief, dta = built.belief, built.dta
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
    result = Result(
        route=SENSED, model=model, objective=posed.problem.objective, method=s.method,
        epsilon=eps, sta=belief.sta, mdp=mdp, dta=dta, belief=belief,
        sensors=dict(belief.sensors),
        controller=SensedController.from_belief(model.game, belief, low.policy),
        timings={**built.timings, "solve": t3 - t2},
        **from_models(low, high, mdp.initial, posed.problem.objective))
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
