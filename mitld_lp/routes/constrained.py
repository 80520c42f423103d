"""Constrained synthesis: maximise the task's probability subject to bounds on the
probability of other formulas, the expected steps or the expected cost; optionally
then the fastest (cheapest) of the optimal policies.  See docs/constraints.md.

    task, constraints --to_dta--> DTAs --joint_automaton--> joint DTA --make_sta--> STA
        --product(game)--> MDP --merge--> Merged --optimise (one LP, Clarabel)--> policy

Certification: the returned randomised policy is evaluated exactly on its Markov chain
(sparse solve) in the *lower* model, where the truncated state counts as failure for
the task and as violation for each constraint: its task value is ``lower`` and each
constraint's value is reported with its bound.  The *upper* model counts truncation the
other way (success, satisfaction); its LP optimum ``upper`` bounds the constrained
optimum from above.  So the constrained optimum lies in ``[lower, upper]``.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from mitld_lp.automata.joint import Joint
from mitld_lp.automata.sta import STA
from mitld_lp.checks import Check
from mitld_lp.controllers.kinds import ConstrainedController
from mitld_lp.mdp import MDP
from mitld_lp.problem import CONSTRAINED, Posed, ProblemError
from mitld_lp.result import Result
from mitld_lp.routes.constraints import (
    LEXICOGRAPHIC_TOL,
    Constraint,
    ConstraintError,
)
from mitld_lp.routes.stages import Built
from mitld_lp.solvers.constrained import INFEASIBLE, OPTIMAL, Row, Solved, optimise
from mitld_lp.solvers.constrained_model import Quantity, merge
from mitld_lp.solvers.result import Status

__all__ = ["ConstraintValue",
           "ConstrainedController", "quantity_of", "rows_for", "cost_vector"]


@dataclass(frozen=True, slots=True)
class ConstraintValue:
    """A constraint and its exact value on the returned policy (lower-model accounting:
    truncation counts as violation); ``holds`` to :data:`CONSTRAINT_TOL`.
    ``feasible_bound``: when the constraints are infeasible, the tightest bound of this
    constraint that the others allow (None when they are infeasible on their own)."""

    constraint: Constraint
    value: float
    holds: bool
    feasible_bound: float | None = None


def quantity_of(c: Constraint, component: int, model: str) -> Quantity:
    """The quantity a constraint bounds; in the ``"lower"`` model truncation counts as
    violating it, in the ``"upper"`` model as satisfying it."""
    if c.kind != "prob":
        return Quantity(c.kind)
    violate = model == "lower"
    # P(phi) <= x is violated by phi holding; P(phi) >= x by phi failing
    holds_when_truncated = (c.sense == "<=") == violate
    return Quantity("prob", component, 1.0 if holds_when_truncated else 0.0)


def rows_for(cons: tuple[Constraint, ...], model: str) -> list[Row]:
    """The LP rows of ``cons`` in the ``"lower"`` or ``"upper"`` model; the ``i``-th
    probability constraint reads joint component ``i`` (the task is component 0)."""
    out, k = [], 0
    for c in cons:
        k += c.kind == "prob"
        out.append(Row(quantity_of(c, k if c.kind == "prob" else 0, model), c.sense, c.bound))
    return out


def cost_vector(mdp: MDP, costs: Mapping[str, float]) -> np.ndarray:
    unknown = sorted(set(costs) - set(mdp.action_names))
    if unknown:
        raise ConstraintError(
            f"costs.{unknown[0]}: no action {unknown[0]!r} in the world (actions: "
            f"{', '.join(mdp.action_names)})")
    return np.array([costs.get(a, 1.0) for a in mdp.action_names], dtype=np.float64)


def solve_constrained(posed: Posed, built: Built, *,
                      costs: Mapping[str, float] | None = None,
                      seed: int | None = 0) -> Result:
    """The constrained LP of a posed problem with point laws on its built joint product
    (one with no constraint is solved too: the trade-off curve's end points).  The
    entry point is :func:`mitld_lp.synthesis.solve` (it refuses, naming it, a problem
    this LP does not solve, :func:`mitld_lp.problem.check_constrained`)."""
    if posed.robust or built.joint is None:
        raise ProblemError("solve_constrained: a law known only within a band, or a "
                           "product built without the constraints; mitld_lp.synthesize "
                           "solves it (mitld_lp.synthesis.solve)")
    return solve_merged(posed, built.mdp, built.joint, built.sta, time.perf_counter(),
                        costs=costs, seed=seed, build=built.timings)


def solve_merged(posed: Posed, mdp: MDP, joint: Joint, sta: STA, t0: float, *,
                 costs: Mapping[str, float] | None = None, seed: int | None = 0,
                 build: Mapping[str, float] | None = None) -> Result:
    """The constrained LPs on the product ``mdp`` of the world with ``joint`` (module
    docs), the chosen policy's exact values and the certificate; the time limit counts
    from ``t0``, ``build`` the seconds of the stages before it."""
    model, s, cons, then = posed.model, posed.settings, posed.problem.constraints, \
        posed.problem.then
    cost_map = dict(model.costs if costs is None else costs)
    deadline = None if s.time_limit is None else t0 + s.time_limit
    eps = model.epsilon if s.epsilon is None else s.epsilon
    merged = merge(mdp, joint)
    cost_vec = cost_vector(mdp, cost_map)

    def rows(which: str) -> list[Row]:
        return rows_for(cons, which)

    def lp(objective: Quantity, maximise: bool, lp_rows: list[Row]) -> Solved:
        left = None if deadline is None else max(deadline - time.perf_counter(), 0.0)
        return optimise(merged, objective, maximise, lp_rows, costs=cost_vec,
                        tol=s.tol * 0.1, time_limit=left)

    task_lo = Quantity("prob", 0, 0.0)
    task_hi = Quantity("prob", 0, 1.0)
    low = lp(task_lo, True, rows("lower"))
    common: dict[str, Any] = dict(route=CONSTRAINED, method="lp", merged=merged, joint=joint,
                                  sta=sta, mdp=mdp, objective=posed.problem.objective,
                                  model=model, epsilon=eps, then=then)
    if low.status != OPTIMAL:
        return _unsolved(low, cons, rows("lower"), cost_vec, build, **common)
    chosen = low
    secondary = None
    if then is not None:
        q2 = Quantity("steps" if then == "min-steps" else "cost")
        keep = Row(task_lo, ">=", low.objective - LEXICOGRAPHIC_TOL)
        second = lp(q2, False, [*rows("lower"), keep])
        if second.status != OPTIMAL:
            return _unsolved(second, cons, rows("lower"), cost_vec, build, **common)
        chosen = second
        secondary = second.values[0]
    high = low
    if merged.truncated.any():
        high = lp(task_hi, True, rows("upper"))
    # exact values of the chosen policy: the task, each constraint, the steps
    assert chosen.prob is not None and chosen.stay is not None
    from mitld_lp.solvers.constrained_model import columns, evaluate
    asked = [task_lo, *(r.quantity for r in rows("lower")), Quantity("steps")]
    vals = evaluate(merged, chosen.prob, chosen.stay,
                    [(*columns(merged, q, cost_vec), q.kind != "prob") for q in asked]).values
    lower, con_vals, steps = vals[0], vals[1:-1], vals[-1]
    values = tuple(ConstraintValue(c, v, c.holds(v)) for c, v in zip(cons, con_vals, strict=True))
    upper = high.objective if high.status == OPTIMAL else float("nan")
    want = low.objective - (LEXICOGRAPHIC_TOL if then else 0.0)
    certify_tol = s.certify_tol
    checks = (
        Check("lower LP", low.status == OPTIMAL, low.message),
        Check("upper LP", high.status == OPTIMAL, high.message),
        Check("policy value = LP optimum", lower >= want - certify_tol and
              (then is not None or abs(lower - low.objective) <= certify_tol),
              f"{lower!r} vs {low.objective!r}"),
        Check("constraints hold on the policy", all(v.holds for v in values),
              "; ".join(f"{v.constraint}: {v.value!r}" for v in values)),
        Check("lower <= upper", lower <= upper + certify_tol, f"{lower!r} <= {upper!r}"),
    )
    controller = ConstrainedController(model.game, sta, joint, merged, mdp, chosen.prob,
                                       chosen.stay, seed=seed)
    value = low.objective
    # the LP's optimum is inexact to its tolerance; when the policy's exact value lies
    # above it (within the check's tolerance), the bracket keeps its order
    upper = max(upper, lower) if upper == upper else upper
    if posed.minimise:  # Pmin(task) = 1 - Pmax(not task): the bracket read back
        lower, upper, value = 1.0 - upper, 1.0 - lower, 1.0 - value
    return Result(
        status=Status.OPTIMAL, lower=lower, upper=upper, value=value,
        certified=all(c.passed for c in checks), constraints=values,
        secondary=secondary, steps=steps, checks=checks, message=chosen.message,
        controller=controller, prob=chosen.prob, stay=chosen.stay,
        timings={**(build or {}), "solve": time.perf_counter() - t0}, **common)


def _unsolved(failed: Solved, cons: tuple[Constraint, ...], rows: list[Row], cost_vec: np.ndarray,
              build: Mapping[str, float] | None, **common: Any) -> Result:
    """An infeasible (or failed) answer; when infeasible, each constraint's tightest bound
    the others allow (a second LP: optimise that constraint's quantity subject to them)."""
    merged = common["merged"]
    values = []
    for i, c in enumerate(cons):
        bound = None
        if failed.status == INFEASIBLE:
            others = rows[:i] + rows[i + 1:]
            best = optimise(merged, rows[i].quantity, c.sense == ">=", others, costs=cost_vec)
            bound = best.objective if best.status == OPTIMAL else None
        values.append(ConstraintValue(c, float("nan"), False, bound))
    nan = float("nan")
    return Result(
        status=Status(failed.status), lower=nan, upper=nan, value=nan, certified=False,
        constraints=tuple(values), secondary=None, steps=nan, checks=(),
        message=failed.message, controller=None, prob=None, stay=None,
        timings=dict(build or {}), **common)
