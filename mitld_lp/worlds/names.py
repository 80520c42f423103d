"""Names of world states in the world's own terms, for the exports, the decision tree
and the policy table: a grid cell's coordinates ``x`` and ``y``, a PRISM world's
variables by name, and otherwise the state itself (a gymnasium observation integer, an
explicit game's state) under the one name ``state``."""

from __future__ import annotations

import sys
from collections.abc import Hashable
from typing import Any

from mitld_lp.worlds.game import Game

__all__ = ["state_fields", "state_record", "state_values", "valuation_text", "world_variables"]


def world_variables(game: Game[Any]) -> tuple[str, ...] | None:
    """The names of the world's variables when its states are tuples of their values
    (a PRISM world's ``variables``), else None."""
    names = getattr(game, "variables", None)
    if isinstance(names, tuple) and names and all(isinstance(v, str) for v in names):
        initial = game.initial
        if isinstance(initial, tuple) and len(initial) == len(names):
            return names
    return None


def state_fields(game: Game[Any]) -> tuple[str, ...]:
    """The names of a world state's parts: ``("x", "y")`` for a grid, a PRISM world's
    variables, else ``("state",)``."""
    grid = sys.modules.get("mitld_lp.worlds.grid")  # not imported: no game is a grid
    if grid is not None and isinstance(game, grid.GridWorld):
        return ("x", "y")
    names = world_variables(game)
    return names if names is not None else ("state",)


def state_values(game: Game[Any], state: Hashable) -> tuple[Any, ...]:
    """The values of ``state``'s parts, in the order of :func:`state_fields`."""
    if len(state_fields(game)) == 1:
        return (state,)
    assert isinstance(state, tuple)
    return state


def state_record(game: Game[Any], state: Hashable) -> Any:
    """``state`` as the policy table writes it: a PRISM world's state as an object of
    its variables by name (``{"open": False, "x": 2}``, which ``mitld-lp run`` reads
    back), any other world's state as it is (a grid cell ``(x, y)``, a gymnasium
    observation integer)."""
    names = world_variables(game)
    if names is None:
        return state
    assert isinstance(state, tuple)
    return dict(zip(names, state, strict=True))


def _text(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return "".join(str(value).split())  # one token: a DRN line is split on whitespace


def valuation_text(fields: tuple[str, ...], values: tuple[Any, ...]) -> str:
    """``x=1 & y=2`` (booleans as ``true``/``false``, no spaces inside a value)."""
    return " & ".join(f"{f}={_text(v)}" for f, v in zip(fields, values, strict=True))
