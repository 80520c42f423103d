"""A world's moves in rational arithmetic, for an exact answer (:mod:`mitld_lp.exact`).

A world that knows its probabilities as rational numbers offers a method beside
:meth:`~mitld_lp.worlds.game.Game.successors`::

    def exact_successors(self, state, action, events) -> tuple[tuple[S, Fraction], ...]

with the same next states in the same order, each with its probability as written
(``fractions.Fraction`` or any exact rational; they sum to exactly 1).  The grid world
has it (``slip`` as written, :mod:`mitld_lp.util.decimals`), and so has a PRISM world
(Storm's exact build, :mod:`mitld_lp.worlds.prism_exact`).  A world that computes its
probabilities in floating point (a gymnasium table, a ``[python]`` world, an
:class:`~mitld_lp.worlds.game.ExplicitGame`) has none, and an exact answer refuses it
by name.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["exact_successors_of"]

ExactMoves = Callable[[Any, str, frozenset[str]], tuple[tuple[Any, Any], ...]]


def exact_successors_of(world: object) -> ExactMoves | None:
    """The world's ``exact_successors`` (module docs), or None when it has none."""
    method = getattr(type(world), "exact_successors", None)
    if method is None:
        return None
    bound: ExactMoves = method.__get__(world)
    return bound
