"""The product's size budgets, checked before the work that would exceed them.

:func:`estimate_size` bounds the product from its factors before anything is built;
:class:`BuildBudget` counts the states and transitions as the build goes and refuses,
before a batch's new states are stored, a product over ``max_states`` states or over
``max_memory`` bytes (:data:`BYTES_PER_STATE`, :data:`BYTES_PER_TRANSITION`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

from mitld_lp.automata.sta import STA
from mitld_lp.game import Game, world_members

__all__ = [
    "ProductTooLarge",
    "BYTES_PER_STATE",
    "BYTES_PER_TRANSITION",
    "MAX_INDEX",
    "SizeEstimate",
    "BuildBudget",
    "default_max_memory",
    "estimate_size",
]

MAX_INDEX = 2**31 - 1
"""The most states an MDP can hold: the matrix's column indices are int32."""


class ProductTooLarge(RuntimeError):
    """The product would exceed a budget (``max_states`` or ``max_memory``); a user
    error: the message names the numbers and what to change."""


# Peak bytes of the construction, measured with experiments/bench_product.py on builds
# of 0.3-3.5M states (tracemalloc, numpy's buffers included): about 30 bytes per
# transition (the matrix, the batches' rows, the merge) and 80 per state (the index at
# load 1/4-1/2, the keys, the rows per choice); rounded up.
BYTES_PER_TRANSITION = 32
BYTES_PER_STATE = 96


def default_max_memory() -> int:
    """Half the machine's physical memory, in bytes (8 GiB if the system cannot say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2
    except (AttributeError, ValueError, OSError):
        return 8 << 30


@dataclass(frozen=True, slots=True)
class SizeEstimate:
    """An upper bound on the product's states from its factors, before anything is built.

    ``states = game_states * automaton_states * situations + 3``: every ordinary product
    state is a game state, a non-absorbing automaton state and a situation (the pending
    events and a clock value at most ``cap(pending)``), plus the three absorbing states.
    ``game_states`` is None (and so is ``states``) for a game that does not say how many
    states it has (:attr:`mitld_lp.game.WorldMembers.n_states`).
    """

    game_states: int | None
    automaton_states: int
    situations: int

    @property
    def states(self) -> int | None:
        if self.game_states is None:
            return None
        return self.game_states * self.automaton_states * self.situations + 3

    def __str__(self) -> str:
        game = "?" if self.game_states is None else f"{self.game_states:,}"
        total = "unknown" if self.states is None else f"{self.states:,}"
        return (
            f"at most {total} states from the factors: {game} game states x "
            f"{self.automaton_states:,} non-absorbing automaton states x "
            f"{self.situations:,} event "
            "situations (pending events, clock)"
        )


def estimate_size(game: Game[Any], sta: STA) -> SizeEstimate:
    """:class:`SizeEstimate` of ``product(game, sta)``, in time linear in the events.

    The situations are counted exactly: with the events' caps sorted,
    ``c_0 <= ... <= c_{k-1}``, the pending sets whose largest cap is ``c_i`` (ties broken
    by the order) are ``2^i``, each with clock values ``0..c_i``; the empty set has one.
    """
    dta = sta.dta
    automaton = dta.n_states - (dta.accepting is not None) - (dta.rejecting is not None)
    caps = sorted(c.cap for c in sta.clocks.values())
    situations = 1 + sum((1 << i) * (c + 1) for i, c in enumerate(caps))
    return SizeEstimate(world_members(game).n_states, max(automaton, 0), situations)


@dataclass(slots=True)
class BuildBudget:
    """The limits of one build and what the build has used so far."""

    max_states: int
    max_memory: int
    estimate: SizeEstimate
    expanded: int = 0  # states whose rows are built
    transitions: int = 0  # their transitions

    def check(self, states: int) -> None:
        """Raise :class:`ProductTooLarge` if ``states`` states would exceed a budget."""
        if states > MAX_INDEX:  # the matrix's column indices are int32
            raise ProductTooLarge(
                f"the product has more than {MAX_INDEX:,} states ({self.estimate}), more "
                "than an MDP can index; loosen epsilon or shrink the model"
            )
        if states > self.max_states:
            raise ProductTooLarge(
                f"the product has more than {self.max_states:,} reachable states "
                f"({states:,} found; {self.estimate}); raise max_states, loosen epsilon, "
                "or shrink the model"
            )
        per_state = self.transitions / self.expanded if self.expanded else 0.0
        need = states * (BYTES_PER_STATE + per_state * BYTES_PER_TRANSITION)
        if need > self.max_memory:
            raise ProductTooLarge(
                f"the product would need about {_bytes(need)}, more than max_memory = "
                f"{_bytes(self.max_memory)} ({states:,} states found, {per_state:.1f} "
                f"transitions each, {BYTES_PER_STATE} bytes per state and "
                f"{BYTES_PER_TRANSITION} per transition); raise max_memory, loosen "
                "epsilon, or shrink the model"
            )


def _bytes(n: float) -> str:
    for unit, size in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= size:
            return f"{n / size:.1f} {unit}"
    return f"{n:.0f} bytes"
