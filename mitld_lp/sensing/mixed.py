"""The controller of a randomised policy over information states (the
``sensed-constrained`` route, :mod:`mitld_lp.routes.sensed_constrained`), run online.

It follows the information state from the observations as the deterministic sensed
controller does (:class:`~mitld_lp.controllers.kinds.SensedController`, the same
``moves``); in each information state it draws *stay* with the policy's probability
(then plays, uniformly, the actions that keep the run in that state's end component,
for ever; for a *keep*, in its keep states' end component) or
else an action with the policy's weights.  A hypothesis's end is read by the task's
verdict: ``"target"`` when the task accepted, ``"sink"`` otherwise (the controller stops
once nothing undecided is left).  Its ``save`` writes the
``sensed-randomised`` controller file (:mod:`mitld_lp.controllers.format`), which
``mitld-lp run`` and :mod:`mitld_lp.runtime` run with the same draws for the same seed;
:mod:`mitld_lp.running.sensed_chain` writes its controlled chain.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mitld_lp.automata.joint import ACCEPTED
from mitld_lp.controllers.kinds import MixedSensedController
from mitld_lp.controllers.stepper import Decision
from mitld_lp.controllers.tables import MixedSensedPlan
from mitld_lp.solvers.quotient import maximal_end_components
from mitld_lp.worlds.game import Game

__all__ = ["MixedSensedPlan", "MixedSensedController", "mixed_controller"]


def mixed_controller(game: Game[Any], belief: Any, merged: Any, prob: np.ndarray,
                     verdict_type: type, *, seed: int | None = 0) -> MixedSensedController:
    """The controller of ``prob`` (per choice of ``merged``, the information-state
    model of :func:`mitld_lp.routes.sensed_constrained.info_merged`, whose stay choices
    are its ``keep`` ones) on ``belief``; ``verdict_type``: the records of its ends."""
    mdp = belief.mdp
    n = mdp.n_states
    live = np.array([not merged.absorbing[i] for i in range(n)], dtype=bool)
    internal = np.asarray(maximal_end_components(mdp, live).internal, dtype=bool)
    cs, mcs = mdp.choice_state(), merged.mdp.choice_state()
    inside: list[list[str]] = [[] for _ in range(n)]
    kept: list[list[str]] = [[] for _ in range(n)]
    for c in np.flatnonzero(internal).tolist():
        inside[int(cs[c])].append(mdp.action_name(c))
    for c in np.flatnonzero(merged.keep_internal).tolist():  # a task's safety part kept
        kept[int(mcs[c])].append(merged.mdp.action_name(c))
    decisions: list[Decision | None] = [None] * n
    for s in np.flatnonzero(live).tolist():
        first, last = int(merged.mdp.row_groups[s]), int(merged.mdp.row_groups[s + 1])
        names, weights, stay = [], [], 0.0
        for c in range(first, last):
            assert int(mcs[c]) == s
            p = float(prob[c])
            if p <= 0.0:
                continue
            if merged.keep[c]:
                stay += p
            else:
                names.append(merged.mdp.action_name(c))
                weights.append(p)
        if not names:  # it stays for sure: any weights will do after the draw
            names, weights = list(inside[s][:1]) or [merged.mdp.action_name(first)], [1.0]
        decisions[s] = Decision(tuple(names), np.asarray(weights), stay=min(stay, 1.0),
                                inside=tuple(kept[s] or inside[s]))

    def end(v: Any) -> Any:
        if isinstance(v, verdict_type):
            return "target" if v.verdicts[0] == ACCEPTED else "sink"
        return v

    moves = {k: {obs: end(v) for obs, v in row.items()} for k, row in belief.moves.items()}
    initial = mdp.states[mdp.initial]
    plan = MixedSensedPlan(
        initial=end(initial) if merged.absorbing[mdp.initial] else mdp.initial,
        actions=(None,) * n, moves=moves, sensed=frozenset(belief.sensed),
        events=frozenset(belief.sta.events), ignored=frozenset(belief.ignored), game=game,
        decisions=tuple(decisions))
    return MixedSensedController(plan, seed=seed)
