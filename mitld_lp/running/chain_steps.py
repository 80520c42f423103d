"""What a controlled chain's builders share, below every one of them: a product state's
labels and valuation text (:func:`state_marks`), where a controller's plan stops
(:func:`stops`) and the product's choice of a controller's action (:func:`choice_of`).
:mod:`mitld_lp.running.chain` (the plain chain) and :mod:`mitld_lp.running.band_chain`
(the interval chain) both read them."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from mitld_lp.controllers.format import ACCEPTED, REJECTED, UNDECIDED
from mitld_lp.mdp import ActionChoices
from mitld_lp.product import Absorbing, ProductState
from mitld_lp.worlds.game import Game
from mitld_lp.worlds.names import state_values, valuation_text

__all__ = ["state_marks", "stops", "choice_of"]


def state_marks(game: Game[Any], verdicts: Any, rec: Any, props: Callable[[str], str],
                fields: tuple[str, ...]) -> tuple[set[str], str]:
    """The labels and the valuation text of product state ``rec`` in a chain: its world
    propositions (``props``) and ``accept`` / ``reject`` by the controller's automaton
    ``verdicts``; an absorbing record's own label (``accept``, ``reject``,
    ``truncated``)."""
    if not isinstance(rec, ProductState):
        end = {Absorbing.TARGET: "accept", Absorbing.SINK: "reject",
               Absorbing.TRUNCATED: "truncated"}[rec]
        return {end}, str(rec)
    here = {props(p) for p in game.propositions(rec.game)}
    v = verdicts[rec.automaton][0]
    if v == ACCEPTED:
        here.add("accept")
    elif v == REJECTED:
        here.add("reject")
    pend = ",".join(sorted(rec.pending))
    return here, valuation_text(fields, (*state_values(game, rec.game), rec.automaton,
                                         f"{{{pend}}}", rec.clock))


def stops(plan: Any, rec: ProductState) -> str | None:
    """Where a controller's ``plan`` stops at product state ``rec``: ``"accept"`` or
    ``"reject"`` once every component of its automaton state is decided, else None."""
    verdicts = plan.verdicts[rec.automaton]
    if UNDECIDED in verdicts:
        return None
    return "accept" if verdicts[0] == ACCEPTED else "reject"


def choice_of(mdp: ActionChoices, i: int, action: str) -> int:
    """The choice of product state ``i`` whose action is ``action`` (the controller's)."""
    for c in range(int(mdp.row_groups[i]), int(mdp.row_groups[i + 1])):
        if mdp.action_name(c) == action:
            return c
    raise ValueError(f"product state {i}: the controller chose {action!r}, which is not "
                     "one of its actions (the controller is not of this product)")
