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
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from mitld_lp.automata.joint import Joint, joint_automaton
from mitld_lp.automata.sta import STA, make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.checks import Check
from mitld_lp.distributions import FirstOccurrence
from mitld_lp.distributions.literal import from_spec
from mitld_lp.logic import check
from mitld_lp.logic.syntax import DistLiteral, atoms
from mitld_lp.mdp import MDP
from mitld_lp.model import Model
from mitld_lp.problem import CONSTRAINED, Posed, ProblemError, check_constrained
from mitld_lp.product import ProductState, product
from mitld_lp.routes.constraints import (
    LEXICOGRAPHIC_TOL,
    Constraint,
    ConstraintError,
)
from mitld_lp.running.randomised import ConstrainedController
from mitld_lp.solvers.constrained import INFEASIBLE, OPTIMAL, Row, Solved, optimise
from mitld_lp.solvers.constrained_model import Merged, Quantity, merge
from mitld_lp.solvers.result import Status
from mitld_lp.worlds.names import state_record

__all__ = ["ConstrainedResult", "ConstraintValue",
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


@dataclass(frozen=True, slots=True, eq=False)
class ConstrainedResult:
    """The answer of :func:`synthesize_constrained`.

    ``status``: a :class:`~mitld_lp.solvers.result.Status`, the vocabulary of every route
    (``OPTIMAL``, ``INFEASIBLE``: no policy meets the constraints, each
    :class:`ConstraintValue` then carries ``feasible_bound``; ``FAILED``, ``TIME_LIMIT``);
    each is also its string (``"optimal"``).
    ``lower``: the task's exact probability under the returned policy (lower model);
    ``upper``: the upper model's LP optimum; ``value``: the lower model's LP optimum.
    ``then``/``secondary``: the lexicographic objective and its exact value on the policy.
    """

    status: Status
    lower: float
    upper: float
    value: float
    certified: bool
    constraints: tuple[ConstraintValue, ...]
    then: str | None
    secondary: float | None
    steps: float
    checks: tuple[tuple[str, bool, str], ...]
    message: str
    controller: ConstrainedController | None
    merged: Merged
    joint: Joint
    sta: STA
    mdp: MDP
    prob: np.ndarray | None
    stay: np.ndarray | None
    timings: dict[str, float] = field(default_factory=dict)
    objective: str = "max"
    model: Model | None = None
    epsilon: float = float("nan")
    bands: Mapping[str, str] = field(default_factory=dict)  # laws known within a band
    route: ClassVar[str] = CONSTRAINED
    method: ClassVar[str] = "lp"

    @property
    def seconds(self) -> float:
        return float(sum(self.timings.values()))

    @property
    def failed_checks(self) -> tuple[Check, ...]:
        """The checks that failed, as :class:`~mitld_lp.checks.Check` records."""
        return tuple(Check(n, ok, d) for n, ok, d in self.checks if not ok)

    def policy_table(self) -> list[dict[str, Any]]:
        """One row per (state, action) the policy takes with positive probability: the
        world state, the joint automaton's component states, pending events, clock, the
        action (``stay`` for staying for ever) and its probability."""
        if self.prob is None or self.stay is None:
            return []
        m = self.merged
        rows = []
        cs = m.mdp.choice_state()
        for c in np.flatnonzero(self.prob > 0).tolist():
            s = int(cs[c])
            if m.absorbing[s]:
                continue
            name = "keep" if m.keep[c] else m.mdp.action_name(c)
            rows.append(self._row(s, name, float(self.prob[c])))
        for s in np.flatnonzero(self.stay > 0).tolist():
            rows.append(self._row(int(s), "stay", float(self.stay[s])))
        return rows

    def _row(self, s: int, action: str, p: float) -> dict[str, Any]:
        rec = self.mdp.states[int(self.merged.origin[s])]
        assert isinstance(rec, ProductState)
        game = None if self.model is None else self.model.game
        return {"game_state": rec.game if game is None else state_record(game, rec.game),
                "automaton_state": list(self.joint.components[rec.automaton]),
                "pending": sorted(rec.pending), "clock": rec.clock, "action": action,
                "probability": p}

    def summary(self) -> dict[str, Any]:
        """The numbers, as plain data (the command line's ``--json``,
        :func:`mitld_lp.report.summary`)."""
        from mitld_lp.report import summary

        return summary(self)

    @property
    def randomized_states(self) -> int:
        """How many states the policy randomises in."""
        return 0 if self.prob is None else int(np.count_nonzero(self._mixed()))

    def _mixed(self) -> np.ndarray:
        assert self.prob is not None and self.stay is not None
        cs = self.merged.mdp.choice_state()
        positive = np.bincount(cs, weights=(self.prob > 0).astype(float),
                               minlength=self.merged.mdp.n_states) + (self.stay > 0)
        return positive > 1


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


def _laws(model: Model, constraints: tuple[Constraint, ...]) -> dict[str, FirstOccurrence]:
    """The model's laws and those of the constraints' new events (inline literals)."""
    laws = dict(model.distributions)
    task = dict(check(model.spec).events)
    for c in constraints:
        if c.formula is None:
            continue
        events = {e for e, _ in check(c.formula).events}
        unknown = sorted(atoms(c.formula) - set(model.game.proposition_names) - events
                         - set(laws))
        if unknown:
            raise ConstraintError(
                f"constraint {str(c)!r}: proposition {unknown[0]!r} is neither a proposition "
                f"of the world ({', '.join(sorted(model.game.proposition_names))}) nor an event")
        for event, mu in check(c.formula).events:
            if event in task:
                if task[event] != mu:
                    raise ConstraintError(
                        f"constraint {str(c)!r}: event {event!r} has D[{task[event]}] in the "
                        f"spec and D[{mu}] here; one law per event")
            elif event in laws:
                continue
            elif isinstance(mu, DistLiteral):
                laws[event] = from_spec(mu)
            else:
                raise ConstraintError(
                    f"constraint {str(c)!r}: event {event!r} is not an event of the spec; "
                    f"give it an inline law (D[geometric(0.3)] {event}), not D[{mu}]")
    return laws


def cost_vector(mdp: MDP, costs: Mapping[str, float]) -> np.ndarray:
    unknown = sorted(set(costs) - set(mdp.action_names))
    if unknown:
        raise ConstraintError(
            f"costs.{unknown[0]}: no action {unknown[0]!r} in the world (actions: "
            f"{', '.join(mdp.action_names)})")
    return np.array([costs.get(a, 1.0) for a in mdp.action_names], dtype=np.float64)


def solve_constrained(posed: Posed, *, costs: Mapping[str, float] | None = None,
                      seed: int | None = 0) -> ConstrainedResult:
    """The constrained LP of a posed problem with point laws (one with no constraint is
    solved too: the trade-off curve's end points); refuses, naming it, a problem that LP
    does not solve (:func:`mitld_lp.problem.check_constrained`).  The entry point for
    every law is :func:`mitld_lp.synthesis.synthesize_constrained`."""
    check_constrained(posed)
    if posed.robust:
        raise ProblemError("solve_constrained: a law known only within a band; "
                           "mitld_lp.synthesize (or synthesize_constrained) solves it "
                           "(mitld_lp.routes.robust_constrained)")
    s = posed.settings
    t0 = time.perf_counter()
    joint, sta = joint_sta(posed)
    mdp = product(posed.model.game, sta, max_states=s.max_states, max_memory=s.max_memory)
    return solve_merged(posed, mdp, joint, sta, t0, costs=costs, seed=seed)


def joint_sta(posed: Posed) -> tuple[Joint, STA]:
    """The joint automaton of the task (its complement for ``objective="min"``) and the
    constraints' formulas, with the events' laws and the truncation settings."""
    model, s, cons = posed.model, posed.settings, posed.problem.constraints
    assert s.max_states is not None and s.max_automaton_states is not None  # resolved
    laws = _laws(model, cons)
    formulas = [c.formula for c in cons if c.kind == "prob"]
    cap = min(s.max_states, s.max_automaton_states)
    task = to_dta(model.spec, max_states=cap)
    parts = [task.complement() if posed.minimise else task,
             *(to_dta(f, max_states=cap) for f in formulas if f is not None)]
    joint = joint_automaton(parts, max_states=cap)
    eps = model.epsilon if s.epsilon is None else s.epsilon
    sta = make_sta(joint.dta, laws, eps, clock_reduction=s.clock_reduction,
                   truncation=s.truncation_map)
    return joint, sta


def solve_merged(posed: Posed, mdp: MDP, joint: Joint, sta: STA, t0: float, *,
                 costs: Mapping[str, float] | None = None,
                 seed: int | None = 0) -> ConstrainedResult:
    """The constrained LPs on the product ``mdp`` of the world with ``joint`` (module
    docs), the chosen policy's exact values and the certificate."""
    model, s, cons, then = posed.model, posed.settings, posed.problem.constraints, \
        posed.problem.then
    cost_map = dict(model.costs if costs is None else costs)
    deadline = None if s.time_limit is None else t0 + s.time_limit
    eps = model.epsilon if s.epsilon is None else s.epsilon
    merged = merge(mdp, joint)
    cost_vec = cost_vector(mdp, cost_map)
    t1 = time.perf_counter()

    def rows(which: str) -> list[Row]:
        return rows_for(cons, which)

    def lp(objective: Quantity, maximise: bool, lp_rows: list[Row]) -> Solved:
        left = None if deadline is None else max(deadline - time.perf_counter(), 0.0)
        return optimise(merged, objective, maximise, lp_rows, costs=cost_vec,
                        tol=s.tol * 0.1, time_limit=left)

    task_lo = Quantity("prob", 0, 0.0)
    task_hi = Quantity("prob", 0, 1.0)
    low = lp(task_lo, True, rows("lower"))
    common: dict[str, Any] = dict(merged=merged, joint=joint, sta=sta, mdp=mdp,
                                  objective=posed.problem.objective, model=model,
                                  epsilon=eps)
    if low.status != OPTIMAL:
        return _unsolved(low, cons, rows("lower"), cost_vec, then, t1 - t0, **common)
    chosen = low
    secondary = None
    if then is not None:
        q2 = Quantity("steps" if then == "min-steps" else "cost")
        keep = Row(task_lo, ">=", low.objective - LEXICOGRAPHIC_TOL)
        second = lp(q2, False, [*rows("lower"), keep])
        if second.status != OPTIMAL:
            return _unsolved(second, cons, rows("lower"), cost_vec, then, t1 - t0, **common)
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
        ("lower LP", low.status == OPTIMAL, low.message),
        ("upper LP", high.status == OPTIMAL, high.message),
        ("policy value = LP optimum", lower >= want - certify_tol and
         (then is not None or abs(lower - low.objective) <= certify_tol),
         f"{lower!r} vs {low.objective!r}"),
        ("constraints hold on the policy", all(v.holds for v in values),
         "; ".join(f"{v.constraint}: {v.value!r}" for v in values)),
        ("lower <= upper", lower <= upper + certify_tol, f"{lower!r} <= {upper!r}"),
    )
    controller = ConstrainedController(model.game, sta, joint, merged, mdp, chosen.prob,
                                       chosen.stay, seed=seed)
    value = low.objective
    if posed.minimise:  # Pmin(task) = 1 - Pmax(not task): the bracket read back
        lower, upper, value = 1.0 - upper, 1.0 - lower, 1.0 - value
    return ConstrainedResult(
        status=OPTIMAL, lower=lower, upper=upper, value=value,
        certified=all(ok for _, ok, _ in checks), constraints=values, then=then,
        secondary=secondary, steps=steps, checks=checks, message=chosen.message,
        controller=controller, prob=chosen.prob, stay=chosen.stay,
        timings={"build": t1 - t0, "solve": time.perf_counter() - t1}, **common)


def _unsolved(failed: Solved, cons: tuple[Constraint, ...], rows: list[Row], cost_vec: np.ndarray,
              then: str | None, build: float, **common: Any) -> ConstrainedResult:
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
    return ConstrainedResult(
        status=failed.status, lower=nan, upper=nan, value=nan, certified=False,
        constraints=tuple(values), then=then, secondary=None, steps=nan, checks=(),
        message=failed.message, controller=None, prob=None, stay=None,
        timings={"build": build}, **common)
