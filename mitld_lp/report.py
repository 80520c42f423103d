"""What a :class:`~mitld_lp.synthesis.SynthesisResult` says, as data: the policy table
(one row per undecided product state), the JSON summary (the command line's ``--json``)
and the table a notebook shows.  Files are written by :mod:`mitld_lp.files`."""

from __future__ import annotations

from html import escape
from typing import TYPE_CHECKING, Any

from mitld_lp.product import ProductState
from mitld_lp.world_names import state_record

if TYPE_CHECKING:
    from mitld_lp.synthesis import SynthesisResult

__all__ = ["POLICY_COLUMNS", "policy_table", "summary", "html"]

POLICY_COLUMNS = ("game_state", "automaton_state", "pending", "clock", "action", "value",
                  "accepting_component")
"""The keys of a :func:`policy_table` row, in the order the CSV file writes them."""


def policy_table(result: SynthesisResult) -> list[dict[str, Any]]:
    """The policy as data: one row per product state that is still undecided.

    Keys: ``game_state`` (the game's own state; a PRISM world's as an object of its
    variables by name, :func:`mitld_lp.world_names.state_record`), ``automaton_state``
    (the obligation still to satisfy, as formula text), ``pending`` (the events that
    have not happened,
    sorted), ``clock`` (steps counted for the pending events, capped where their hazards
    stop changing), ``action`` (the policy's action), ``value`` (the probability that
    the policy satisfies the task from there, truncation counted as failure: exact, from
    the linear solve on the policy's Markov chain that certified it,
    ``result.lower_model.policy_values``), ``accepting_component`` (whether the state
    lies in an accepting end component of a task with a safety part: the task is then
    kept by playing ``action`` forever, an action that never leaves the component;
    always false for a co-safe task).
    """
    mdp, low = result.mdp, result.lower_model
    policy, values = low.policy, low.policy_values
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
            "accepting_component": bool(goal[i]),
        })
    return rows


def summary(result: SynthesisResult) -> dict[str, Any]:
    """A JSON-ready record of ``result`` (the command line's ``--json``).

    ``value`` is the lower model's optimum by the method (``lower_model.value``);
    ``lower``, ``upper``: the certified bracket; the sizes are the automaton's and the
    product's; ``lp`` and ``iteration`` the lower model's solver records.
    """
    low, high, mdp, sta = result.lower_model, result.upper_model, result.mdp, result.sta
    lp = low.lp
    return {
        "model": result.model.name,
        "status": result.status.value,
        "lower": result.lower,
        "upper": result.upper,
        "value": low.value,
        "certified": result.certified,
        "failed_checks": [f"{c.name}: {c.detail}" for c in result.failed_checks],
        "method": result.method,
        "states": mdp.n_states,
        "choices": mdp.n_choices,
        "transitions": mdp.n_transitions,
        "dta_states": result.dta.n_states,
        "epsilon": result.epsilon,
        "epsilon_achieved": sta.epsilon_achieved,
        "truncation_points": dict(sta.truncation_points),
        "seconds": result.seconds,
        "timings": dict(result.timings),
        "lp": None if lp is None else {
            "status": lp.status.value,
            "solver": lp.solver,
            "backend": lp.backend,
            "primal_objective": lp.primal_objective,
            "dual_objective": lp.dual_objective,
            "iterations": lp.iterations,
            "seconds": lp.seconds,
            "message": lp.message,
        },
        "iteration": {
            "status": low.iteration.status.value,
            "lower": low.iteration.value_lower,
            "upper": high.iteration.value_upper,
            "iterations": low.iteration.iterations,
        },
    }


def html(result: SynthesisResult) -> str:
    """An HTML table of the answer (what a notebook shows for a result)."""
    rows = [
        ("model", result.model.name),
        ("spec", str(result.model.spec)),
        ("optimum in", f"[{result.lower:.7f}, {result.upper:.7f}]"),
        ("certified", "yes" if result.certified else "NO: " + "; ".join(
            c.name for c in result.failed_checks)),
        ("status", result.status.value),
        ("epsilon achieved", f"{result.sta.epsilon_achieved:.3g}"),
        ("sizes", f"{result.dta.n_states} automaton states, {result.mdp.n_states} "
                  f"states, {result.mdp.n_transitions} transitions"),
    ]
    body = "".join(
        f"<tr><th style='text-align:left'>{escape(k)}</th><td>{escape(v)}</td></tr>"
        for k, v in rows
    )
    return f"<table>{body}</table>"
