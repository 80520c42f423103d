"""What a :class:`~mitld_lp.result.Result` says, as data: the policy table (one row per
undecided product state, or per (state, action) of a randomised policy), the JSON
summary (the command line's ``--json``, one schema for every route) and the table a
notebook shows.  Files are written by :mod:`mitld_lp.files.write`."""

from __future__ import annotations

import math
from decimal import ROUND_CEILING, ROUND_FLOOR, Decimal
from typing import Any

import numpy as np

from mitld_lp.files.write import POLICY_COLUMNS  # the keys of a policy_table row
from mitld_lp.product import ProductState
from mitld_lp.worlds.names import state_record

#: A :class:`mitld_lp.result.Result` (not imported: it imports this module, and an
#: import, even for types only, would make a circle).
Result = Any

__all__ = ["POLICY_COLUMNS", "SUMMARY_KEYS", "policy_table", "summary", "html",
           "probability_text", "bracket_text"]


def probability_text(x: float, direction: str = "nearest") -> str:
    """A probability as text: 7 decimals, or 7 significant digits below 1e-3 (and for
    0 < x, when 7 decimals would print 0).  ``direction``: ``"down"`` / ``"up"``
    rounds the printed digits toward minus / plus infinity (a bound printed so that it
    stays a bound), ``"nearest"`` as Python's formatting does."""
    if x != x or x in (float("inf"), float("-inf")):
        return str(x)
    fixed = x == 0 or abs(x) >= 1e-3
    if direction == "nearest":
        return f"{x:.7f}" if fixed else f"{x:.7g}"
    d = Decimal(x)  # exact
    rounding = ROUND_FLOOR if direction == "down" else ROUND_CEILING
    if fixed:
        return f"{d.quantize(Decimal('1e-7'), rounding=rounding):.7f}"
    q = d.quantize(Decimal(1).scaleb(d.adjusted() - 6), rounding=rounding)
    # q has 7 significant digits: the nearest double prints them back as Python does
    return f"{float(q):.7g}" if abs(q) < Decimal("1e-3") else f"{q:.7f}"


def bracket_text(lower: float, upper: float) -> str:
    """``[lower, upper]`` printed outward: the lower end's digits rounded down, the
    upper end's up, so that the printed bracket contains the certified one."""
    return f"[{probability_text(lower, 'down')}, {probability_text(upper, 'up')}]"



def policy_table(result: Result) -> list[dict[str, Any]]:
    """The policy as data: one row per product state that is still undecided.

    A randomised (constrained) policy has one row per (state, action) it takes with
    positive probability (:func:`randomised_table`).

    Keys: ``game_state`` (the game's own state; a PRISM world's as an object of its
    variables by name, :func:`mitld_lp.worlds.names.state_record`), ``automaton_state``
    (the obligation still to satisfy, as formula text), ``pending`` (the events that
    have not happened, sorted), ``clock`` (steps counted for the pending events, capped
    where their hazards stop changing), ``action`` (the policy's action), ``value`` (the
    probability that the policy satisfies the task from there, truncation counted as
    failure: from the linear solve on the policy's Markov chain that the certificate
    starts from, in floating point, ``result.lower_model.policy_values``),
    ``accepting_component`` (whether the state lies in an accepting end component of a
    task with a safety part: the task is then kept by playing ``action`` forever, an
    action that never leaves the component; always false for a co-safe task). For
    ``objective = "min"`` ``value`` is the most the task can happen under the policy
    from there (truncation counted as the task happening): the policy's value, or, where
    the minimum is the complement's maximum read back (``result.complemented``), ``1 -``
    the complement's.
    """
    return result.part.policy_table(result)


def model_table(result: Result) -> list[dict[str, Any]]:
    """:func:`policy_table` of an answer whose policy is a deterministic one on the
    product (the plain and robust routes)."""
    mdp, low = result.mdp, result.lower_model
    policy, values = low.policy, low.policy_values
    if result.complemented:  # Pmin(task) = 1 - Pmax(not task), state by state
        values = 1.0 - np.asarray(values, dtype=np.float64)
    obligations = result.dta.states
    goal = result.acceptance.goal
    game = result.model.game
    rows: list[dict[str, Any]] = []
    for i, state in enumerate(mdp.states):
        if not isinstance(state, ProductState) or policy[i] < 0:
            continue
        rows.append({
            "game_state": state_record(game, state.game),
            "automaton_state": str(obligations[state.automaton]),
            "pending": sorted(state.pending),
            "clock": state.clock,
            "action": mdp.action_name(int(policy[i])),
            "value": float(values[i]),
            "accepting_component": bool(goal[i]) and result.part.kept_components,
        })
    return rows


def randomised_table(result: Result) -> list[dict[str, Any]]:
    """A randomised policy as data: one row per (state, action) it takes with positive
    probability: the world state, the joint automaton's component states, pending
    events, clock, the action (``keep`` for an action that keeps a safety part,
    ``stay`` for staying for ever) and its ``probability``."""
    if result.prob is None or result.stay is None:
        return []
    m = result.merged
    cs = m.mdp.choice_state()
    game = None if result.model is None else result.model.game

    def row(s: int, action: str, p: float) -> dict[str, Any]:
        rec = result.mdp.states[int(m.origin[s])]
        assert isinstance(rec, ProductState)
        return {"game_state": rec.game if game is None else state_record(game, rec.game),
                "automaton_state": list(result.joint.components[rec.automaton]),
                "pending": sorted(rec.pending), "clock": rec.clock, "action": action,
                "probability": p}

    rows = []
    for c in np.flatnonzero(result.prob > 0).tolist():
        s = int(cs[c])
        if not m.absorbing[s]:
            rows.append(row(s, "keep" if m.keep[c] else m.mdp.action_name(c),
                            float(result.prob[c])))
    rows.extend(row(int(s), "stay", float(result.stay[s]))
                for s in np.flatnonzero(result.stay > 0).tolist())
    return rows


#: The keys of every result's :func:`summary` (the command line's ``--json``), whatever
#: the route; a part a route does not have is ``None``, ``[]``, ``{}``, ``0`` or false.
SUMMARY_KEYS = (
    "model", "objective", "route", "status", "certified", "lower", "upper", "value",
    "failed_checks", "checks", "method", "states", "choices", "transitions",
    "product_states", "dta_states", "epsilon", "epsilon_achieved", "truncation_points",
    "seconds", "timings", "lp", "iteration", "robust", "bands", "first_step_hazards",
    "ambiguous_choices", "constraints", "then", "secondary", "expected_steps",
    "randomized_states", "message", "sensors", "complement", "precision", "width", "exact",
    "exact_bracket", "bands_reading", "expected_at",
)


def summary(result: Any) -> dict[str, Any]:
    """A JSON-ready record of any synthesis result (the command line's ``--json``), with
    the keys :data:`SUMMARY_KEYS` on every route (docs/results.md).

    ``lower``, ``upper``: the certified bracket, full-precision floats that hold for the
    model's exact value (in the task's terms also for ``objective = "min"``);
    ``complement``: for a minimum read back from the complement's maximum, the
    complement's bracket ``[a, b]`` (``1 - value`` lies in it), else ``None``;
    ``precision``: the relative width asked; ``width``: ``total``, ``truncation`` and
    ``solver`` parts of ``upper - lower``; ``value``: the method's optimum (the lower
    model's);
    ``states`` / ``choices`` / ``transitions``: the model the solver worked on (for the
    constrained route the merged product, ``product_states`` the product's);
    ``lp`` and ``iteration``: the lower model's solver records where the route has them;
    ``bands_reading``: with a band, ``"worst"`` (the bracket is the worst case over the
    bands, guaranteed by the policy) or ``"best"`` (the best case, PRISM's ``Pmaxmax``:
    the policy reaches it only under the law its answer names), else ``None``;
    ``expected_at``: the law of the bands ``expected_steps`` is at (:func:`expected_at`).
    """
    out = dict.fromkeys(SUMMARY_KEYS)
    mdp, sta = result.mdp, result.sta
    out.update(
        model=None if result.model is None else result.model.name,
        objective=result.objective, route=result.route, certified=bool(result.certified),
        lower=result.lower, upper=result.upper, value=result.value,
        failed_checks=[f"{c.name}: {c.detail}" for c in result.failed_checks],
        method=result.method, product_states=mdp.n_states,
        epsilon=result.epsilon, epsilon_achieved=sta.epsilon_achieved,
        truncation_points=dict(sta.truncation_points), seconds=result.seconds,
        timings=dict(result.timings), robust=bool(result.bands), bands=dict(result.bands),
        first_step_hazards={e: list(b) for e, b in result.first_step_hazards().items()},
        ambiguous_choices=0, constraints=[], randomized_states=0, status=str(result.status),
        checks=[{"name": c.name, "ok": c.passed, "detail": c.detail} for c in result.checks],
        dta_states=result.automaton.n_states,
        sensors={a: s.detect for a, s in result.sensors.items()},
        complement=None if result.complement is None else list(result.complement),
        precision=result.precision, width=dict(result.width),
        bands_reading=result.part.reading if result.bands else None,
        **_exact_part(result.exact),
    )
    out.update(result.part.summary(result))
    return out


def models_summary(result: Result) -> dict[str, Any]:
    """The keys an answer from two solved models fills (plain and sensed routes): the
    sizes of the model solved, the lower model's LP and the iteration's bracket."""
    mdp, low, high = result.mdp, result.lower_model, result.upper_model
    out: dict[str, Any] = dict(states=mdp.n_states, choices=mdp.n_choices,
                               transitions=mdp.n_transitions)
    lp = low.lp
    out["lp"] = None if lp is None else {
        "status": lp.status.value, "solver": lp.solver, "backend": lp.backend,
        "primal_objective": lp.primal_objective, "dual_objective": lp.dual_objective,
        "iterations": lp.iterations, "seconds": lp.seconds, "message": lp.message}
    # a minimum solved as one: the controller's model (upper) bounds it from above
    below, above = ((high.iteration.value_lower, low.iteration.value_upper)
                    if result.sense == "min" else
                    (low.iteration.value_lower, high.iteration.value_upper))
    out["iteration"] = {"status": low.iteration.status.value,
                        **_task_terms(result, below, above),
                        "iterations": low.iteration.iterations}
    return out


def robust_summary(result: Result) -> dict[str, Any]:
    """The keys a robust answer fills: the interval MDP's sizes, its ambiguous choices,
    the policy's robust LP and the robust iteration's bracket."""
    mdp, low, high = result.mdp, result.lower_model, result.upper_model
    out: dict[str, Any] = dict(states=mdp.n_states, choices=mdp.n_choices,
                               transitions=mdp.n_transitions,
                               ambiguous_choices=mdp.ambiguous_choices)
    out["lp"] = None if low.lp is None else {
        "status": low.lp.status.value, "variables": low.lp.variables,
        "constraints": low.lp.constraints, "message": low.lp.message}
    out["iteration"] = {"status": low.iteration.status.value,
                        **_task_terms(result, low.bracket[0], high.bracket[1]),
                        "iterations": low.iteration.sweeps}
    if result.part.message:  # the bands read for their best law: what the policy is worth
        out["message"] = result.part.message
    return out


def _task_terms(result: Result, lower: float, upper: float) -> dict[str, float]:
    """A bracket of the solved automaton in the task's terms: the complement's
    ``[lower, upper]`` is ``[1 - upper, 1 - lower]`` of a minimised task read back from
    its complement (``result.complemented``)."""
    if result.complemented:
        return {"lower": 1.0 - upper, "upper": 1.0 - lower}
    return {"lower": lower, "upper": upper}


def constrained_summary(result: Any) -> dict[str, Any]:
    """The keys a constrained result fills (its model is the merged product)."""
    merged = result.merged.mdp
    infeasible = result.status == "infeasible"
    return {
        "states": merged.n_states, "choices": merged.n_choices,
        "transitions": merged.n_transitions,
        "constraints": [
            {"constraint": str(c.constraint), "value": c.value, "bound": c.constraint.bound,
             "holds": c.holds, "certified": list(c.bounds), "miss": c.miss,
             **({"feasible_bound": c.feasible_bound} if infeasible else {})}
            for c in result.constraints],
        "then": result.then, "secondary": result.secondary,
        "expected_steps": result.steps, "expected_at": expected_at(result),
        "message": result.message, "randomized_states": result.randomized_states,
    }


#: ``expected_at``'s values: a band answer's ``expected_steps`` (and its ``then``'s
#: ``secondary``) at the worst law of the bands, or at the law the answer chose.
EXPECTED_AT = ("worst law", "chosen law")


def expected_at(result: Any) -> str | None:
    """The law of the bands a constrained answer's expected steps (cost) are at:
    ``"worst law"`` (nature maximising them: the policy's guarantee) or, with the bands
    read for their best law (``--bands best``), ``"chosen law"`` (the law the answer
    chose, no worst case); ``None`` for point laws, and where no finite expected steps
    were found (the JSON's ``expected_steps`` is then ``null`` too)."""
    if not result.bands or not math.isfinite(result.steps):
        return None
    return EXPECTED_AT[0] if result.part.reading == "worst" else EXPECTED_AT[1]


def html(result: Result) -> str:
    """An HTML table of the answer (what a notebook shows for a result)."""
    from html import escape  # a notebook's: the command line never needs it

    rows = [
        ("model", "" if result.model is None else result.model.name),
        ("spec", "" if result.model is None else str(result.model.spec)),
        ("optimum in", bracket_text(result.lower, result.upper)),
        ("certified", "yes" if result.certified else "NO: " + "; ".join(
            c.name for c in result.failed_checks)),
        ("status", str(result.status)),
        ("epsilon achieved", f"{result.sta.epsilon_achieved:.3g}"),
        ("sizes", f"{result.automaton.n_states} automaton states, {result.mdp.n_states} "
                  f"states, {result.mdp.n_transitions} transitions"),
    ]
    body = "".join(
        f"<tr><th style='text-align:left'>{escape(k)}</th><td>{escape(v)}</td></tr>"
        for k, v in rows
    )
    return f"<table>{body}</table>"


def _exact_part(exact: Any) -> dict[str, Any]:
    """``exact``: the exact optimum as ``"p/q"`` (None unless asked for, and when a
    truncation leaves two models); ``exact_bracket``: both models' optima, ``["p/q",
    "r/s"]`` (None unless asked for)."""
    if exact is None:
        return {}
    point = exact.value
    return {"exact": None if point is None else _fraction(point),
            "exact_bracket": [_fraction(exact.lower), _fraction(exact.upper)]}


def _fraction(x: Any) -> str:
    return f"{x.numerator}/{x.denominator}"
