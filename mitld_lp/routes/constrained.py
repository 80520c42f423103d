"""Constrained synthesis: maximise the task's probability subject to bounds on the
probability of other formulas, the expected steps or the expected cost; optionally
then the fastest (cheapest) of the optimal policies.  See docs/constraints.md.

    task, constraints --to_dta--> DTAs --joint_automaton--> joint DTA --make_sta--> STA
        --product(game)--> MDP --merge--> Merged --optimise (one LP, Clarabel)--> policy

Certification: the returned randomised policy is evaluated on its Markov chain in the
*lower* model, where the truncated state counts as failure for the task and as
violation for each constraint, and each value is bounded in exact arithmetic
(:mod:`mitld_lp.solvers.certify_mixture`): the task's lower bound is ``lower``, and a
constraint holds when its bound's side that matters meets it exactly.  The LP's answer
meets a binding constraint only to its tolerance, so a constraint the policy misses is
tightened by what it missed (and a little more) and the LPs solved again, a few times;
what still misses is reported with by how much, and the answer is not certified.  The
*upper* model counts truncation the other way (success, satisfaction); its LP optimum
``upper`` bounds the constrained optimum from above.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from mitld_lp import report
from mitld_lp.automata.joint import Joint
from mitld_lp.automata.sta import STA
from mitld_lp.checks import Check
from mitld_lp.controllers.kinds import ConstrainedController
from mitld_lp.logic.constraints import (
    LEXICOGRAPHIC_TOL,
    Constraint,
    ConstraintError,
)
from mitld_lp.mdp import MDP
from mitld_lp.problem import Posed, ProblemError, task_words
from mitld_lp.result import Part, Result, precision_check
from mitld_lp.routes.route import Route
from mitld_lp.routes.stages import Built, build_joint
from mitld_lp.solvers.result import Status
from mitld_lp.util.clock import Deadline

if TYPE_CHECKING:  # the LP's modules load when a constrained problem is solved
    from mitld_lp.solvers.constrained import Row, Solved
    from mitld_lp.solvers.constrained_model import Merged, Quantity

__all__ = ["ConstrainedRoute", "ConstrainedPart", "lp_refusals", "ConstraintValue",
           "ConstrainedController", "quantity_of", "rows_for", "cost_vector"]


@dataclass(frozen=True, slots=True)
class ConstraintValue:
    """A constraint and its value on the returned policy (lower-model accounting:
    truncation counts as violation): ``value`` the float estimate, ``bounds`` the value
    bounded in exact arithmetic; ``holds`` when the bound's side that matters meets it
    (``<=``: the upper bound at most ``bound``; ``>=``: the lower at least), else
    ``miss`` says by how much it does not.  ``feasible_bound``: when the constraints are
    infeasible, the tightest bound of this constraint that the others allow (None when
    they are infeasible on their own)."""

    constraint: Constraint
    value: float
    holds: bool
    feasible_bound: float | None = None
    bounds: tuple[float, float] = (float("nan"), float("nan"))

    @property
    def certified(self) -> float:
        """The bound that decides the constraint (upper for ``<=``, lower for ``>=``)."""
        return self.bounds[1] if self.constraint.sense == "<=" else self.bounds[0]

    @property
    def miss(self) -> float:
        """How far the certified bound lies beyond the constraint's (0 when it holds)."""
        c = self.constraint
        gap = self.certified - c.bound if c.sense == "<=" else c.bound - self.certified
        return max(gap, 0.0) if gap == gap else float("nan")


def quantity_of(c: Constraint, component: int, model: str) -> Quantity:
    """The quantity a constraint bounds; in the ``"lower"`` model truncation counts as
    violating it, in the ``"upper"`` model as satisfying it."""
    from mitld_lp.solvers.constrained_model import Quantity

    if c.kind != "prob":
        return Quantity(c.kind)
    violate = model == "lower"
    # P(phi) <= x is violated by phi holding; P(phi) >= x by phi failing
    holds_when_truncated = (c.sense == "<=") == violate
    return Quantity("prob", component, 1.0 if holds_when_truncated else 0.0)


def rows_for(cons: tuple[Constraint, ...], model: str) -> list[Row]:
    """The LP rows of ``cons`` in the ``"lower"`` or ``"upper"`` model; the ``i``-th
    probability constraint reads joint component ``i`` (the task is component 0)."""
    from mitld_lp.solvers.constrained import Row

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
    entry point is :func:`mitld_lp.synthesis.solve` (:func:`mitld_lp.synthesis.pose`
    refuses, naming it, a problem this LP does not solve: :class:`ConstrainedRoute`)."""
    if posed.robust or built.joint is None:
        raise ProblemError("solve_constrained: a law known only within a band, or a "
                           "product built without the constraints; mitld_lp.synthesize "
                           "solves it (mitld_lp.synthesis.solve)")
    return solve_merged(posed, built.mdp, built.joint, built.sta, time.perf_counter(),
                        costs=costs, seed=seed, build=built.timings)


def solve_merged(posed: Posed, mdp: MDP, joint: Joint, sta: STA, t0: float, *,
                 costs: Mapping[str, float] | None = None, seed: int | None = 0,
                 build: Mapping[str, float] | None = None, merged: Merged | None = None,
                 eta: float | None = None, route: str | None = None,
                 part: Callable[..., ConstrainedPart] | None = None,
                 controller: Callable[[Merged, Solved], Any] | None = None) -> Result:
    """The constrained LPs on the product ``mdp`` of the world with ``joint`` (module
    docs), the chosen policy's values bounded in exact arithmetic and the certificate;
    the time limit counts from ``t0``, ``build`` the seconds of the stages before it.
    Another route's model (:mod:`mitld_lp.routes.sensed_constrained`) comes as its own
    ``merged`` model with its ``eta``, ``route`` name, ``part`` record and
    ``controller`` (made from the model and the chosen LP)."""
    from mitld_lp.solvers.constrained import Row, optimise
    from mitld_lp.solvers.constrained_model import Quantity, merge
    from mitld_lp.solvers.rounding import model_eta

    model, s, cons, then = posed.model, posed.settings, posed.problem.constraints, \
        posed.problem.then
    cost_map = dict(model.costs if costs is None else costs)
    deadline = Deadline.after(s.time_limit, t0)
    eps = model.epsilon if s.epsilon is None else s.epsilon
    merged = merge(mdp, joint, negated=posed.minimise) if merged is None else merged
    cost_vec = cost_vector(mdp, cost_map)
    eta = model_eta(sta) if eta is None else eta

    def rows(which: str) -> list[Row]:
        return rows_for(cons, which)

    def lp(objective: Quantity, maximise: bool, lp_rows: list[Row]) -> Solved:
        return optimise(merged, objective, maximise, lp_rows, costs=cost_vec,
                        tol=s.tol * 0.1, time_limit=deadline.left())

    task_lo = Quantity("prob", 0, 0.0)
    task_hi = Quantity("prob", 0, 1.0)
    common: dict[str, Any] = dict(route=route or ConstrainedRoute.name, method="lp",
                                  sta=sta, mdp=mdp, objective=posed.problem.objective,
                                  model=model, epsilon=eps)
    whole = (part or ConstrainedPart)(then=then, merged=merged, joint=joint)
    margins = [0.0] * len(cons)
    found = None
    first = float("nan")  # the untightened LP's optimum
    untightened: Solved | None = None
    for attempt in range(TIGHTEN_ROUNDS + 1):
        lp_rows = [Row(r.quantity, r.sense, r.bound - m if r.sense == "<=" else r.bound + m)
                   for r, m in zip(rows("lower"), margins, strict=True)]
        low = lp(task_lo, True, lp_rows)
        if not low.status.has_solution:
            if found is None:
                return _unsolved(low, cons, rows("lower"), cost_vec, build, whole, **common)
            break  # a tightened LP failed: the last policy stands, its misses reported
        chosen, secondary = low, None
        if attempt == 0:
            first, untightened = low.objective, low
        if then is not None:
            q2 = Quantity("steps" if then == "min-steps" else "cost")
            keep = Row(task_lo, ">=", low.objective - LEXICOGRAPHIC_TOL)
            second = lp(q2, False, [*lp_rows, keep])
            if not second.status.has_solution:
                if found is None:
                    return _unsolved(second, cons, rows("lower"), cost_vec, build, whole,
                                     **common)
                break
            chosen, secondary = second, second.values[0]
        found = (low, chosen, secondary, _values(merged, chosen, cons, cost_vec, eta),
                 attempt)
        misses = [v.miss for v in found[3][1]]
        if not any(m > 0 or m != m for m in misses):
            break
        margins = [m + (2.0 * d + 1e-12 * max(1.0, abs(c.bound)) if d > 0 else 0.0)
                   for m, d, c in zip(margins, misses, cons, strict=True)]
    assert found is not None
    low, chosen, secondary, (task, values, steps), attempts = found
    # the upper bound from the LP with the problem's own bounds (a tightened one's duals
    # would be extrapolated back to them, overshooting where the optimum bends)
    high, which = (untightened or low), "lower"
    if merged.truncated.any():
        high, which = lp(task_hi, True, rows("upper")), "upper"
    assert chosen.prob is not None and chosen.stay is not None
    lower = task.lower
    upper, proved = _upper_bound(merged, high, rows(which), task_hi if which == "upper"
                                 else task_lo, cost_vec, eta)
    checks = [
        Check("lower LP", low.status.has_solution, low.message),
        Check("upper LP", high.status.has_solution, high.message),
        proved,
        task.check,
        *(Check(f"constraint {v.constraint}", v.holds, _said(v)) for v in values),
    ]
    if attempts:
        checks.append(Check("constraints tightened", True, (
            f"the LPs solved again {attempts} times with bounds tightened by "
            + ", ".join(f"{m:.3g}" for m in margins) + " so that the policy meets them")))
    value = low.objective
    allowed = LEXICOGRAPHIC_TOL if then else 0.0
    # what tightening the bounds cost the optimum (the LP's estimate): deliberate, as
    # the lexicographic tolerance is, and reported apart from the solver's part
    tightening = max(first - low.objective, 0.0) if attempts else 0.0
    complement = None
    if posed.minimise:  # Pmin(task) = 1 - Pmax(not task): the bracket read back
        from mitld_lp.solvers.rounding import one_minus

        complement = (lower, upper)
        (lower, upper), value = one_minus(lower, upper), 1.0 - value
    apart = 0.0
    if merged.truncated.any() and high.status.has_solution:
        apart = max(high.objective - first, 0.0)
    total = upper - lower
    solver = max(total - apart - allowed - tightening, 0.0)
    checks.append(precision_check(lower, upper, solver, apart, s.precision))
    controller = (ConstrainedController(model.game, sta, joint, merged, mdp, chosen.prob,
                                        chosen.stay, seed=seed) if controller is None
                  else controller(merged, chosen))
    return Result(
        status=Status.OPTIMAL, lower=lower, upper=upper, value=value,
        certified=all(c.passed for c in checks), checks=tuple(checks),
        part=replace(whole, constraints=values, secondary=secondary, steps=steps,
                     message=chosen.message, prob=chosen.prob, stay=chosen.stay),
        controller=controller,
        timings={**(build or {}), "solve": time.perf_counter() - t0},
        complement=complement, precision=s.precision,
        width={"total": total, "truncation": apart, "solver": solver,
               **({"lexicographic": allowed} if then else {}),
               **({"tightening": tightening} if attempts else {})}, **common)


def _upper_bound(merged: Any, high: Solved, rows: list[Row], objective: Quantity,
                 cost_vec: np.ndarray, eta: float) -> tuple[float, Check]:
    """The constrained optimum bounded from above in exact arithmetic by weak duality
    from the LP's dual solution, against the problem's own bounds (those of a tightened
    LP's rows are not this answer's: the dual solution is feasible whatever they are),
    :mod:`mitld_lp.solvers.certify_dual`; the LP's float optimum when no dual solution
    settles, with a failed check."""
    from mitld_lp.solvers.certify_dual import dual_bound

    name = "upper bound: the constrained optimum (weak duality)"
    if not high.status.has_solution or high.duals is None:
        return float("nan"), Check(name, False, f"the upper LP is {high.status}")
    from mitld_lp.solvers.constrained import never_reaching

    timed = any(r.quantity.kind in ("steps", "cost") for r in rows)
    allowed, stay_allowed = never_reaching(merged, rows)
    stays = merged.stay_ok & ~(merged.undecided & timed) & stay_allowed
    upper, check = dual_bound(merged, [objective, *(r.quantity for r in rows)],
                              [r.sense for r in rows], [r.bound for r in rows],
                              high.duals, stays, cost_vec, eta, allowed)
    if upper == float("inf"):
        return high.objective, check
    return upper, check


#: Rounds of tightening the bounds a policy missed (module docs).
TIGHTEN_ROUNDS = 3


def _values(merged: Any, chosen: Solved, cons: tuple[Constraint, ...], cost_vec: np.ndarray,
            eta: float) -> tuple[Any, tuple[ConstraintValue, ...], float]:
    """The chosen policy's task probability, each constraint's value and its expected
    steps, bounded in exact arithmetic (lower-model accounting)."""
    from mitld_lp.solvers.constrained import certified_value
    from mitld_lp.solvers.constrained_model import Quantity

    assert chosen.prob is not None and chosen.stay is not None
    task = certified_value(merged, chosen.prob, chosen.stay, Quantity("prob", 0, 0.0),
                           "lower bound: the policy's task probability", eta=eta)
    values = []
    for c, r, v in zip(cons, rows_for(cons, "lower"), chosen.values[1:], strict=False):
        b = certified_value(merged, chosen.prob, chosen.stay, r.quantity, f"{c}",
                            costs=cost_vec, eta=eta)
        side = b.upper if c.sense == "<=" else b.lower
        holds = b.check.passed and (side <= c.bound if c.sense == "<=" else side >= c.bound)
        values.append(ConstraintValue(c, float(v), bool(holds), bounds=(b.lower, b.upper)))
    steps = certified_value(merged, chosen.prob, chosen.stay, Quantity("steps"),
                            "expected steps").value
    return task, tuple(values), steps


def _said(v: ConstraintValue) -> str:
    c = v.constraint
    word = "at most" if c.sense == "<=" else "at least"
    if v.holds:
        return (f"the policy's value is {word} {v.certified!r} in exact arithmetic, "
                f"within the bound {c.bound!r} (estimate {v.value!r})")
    return (f"the policy's value is only known {word} {v.certified!r}: it misses the bound "
            f"{c.bound!r} by up to {v.miss:.3g} (estimate {v.value!r})")


def _unsolved(failed: Solved, cons: tuple[Constraint, ...], rows: list[Row], cost_vec: np.ndarray,
              build: Mapping[str, float] | None, whole: ConstrainedPart,
              **common: Any) -> Result:
    """An infeasible (or failed) answer; when infeasible, each constraint's tightest bound
    the others allow (a second LP: optimise that constraint's quantity subject to them)."""
    from mitld_lp.solvers.constrained import INFEASIBLE, optimise

    merged = whole.merged
    assert merged is not None  # solve_merged's part has its model
    values = []
    for i, c in enumerate(cons):
        bound = None
        if failed.status == INFEASIBLE:
            others = rows[:i] + rows[i + 1:]
            best = optimise(merged, rows[i].quantity, c.sense == ">=", others, costs=cost_vec)
            bound = best.objective if best.status.has_solution else None
        values.append(ConstraintValue(c, float("nan"), False, bound))
    nan = float("nan")
    return Result(
        status=Status(failed.status), lower=nan, upper=nan, value=nan, certified=False,
        checks=(), controller=None,
        part=replace(whole, constraints=tuple(values), message=failed.message),
        timings=dict(build or {}), **common)


@dataclass(frozen=True, slots=True, eq=False)
class ConstrainedPart(Part):
    """The constrained routes' part of the answer: each constraint's value, the
    lexicographic objective and its value, the expected steps, the solver's message, and
    the randomised policy (``prob`` per choice, ``stay`` per state) on the ``merged``
    model of the ``joint`` automaton."""

    then: str | None = None
    merged: Merged | None = None
    joint: Joint | None = None
    constraints: tuple[ConstraintValue, ...] = ()
    secondary: float | None = None
    steps: float = float("nan")
    message: str = ""
    prob: np.ndarray | None = None
    stay: np.ndarray | None = None
    options: Any = None  # with a band: nature's options on merged (solvers/robust_merged)
    randomised = True

    def policy_table(self, result: Result) -> list[dict[str, Any]]:
        return report.randomised_table(result)

    def summary(self, result: Result) -> dict[str, Any]:
        return report.constrained_summary(result)


class ConstrainedRoute(Route):
    """Constraints or a ``then`` objective with point laws: one Clarabel LP over the
    joint product's occupancy measures, a randomised controller.  ``every``: it claims
    problems without constraints too (the trade-off curve's end points,
    :func:`mitld_lp.synthesis.synthesize_constrained`)."""

    name = "constrained"
    takes_constraints = True

    def __init__(self, *, every: bool = False) -> None:
        self.every = every

    def claims(self, posed: Posed) -> bool:
        return (posed.problem.constrained or self.every) and not posed.robust

    def refusal(self, posed: Posed) -> list[str]:
        return lp_refusals(posed)

    def build(self, posed: Posed, progress: bool | None = None) -> Built:
        return build_joint(posed, progress)

    def solve(self, posed: Posed, built: Built, *, costs: Mapping[str, float] | None = None,
              seed: int | None = 0) -> Result:
        return solve_constrained(posed, built, costs=costs, seed=seed)


def lp_refusals(posed: Posed) -> list[str]:
    """Why the constrained LP (one Clarabel LP over the joint product's occupancy
    measures) does not solve ``posed`` as posed (empty: it does)."""
    from mitld_lp.logic.fragment import CO_SAFE, OBLIGATION, SAFETY, check

    s, cons, fragment = posed.settings, posed.problem.constraints, posed.fragment
    what = task_words(fragment, posed.problem.objective)
    refused = []
    if fragment not in (CO_SAFE, SAFETY, OBLIGATION):
        refused.append(f"{what} with constraints: not a supported class")
    for c in cons:
        if c.formula is not None and check(c.formula).fragment != CO_SAFE:
            refused.append(f"constraint {c}: class {check(c.formula).fragment}; "
                           "constraint formulas must be co-safe")
    if s.method != "lp":
        refused.append(f"method {s.method!r} with constraints: the constrained "
                       "optimum is one occupancy LP (method 'lp')")
    if s.solver != "CLARABEL" or s.backend == "cvxpy":
        refused.append(f"solver {s.solver} / backend {s.backend} with constraints: the "
                       "constrained LP is solved by Clarabel directly")
    if s.decompose is True:
        refused.append("decompose with constraints: the constrained LP is one LP over "
                       "the whole product (its rows couple every block)")
    return refused
