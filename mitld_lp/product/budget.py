"""The product's size budgets, checked before the work that would exceed them.

:func:`estimate_size` bounds the product from its factors before anything is built;
:class:`BuildBudget` counts the states and transitions as the build goes and refuses,
before a batch's new states are stored, a product over ``max_states`` states or over
``max_memory`` bytes (:data:`BYTES_PER_STATE`, :data:`BYTES_PER_TRANSITION`).

A robust product (some law a band) is solved on nature's vertex distributions
(:func:`mitld_lp.product.imdp.vertex_rows`): a choice with ``k`` ambiguous events has ``2^k``
vertex rows, each over the union of its ``2^k`` branches' successors, computed from
``2^k x 2^k`` weights.  The budget counts them too, as the build finds the choices
(:data:`BYTES_PER_VERTEX_ENTRY`, :data:`BYTES_PER_VERTEX_ROW`, and the widest block of
weights at :data:`mitld_lp.product.imdp.BYTES_PER_WEIGHT`), and before anything is built
refuses a task whose start alone, with every event pending, would not fit
(:meth:`BuildBudget.check_start`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from mitld_lp.automata.sta import STA
from mitld_lp.product.imdp import BYTES_PER_WEIGHT, WEIGHT_BLOCK
from mitld_lp.util.memory import ProductTooLarge, byte_text, default_max_memory
from mitld_lp.worlds.game import Game, world_members

__all__ = [
    "ProductTooLarge",
    "BYTES_PER_STATE",
    "BYTES_PER_TRANSITION",
    "BYTES_PER_VERTEX_ENTRY",
    "BYTES_PER_VERTEX_ROW",
    "MAX_INDEX",
    "SizeEstimate",
    "BuildBudget",
    "default_max_memory",
    "estimate_size",
]

MAX_INDEX = 2**31 - 1
"""The most states an MDP can hold: the matrix's column indices are int32."""


# Peak bytes of the construction, measured with experiments/bench_product.py on builds
# of 0.3-3.5M states (tracemalloc, numpy's buffers included): about 30 bytes per
# transition (the matrix, the batches' rows, the merge) and 80 per state (the index at
# load 1/4-1/2, the keys, the rows per choice); rounded up.
BYTES_PER_TRANSITION = 32
BYTES_PER_STATE = 96

# Robust products: peak bytes per entry and per row of nature's vertex distributions,
# measured (ru_maxrss, experiments/fuzz.py's band cases) on a model with 8 ambiguous
# events: 12.0M vertex entries, 0.26M vertex rows, 0.89 GB above the product for the
# vertex rows, the robust iteration and the policy LP together (74 bytes per entry);
# rounded up.
BYTES_PER_VERTEX_ENTRY = 80
BYTES_PER_VERTEX_ROW = 64


@dataclass(frozen=True, slots=True)
class SizeEstimate:
    """An upper bound on the product's states from its factors, before anything is built.

    ``states = game_states * automaton_states * situations + 3``: every ordinary product
    state is a game state, a non-absorbing automaton state and a situation (the pending
    events and a clock value at most ``cap(pending)``), plus the three absorbing states.
    ``game_states`` is None (and so is ``states``) for a game that does not say how many
    states it has (:attr:`mitld_lp.worlds.game.WorldMembers.n_states`).
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
    vertex_entries: int = 0  # robust: their choices' vertex rows' entries
    vertex_rows: int = 0  # and vertex rows
    weights: int = 0  # and vertex weights (2^k x 2^k per choice)
    widest: int = 0  # the most ambiguous events of one choice

    def add_vertices(self, entries: int, rows: int, weights: int, widest: int) -> None:
        """Count the vertex distributions of a batch of expanded states (robust)."""
        self.vertex_entries += entries
        self.vertex_rows += rows
        self.weights += weights
        self.widest = max(self.widest, widest)

    def _weight_block(self) -> float:
        """Bytes of the largest block of weights :func:`~mitld_lp.product.imdp.vertex_rows`
        holds at once: a block, or one choice wider than a block, or all the weights
        when they are fewer."""
        return min(max(WEIGHT_BLOCK, 4**self.widest), self.weights) * BYTES_PER_WEIGHT

    def check_start(self, ambiguous: int) -> None:
        """Refuse before the build a robust task whose start, with ``ambiguous``
        events pending whose hazard is an interval, cannot fit ``max_memory``: one choice
        there has ``2^k`` vertex rows computed from ``4^k`` weights."""
        def need(k: int) -> int:
            return 4**k * BYTES_PER_WEIGHT + 2**k * (BYTES_PER_VERTEX_ROW
                                                      + BYTES_PER_VERTEX_ENTRY)

        if ambiguous == 0 or need(ambiguous) <= self.max_memory:
            return
        fits = max((k for k in range(ambiguous) if need(k) <= self.max_memory), default=0)
        raise ProductTooLarge(
            f"{ambiguous} events whose law is a band are pending together at the start: "
            f"nature's vertex distributions of one choice there alone need 2^{ambiguous} "
            f"vertex rows from 4^{ambiguous} = {4**ambiguous:,} weights, about "
            f"{byte_text(need(ambiguous))}, more than max_memory = {byte_text(self.max_memory)} "
            f"(at most {fits} such events fit); raise max_memory, or give fewer events "
            "a band (an exact law)")

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
        if self.vertex_rows:  # counted exactly on the states expanded: the vertex rows
            # are computed after the build, and the first states (every event pending)
            # have the most: an average would overstate the rest
            need += (self.vertex_entries * BYTES_PER_VERTEX_ENTRY
                     + self.vertex_rows * BYTES_PER_VERTEX_ROW + self._weight_block())
            if need > self.max_memory:
                raise ProductTooLarge(
                    f"the robust product would need about {byte_text(need, 2)}, more than "
                    f"max_memory = {byte_text(self.max_memory, 2)} ({states:,} states found, "
                    f"{per_state:.1f} branch transitions each; nature's vertex "
                    f"distributions of the {self.expanded:,} states expanded: "
                    f"{self.vertex_rows:,} rows, up to 2^{self.widest} per choice, "
                    f"{self.vertex_entries:,} entries at {BYTES_PER_VERTEX_ENTRY} bytes); "
                    f"raise max_memory above {byte_text(need, 2)}, give fewer events a band, "
                    "loosen epsilon, or shrink the model")
        if need > self.max_memory:
            raise ProductTooLarge(
                f"the product would need about {byte_text(need)}, more than max_memory = "
                f"{byte_text(self.max_memory)} ({states:,} states found, {per_state:.1f} "
                f"transitions each, {BYTES_PER_STATE} bytes per state and "
                f"{BYTES_PER_TRANSITION} per transition); raise max_memory, loosen "
                "epsilon, or shrink the model"
            )
