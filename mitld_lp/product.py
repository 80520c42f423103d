"""The product of the game with the STA: a finite MDP, built over reachable states only.

A product state is ``(game state, automaton state, pending events, clock)``.  From it
the robot picks an action ``a``; the environment's events ``E`` of the step are drawn
from the pending events' hazards (:meth:`STA.outcomes`); the game moves to ``s'`` with
probability ``P(s' | s, a, E)``; the automaton reads the label ``L(s') = props(s') | E``.
So, DESIGN.md's semantics::

    P((s, q, Y, c) --a--> (s', q', Y \\ E, c'))  =  p_STA(E | Y, c) * P(s' | s, a, E)
    with q' = delta(q, props(s') | E).

At step 0 no event has happened: the initial state is ``(s0, delta(q0, props(s0)), U, 0)``.
Accepting automaton states collapse into one absorbing ``target`` state, rejecting ones
into ``sink``, and outcomes that cross a truncation point into ``truncated``; the three
are kept apart in the MDP's masks, so one build yields both the lower model (truncated
loses) and the upper model (truncated wins).
"""

from __future__ import annotations

import logging
from collections.abc import Hashable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
from tqdm.auto import tqdm

from mitld_lp.automata.sta import STA, TRUNCATED
from mitld_lp.game import Game
from mitld_lp.mdp import ABSORB, MDP

__all__ = ["ProductState", "ProductTooLarge", "product", "TARGET", "SINK", "TRUNCATED_STATE"]

log = logging.getLogger(__name__)

TARGET = "target"
SINK = "sink"
TRUNCATED_STATE = "truncated"


class ProductTooLarge(RuntimeError):
    """The reachable product exceeded ``max_states``."""


@dataclass(frozen=True, slots=True)
class ProductState:
    """A non-absorbing product state.

    ``clock`` counts the steps taken, capped where no pending event's hazard changes
    any more; ``ages`` gives each pending event's age as its distribution sees it.
    """

    game: Hashable
    automaton: int
    pending: frozenset[str]
    clock: int

    def ages(self, sta: STA) -> dict[str, int]:
        return {a: min(self.clock, sta.clocks[a].cap) for a in sorted(self.pending)}


def product(
    game: Game[Any],
    sta: STA,
    *,
    max_states: int = 5_000_000,
    progress: bool | None = None,
) -> MDP:
    """Build the reachable product MDP of ``game`` and ``sta`` (see the module docstring).

    Raises :class:`ProductTooLarge` when more than ``max_states`` states are reached.
    ``progress``: show a progress bar (None: only on a terminal, for large builds).
    """
    dta = sta.dta
    accepting, rejecting = dta.accepting, dta.rejecting
    index: dict[Any, int] = {}
    states: list[Hashable] = []
    kinds: list[int] = []  # 0 ordinary, 1 target, 2 sink, 3 truncated
    special = {TARGET: 1, SINK: 2, TRUNCATED_STATE: 3}

    def intern(key: Hashable) -> int:
        i = index.get(key)
        if i is None:
            i = index[key] = len(states)
            states.append(key)
            kinds.append(special.get(key, 0) if isinstance(key, str) else 0)
            if len(states) > max_states:
                raise ProductTooLarge(
                    f"the product has more than {max_states:,} reachable states "
                    f"(automaton: {dta.n_states} states, events: {sorted(sta.events)}, "
                    f"truncation points: {sta.truncation_points or 'none'}); raise "
                    "max_states, loosen epsilon, or shrink the model"
                )
        return i

    def state_key(s: Hashable, q: int, pending: frozenset[str], clock: int) -> Hashable:
        if clock == TRUNCATED:
            return TRUNCATED_STATE
        if q == accepting:
            return TARGET
        if q == rejecting:
            return SINK
        return ProductState(s, q, pending, clock)

    s0 = game.initial
    q0 = dta.step(dta.initial, game.propositions(s0))
    initial = intern(state_key(s0, q0, sta.events, 0))

    label_cache: dict[tuple[Hashable, frozenset[str]], frozenset[str]] = {}
    succ_cache: dict[tuple[Hashable, str, frozenset[str]], tuple] = {}
    action_index: dict[str, int] = {}

    indptr = [0]
    cols: list[int] = []
    vals: list[float] = []
    row_groups = [0]
    choice_actions: list[int] = []

    bar = tqdm(
        total=None,
        unit=" states",
        disable=(not progress) if progress is not None else None,
        leave=False,
        mininterval=0.5,
        desc="product",
    )
    head = 0
    while head < len(states):
        key = states[head]
        head += 1
        if head % 4096 == 0:
            bar.update(4096)
        if not isinstance(key, ProductState):
            cols.append(head - 1)
            vals.append(1.0)
            indptr.append(len(cols))
            choice_actions.append(ABSORB)
            row_groups.append(len(choice_actions))
            continue
        s, q, pending, clock = key.game, key.automaton, key.pending, key.clock
        outcomes = sta.outcomes(pending, clock)
        for action in game.actions(s):
            row: dict[int, float] = {}
            for out in outcomes:
                if out.clock == TRUNCATED:
                    j = intern(TRUNCATED_STATE)
                    row[j] = row.get(j, 0.0) + out.probability
                    continue
                skey = (s, action, out.occurred)
                succ = succ_cache.get(skey)
                if succ is None:
                    succ = succ_cache[skey] = tuple(game.successors(s, action, out.occurred))
                for s2, p in succ:
                    lkey = (s2, out.occurred)
                    label = label_cache.get(lkey)
                    if label is None:
                        label = label_cache[lkey] = game.propositions(s2) | out.occurred
                    q2 = dta.step(q, label)
                    j = intern(state_key(s2, q2, out.pending, out.clock))
                    row[j] = row.get(j, 0.0) + out.probability * p
            cols.extend(row)
            vals.extend(row.values())
            indptr.append(len(cols))
            choice_actions.append(action_index.setdefault(action, len(action_index)))
        row_groups.append(len(choice_actions))
    bar.close()

    n = len(states)
    matrix = sp.csr_array(
        (np.asarray(vals, dtype=np.float64), np.asarray(cols, dtype=np.int32),
         np.asarray(indptr, dtype=np.int64)),
        shape=(len(choice_actions), n),
    )
    kind = np.asarray(kinds, dtype=np.int8)
    mdp = MDP(
        matrix=matrix,
        row_groups=np.asarray(row_groups, dtype=np.int64),
        choice_actions=np.asarray(choice_actions, dtype=np.int32),
        action_names=tuple(sorted(action_index, key=action_index.__getitem__)),
        initial=initial,
        target=kind == 1,
        sink=kind == 2,
        truncated=kind == 3,
        states=tuple(states),
    )
    log.info(
        "product: %d states, %d choices, %d transitions", n, mdp.n_choices, mdp.n_transitions
    )
    return mdp


def component_counts(mdp: MDP) -> Mapping[str, int]:
    """Sizes for people: states by kind, distinct automaton states and clock values."""
    ordinary = [s for s in mdp.states if isinstance(s, ProductState)]
    return {
        "states": mdp.n_states,
        "choices": mdp.n_choices,
        "transitions": mdp.n_transitions,
        "ordinary states": len(ordinary),
        "target states": int(mdp.target.sum()),
        "sink states": int(mdp.sink.sum()),
        "truncated states": int(mdp.truncated.sum()),
        "game states": len({s.game for s in ordinary}),
        "automaton states": len({s.automaton for s in ordinary}),
        "event situations": len({s.pending for s in ordinary}),
        "clock values": len({s.clock for s in ordinary}),
    }
