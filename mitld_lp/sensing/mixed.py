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

from collections.abc import Iterator, Mapping
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

    moves = _EndedMoves(belief.moves, verdict_type)
    initial = mdp.states[mdp.initial]
    plan = MixedSensedPlan(
        initial=_end(initial, verdict_type) if merged.absorbing[mdp.initial] else mdp.initial,
        actions=(None,) * n, moves=moves, sensed=frozenset(belief.sensed),
        events=frozenset(belief.sta.events), ignored=frozenset(belief.ignored), game=game,
        decisions=tuple(decisions))
    return MixedSensedController(plan, seed=seed)


def _end(v: Any, verdict_type: type) -> Any:
    """A successor as the plan keeps it: a verdict record as its end, ``target`` where
    the task is accepted, else ``sink``; any other as it is."""
    if isinstance(v, verdict_type):
        return "target" if v.verdicts[0] == ACCEPTED else "sink"
    return v


class _EndedMoves(Mapping[Any, Mapping[Any, Any]]):
    """The product's moves (``moves[(state, action)][obs]``) with each successor read by
    :func:`_end`, a state and action's table made the first time it is asked for (not
    all of them when the controller is made: a chain or a run asks for few)."""

    def __init__(self, moves: Mapping[Any, Mapping[Any, Any]], verdict_type: type) -> None:
        self._moves, self._type = moves, verdict_type
        self._made: dict[Any, dict[Any, Any]] = {}

    def __getitem__(self, key: Any) -> Mapping[Any, Any]:
        table = self._made.get(key)
        if table is None:
            table = self._made[key] = {obs: _end(v, self._type)
                                       for obs, v in self._moves[key].items()}
        return table

    def __iter__(self) -> Iterator[Any]:
        return iter(self._moves)

    def __len__(self) -> int:
        return len(self._moves)

    def __contains__(self, key: object) -> bool:
        return key in self._moves
