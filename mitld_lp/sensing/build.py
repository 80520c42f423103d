"""The construction of the information-state product (:mod:`mitld_lp.sensing.belief`'s
module docs): the reachable information states from the initial one, breadth first, each
expanded by the step rules (:mod:`mitld_lp.sensing.rules`), under the state and memory
budgets."""

from __future__ import annotations

import logging
import math
from collections.abc import Hashable, Mapping
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.automata.dta import DTA
from mitld_lp.automata.sta import STA
from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.product import Absorbing, ProductTooLarge
from mitld_lp.sensing.info import (
    BYTES_PER_HYPOTHESIS,
    BYTES_PER_INFO_STATE,
    NOT_YET,
    WEIGHT_TOL,
    Belief,
    Ends,
    InfoSize,
    InfoState,
    Obs,
)
from mitld_lp.sensing.rules import StepRules
from mitld_lp.sensing.sensors import Sensor
from mitld_lp.util.progress import bar as progress_bar
from mitld_lp.worlds.game import Game

__all__ = ["Builder"]

log = logging.getLogger("mitld_lp.sensing.belief")


class Builder(StepRules):
    """The information states reachable from the initial one (module docs), under
    ``max_states`` and ``max_memory`` (``size``: what a state can hold, for the
    messages)."""

    def __init__(self, game: Game[Any], dta: DTA, sta: STA, sensed: tuple[str, ...],
                 sensors: Mapping[str, Sensor], max_states: int, max_memory: int,
                 size: InfoSize, ends: Ends | None = None) -> None:
        super().__init__(game, dta, sta, sensed, sensors, ends)
        self.size, self.max_states = size, max_states
        self.max_memory, self.bytes = max_memory, 0
        self.index: dict[Hashable, int] = {}
        self.states: list[InfoState | Hashable] = []
        self.moves: dict[tuple[int, str], dict[Obs, int | Absorbing]] = {}
        self.succ: dict[tuple[Hashable, str, frozenset[str]], tuple[Any, ...]] = {}


    def intern(self, state: InfoState | Hashable) -> int:
        key = state.key() if isinstance(state, InfoState) else state
        i = self.index.get(key)
        if i is not None:
            if isinstance(state, InfoState):
                old = self.states[i]
                assert isinstance(old, InfoState)
                gap = max(abs(a - b) for a, b in zip(old.weights, state.weights, strict=True))
                if gap > WEIGHT_TOL:  # the posterior is not a function of the key
                    raise RuntimeError(
                        f"internal error: information state {key!r} reached with two "
                        f"posteriors (they differ by {gap:.3g})")
            return i
        if len(self.states) >= self.max_states:
            raise ProductTooLarge(
                f"the information-state product has more than {self.max_states:,} states "
                f"(sensed events: {', '.join(self.sensed)}; truncation points: "
                f"{self.sta.truncation_points}; {self.size}); raise max_states, loosen "
                "epsilon, or shrink the model")
        cost = BYTES_PER_INFO_STATE + (
            BYTES_PER_HYPOTHESIS * len(state.hypotheses) if isinstance(state, InfoState) else 0)
        if self.bytes + cost > self.max_memory:
            raise ProductTooLarge(
                f"the information-state product would need more than {self.max_memory:,} "
                f"bytes ({len(self.states):,} states so far, sensed events: "
                f"{', '.join(self.sensed)}; {self.size}); raise max_memory, loosen "
                "epsilon, or shrink the model")
        self.bytes += cost
        self.index[key] = len(self.states)
        self.states.append(state)
        return len(self.states) - 1

    def make(self, world: Hashable, t: int, reported: frozenset[str],
             pending: frozenset[str], mass: Mapping[tuple[tuple[int, ...], int], float],
             ) -> InfoState:
        total = math.fsum(mass.values())
        hyps = tuple(sorted(mass))
        return InfoState(world, self.clock_key(t, [h for h, _ in hyps], pending, reported),
                         reported, pending, hyps, tuple(mass[h] / total for h in hyps))

    def expand(self, i: int, s: InfoState) -> list[tuple[str, dict[int, float]]]:
        rows = []
        t = s.clock
        for act in self.game.actions(s.world):
            row: dict[int, float] = {}
            groups: dict[tuple[Obs, frozenset[str]], dict[tuple[tuple[int, ...], int], float]]
            groups = {}
            ends: dict[Obs, set[Hashable]] = {}
            for occurred, pu, crossed in self.unsensed_outcomes(s.pending, t):
                if crossed:
                    j = self.intern(Absorbing.TRUNCATED)
                    row[j] = row.get(j, 0.0) + pu
                    continue
                skey = (s.world, act, occurred)
                succ = self.succ.get(skey)
                if succ is None:
                    succ = self.succ[skey] = tuple(self.game.successors(s.world, act, occurred))
                for (times, q), w in zip(s.hypotheses, s.weights, strict=True):
                    for times2, new, pc, cut, now, waiting in self.sensed_branches(
                            times, s.reported, t):
                        base = w * pu * pc
                        if cut:
                            j = self.intern(Absorbing.TRUNCATED)
                            row[j] = row.get(j, 0.0) + base
                            continue
                        happened = occurred | now
                        left = (s.pending - occurred) | waiting
                        for g2, pg in succ:
                            if pg <= 0.0:
                                continue
                            label = self.label(g2) | happened
                            q2 = self.automaton(q, label)
                            obs: Obs = (g2, occurred, new)
                            mass = base * pg
                            end = self.end(q2, left)
                            if end is not None:
                                j = self.intern(end)
                                row[j] = row.get(j, 0.0) + mass
                                ends.setdefault(obs, set()).add(end)
                                continue
                            group = groups.setdefault((obs, s.pending - occurred), {})
                            group[(times2, q2)] = group.get((times2, q2), 0.0) + mass
            moves = self.moves.setdefault((i, act), {})
            for (obs, pending2), mass in groups.items():
                g2, _, new = obs
                state = self.make(g2, t + 1, s.reported | new, pending2, mass)
                j = self.intern(state)
                row[j] = row.get(j, 0.0) + math.fsum(mass.values())
                moves[obs] = j
            for obs, kinds in ends.items():
                if obs not in moves:  # nothing undecided left: the verdict, if one
                    moves[obs] = (next(iter(kinds)) if len(kinds) == 1
                                  else Absorbing.TRUNCATED)
            rows.append((act, row))
        return rows

    # ---------------------------------------------------------------- the MDP

    def build(self, progress: bool | None = None) -> Belief:
        game, dta = self.game, self.dta
        q0 = dta.step(dta.initial, frozenset(game.propositions(game.initial)))
        first = self.end(q0, frozenset(self.sta.events)) if (
            self.ends is not None or q0 in (dta.accepting, dta.rejecting)) else None
        if first is not None:
            initial = self.intern(first)
        else:
            times0 = (NOT_YET,) * len(self.sensed)
            initial = self.intern(self.make(game.initial, 0, frozenset(), self.unsensed,
                                            {(times0, q0): 1.0}))
        indptr, cols, vals = [0], [], []
        groups, actions = [0], []
        names: dict[str, int] = {}
        head = 0
        shown = progress_bar(progress, total=None, unit=" states", desc="information states",
                             leave=False, mininterval=0.5)
        while head < len(self.states):
            shown.update()
            s = self.states[head]
            if not isinstance(s, InfoState):
                cols.append(head)
                vals.append(1.0)
                actions.append(ABSORB)
            else:
                for act, row in self.expand(head, s):
                    cols.extend(row)
                    vals.extend(row.values())
                    actions.append(names.setdefault(act, len(names)))
                    indptr.append(len(cols))
                groups.append(len(actions))
                head += 1
                continue
            indptr.append(len(cols))
            groups.append(len(actions))
            head += 1
        shown.close()
        log.info("information-state product: %s states, %s choices, %s transitions",
                 f"{len(self.states):,}", f"{len(actions):,}", f"{len(cols):,}")
        n = len(self.states)
        kind = np.array([{Absorbing.TARGET: 1, Absorbing.SINK: 2, Absorbing.TRUNCATED: 3}
                         .get(s, 0) if isinstance(s, Absorbing) else 0 for s in self.states],
                        dtype=np.int8)
        matrix = sp.csr_array((np.asarray(vals, dtype=np.float64),
                               np.asarray(cols, dtype=np.int32),
                               np.asarray(indptr, dtype=np.int64)), shape=(len(actions), n))
        mdp = MDP(matrix=matrix, row_groups=np.asarray(groups, dtype=np.int64),
                  choice_actions=np.asarray(actions, dtype=np.int32),
                  action_names=tuple(sorted(names, key=names.__getitem__)),
                  initial=initial, target=kind == 1, sink=kind == 2, truncated=kind == 3,
                  states=tuple(self.states))
        return Belief(mdp, self.sta, self.sensed, self.sensors, self.moves)
