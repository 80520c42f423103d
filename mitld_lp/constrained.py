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
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mitld_lp import defaults
from mitld_lp.automata.joint import Joint, joint_automaton
from mitld_lp.automata.sta import STA, make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.constraints import (
    LEXICOGRAPHIC_TOL,
    THEN,
    Constraint,
    ConstraintError,
    parse_constraints,
)
from mitld_lp.controller_random import ConstrainedController
from mitld_lp.distributions import FirstOccurrence
from mitld_lp.distributions.literal import from_spec
from mitld_lp.logic import check
from mitld_lp.logic.fragment import CO_SAFE
from mitld_lp.logic.syntax import DistLiteral, atoms
from mitld_lp.mdp import MDP
from mitld_lp.model import Model
from mitld_lp.product import ProductState, product
from mitld_lp.solvers.constrained import INFEASIBLE, OPTIMAL, Row, Solved, optimise
from mitld_lp.solvers.constrained_model import Merged, Quantity, merge

__all__ = ["synthesize_constrained", "ConstrainedResult", "ConstraintValue",
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

    ``status``: ``"optimal"``, ``"infeasible"`` (no policy meets the constraints; each
    :class:`ConstraintValue` then carries ``feasible_bound``) or ``"failed"``.
    ``lower``: the task's exact probability under the returned policy (lower model);
    ``upper``: the upper model's LP optimum; ``value``: the lower model's LP optimum.
    ``then``/``secondary``: the lexicographic objective and its exact value on the policy.
    """

    status: str
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
            rows.append(self._row(s, m.mdp.action_name(c), float(self.prob[c])))
        for s in np.flatnonzero(self.stay > 0).tolist():
            rows.append(self._row(int(s), "stay", float(self.stay[s])))
        return rows

    def _row(self, s: int, action: str, p: float) -> dict[str, Any]:
        rec = self.mdp.states[int(self.merged.origin[s])]
        assert isinstance(rec, ProductState)
        return {"game_state": rec.game,
                "automaton_state": list(self.joint.components[rec.automaton]),
                "pending": sorted(rec.pending), "clock": rec.clock, "action": action,
                "probability": p}

    def summary(self) -> dict[str, Any]:
        """The numbers, as plain data (the CLI prints it as JSON)."""
        return {
            "status": self.status, "lower": self.lower, "upper": self.upper,
            "lp_value": self.value, "certified": self.certified,
            "expected_steps": self.steps,
            "constraints": [
                {"constraint": str(c.constraint), "value": c.value, "bound": c.constraint.bound,
                 "holds": c.holds, **({"feasible_bound": c.feasible_bound}
                                      if self.status == INFEASIBLE else {})}
                for c in self.constraints
            ],
            "then": self.then, "secondary": self.secondary,
            "checks": [{"name": n, "ok": ok, "detail": d} for n, ok, d in self.checks],
            "message": self.message,
            "states": self.merged.mdp.n_states, "product_states": self.mdp.n_states,
            "randomized_states": int(np.count_nonzero(self._mixed())) if self.prob is not None
            else 0,
        }

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


def synthesize_constrained(
    model: Model,
    constraints: Iterable[str | Constraint] = (),
    *,
    then: str | None = None,
    costs: Mapping[str, float] | None = None,
    epsilon: float | None = None,
    max_states: int = defaults.MAX_STATES,
    max_memory: int | None = None,
    certify_tol: float = defaults.CERTIFY_TOL,
    seed: int | None = 0,
) -> ConstrainedResult:
    """Maximise the task's probability subject to ``constraints`` (texts or records;
    the model's own ``constraints`` come first), then, with ``then`` (``"min-steps"``
    or ``"min-cost"``), minimise the expected steps / cost among the policies within
    :data:`LEXICOGRAPHIC_TOL` of that probability.  ``costs``: per action (default
    the model's ``[costs]``, 1 for any action not named).  ``seed`` seeds the
    controller's generator.  See the module docstring for what is certified."""
    if then is not None and then not in THEN:
        raise ConstraintError(f"then: must be one of {', '.join(THEN)}, got {then!r}")
    cons = parse_constraints(model.constraints) + parse_constraints(constraints)
    cost_map = dict(model.costs if costs is None else costs)
    t0 = time.perf_counter()
    laws = _laws(model, cons)
    formulas = [c.formula for c in cons if c.kind == "prob"]
    parts = [to_dta(model.spec, max_states=max_states),
             *(to_dta(f, max_states=max_states) for f in formulas if f is not None)]
    for part, text in zip(parts, ["the task", *map(str, formulas)], strict=True):
        if part.fragment != CO_SAFE:  # the joint automaton reads acceptance by reaching
            raise ConstraintError(
                f"{text}: class {part.fragment}; constraints are solved for co-safe "
                "tasks and constraint formulas (a safety part such as G !h can be written "
                "as the constraint P(F h) <= 0)")
    joint = joint_automaton(parts, max_states=max_states)
    eps = model.epsilon if epsilon is None else epsilon
    sta = make_sta(joint.dta, laws, eps)
    mdp = product(model.game, sta, max_states=max_states, max_memory=max_memory)
    merged = merge(mdp, joint)
    cost_vec = cost_vector(mdp, cost_map)
    t1 = time.perf_counter()
    def rows(which: str) -> list[Row]:
        return rows_for(cons, which)
    task_lo = Quantity("prob", 0, 0.0)
    task_hi = Quantity("prob", 0, 1.0)
    low = optimise(merged, task_lo, True, rows("lower"), costs=cost_vec)
    common: dict[str, Any] = dict(merged=merged, joint=joint, sta=sta, mdp=mdp)
    if low.status != OPTIMAL:
        return _unsolved(low, cons, rows("lower"), cost_vec, then, t1 - t0, **common)
    chosen = low
    secondary = None
    if then is not None:
        q2 = Quantity("steps" if then == "min-steps" else "cost")
        keep = Row(task_lo, ">=", low.objective - LEXICOGRAPHIC_TOL)
        second = optimise(merged, q2, False, [*rows("lower"), keep], costs=cost_vec)
        if second.status != OPTIMAL:
            return _unsolved(second, cons, rows("lower"), cost_vec, then, t1 - t0, **common)
        chosen = second
        secondary = second.values[0]
    high = low
    if merged.truncated.any():
        high = optimise(merged, task_hi, True, rows("upper"), costs=cost_vec)
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
    return ConstrainedResult(
        status=OPTIMAL, lower=lower, upper=upper, value=low.objective,
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
