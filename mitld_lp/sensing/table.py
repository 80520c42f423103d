"""The policy table of a sensed answer (:func:`mitld_lp.report.policy_table` reads it
for the ``sensed`` route)."""

from __future__ import annotations

from typing import Any

from mitld_lp.sensing.belief import InfoState
from mitld_lp.worlds.names import state_record

__all__ = ["sensed_table"]


def sensed_table(result: Any) -> list[dict[str, Any]]:
    """One row per information state still undecided, with the columns of the
    plain route's table (:data:`mitld_lp.report.POLICY_COLUMNS`):
    ``automaton_state`` the obligations the hypotheses still alive leave (joined by
    ``" ; "``), ``pending`` the events not known to have happened (sensed and not
    reported, or unsensed and pending), ``value`` the policy's exact value from
    there (truncated hypotheses lose)."""
    mdp, low = result.mdp, result.lower_model
    obligations = result.dta.states
    rows = []
    for i, s in enumerate(mdp.states):
        if not isinstance(s, InfoState) or low.policy[i] < 0:
            continue
        unknown = (set(result.belief.sensed) - s.reported) | s.pending
        rows.append({
            "game_state": state_record(result.model.game, s.world),
            "automaton_state": " ; ".join(sorted({str(obligations[q])
                                                  for _, q in s.hypotheses})),
            "pending": sorted(unknown), "clock": s.clock,
            "action": mdp.action_name(int(low.policy[i])),
            "value": float(low.policy_values[i]), "accepting_component": False})
    return rows
