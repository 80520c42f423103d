"""The chain of a controller that acts on sensor reports where some event's law is a
band, with nature's corners as each state's choices (:func:`sensed_corner_unfolding`;
:mod:`mitld_lp.running.sensed_band_chain` writes it as an interval model and reads the
controller's worst case from it).

Its states and each corner's step are those of :mod:`mitld_lp.running.sensed_chain`
(the truth and the controller's memory).  The corners of a state share everything but
the events' probabilities: the controller's decision, which events may happen and which
outcomes a truncation point gives, the clock after the step, the sensors' reports, the
world's moves, the automaton's step and the controller's memory after it.  So each state
and action is unfolded once into a *template* (:class:`_Template`): the step's outcomes
in the order the chain's step lists them, each with the factors its probability is the
product of; a corner then only multiplies its hazards through it, in the same order as
the step one corner at a time would, and numbers the successors of positive probability
as that step would meet them: the same chain, row by row and bit by bit.  The parts that
depend on less than the state (the outcomes of the pending events at a clock, the clock's
advance, the sensors' reports, the world's moves, the automaton's step) are shared
between states too.
"""

from __future__ import annotations

import itertools
from collections.abc import Hashable, Mapping
from typing import Any

from mitld_lp.automata.dta import DTA
from mitld_lp.automata.sta import STA
from mitld_lp.controllers.format import UNDECIDED
from mitld_lp.controllers.kinds import ControllerLike
from mitld_lp.running.chain_model import Chain
from mitld_lp.running.sensed_chain import TaskEnds, Unfolding, never_share, plan_of
from mitld_lp.sensing.sensors import Sensor
from mitld_lp.worlds.game import Game

__all__ = ["sensed_corner_unfolding"]

Choices = list[list[tuple[str, dict[int, float]]]]

_NONE = object()
"""No memory cached yet (a memory may be any value)."""


def sensed_corner_unfolding(game: Game[Any], dta: DTA, sta: STA,
                            sensors: Mapping[str, Sensor], controller: ControllerLike,
                            max_states: int | None = None, *, ends: Any = None
                            ) -> tuple[Chain, Choices]:
    """The chain of ``controller`` (a controller that acts on sensor reports) where some
    event's law is a band (``sta``'s clocks then give each step's hazard interval,
    :meth:`~mitld_lp.automata.sta.EventClock.band`): every state has one choice per
    corner of the box of the hazards of its pending events whose band is open at its
    clock, nature's (:mod:`mitld_lp.running.sensed_band_chain`); where a randomised
    controller draws among several actions, one per corner for each action drawn
    (nature sees the robot's action, docs/robust.md).  Returns the chain of the union of
    those choices' supports (its labels, valuations, states and rewards) and each
    state's choices ``(name, row)``; past ``max_states`` states it stops
    (:class:`~mitld_lp.util.memory.ProductTooLarge`).  ``ends``: as for
    :func:`~mitld_lp.running.sensed_chain.sensed_chain` (a joint automaton's)."""
    plan, sensed = plan_of(controller, sensors)
    unfolding = _CornerUnfolding(game, dta, sta, sensors, sensed, plan,
                                 ends or TaskEnds(dta))
    unfolding.max_states = max_states
    return unfolding.corners()


class _Successor:
    """A successor of a step's outcome (world state ``g2`` with probability ``p_world``
    under the sensors' reports ``seen``); its chain key (the node, or the end its
    automaton state decides) made the first time a corner gives it a positive
    probability, as the step one corner at a time makes it."""

    __slots__ = ("g2", "p_world", "key")

    def __init__(self, g2: Hashable, p_world: float) -> None:
        self.g2, self.p_world, self.key = g2, p_world, None


class _Branch:
    """One outcome of a step's events (``left`` still pending after it, its probability
    the events' times ``factors``, in order): the truncation, or per report of the
    sensors ``(p_reports, seen, unreported after, successors)``; filled the first time
    a corner gives it a positive probability."""

    __slots__ = ("left", "factors", "truncated", "clock", "reports")

    def __init__(self, left: frozenset[str], factors: tuple[float, ...]) -> None:
        self.left, self.factors = left, factors
        self.truncated: bool | None = None
        self.clock = 0
        self.reports: list[tuple[float, frozenset[str], tuple[int, ...],
                                 list[_Successor]]] = []


class _Template:
    """A state's step under one action, for every corner (module docs): per set of
    events that may happen (in the order of :meth:`Unfolding.events`), which of the
    pending events it holds (``bits``, in sorted order) and its branches."""

    __slots__ = ("occurred", "bits", "branches")

    def __init__(self, occurred: list[frozenset[str]], bits: list[tuple[bool, ...]],
                 branches: list[list[_Branch]]) -> None:
        self.occurred, self.bits, self.branches = occurred, bits, branches


class _CornerUnfolding(Unfolding):
    """:class:`~mitld_lp.running.sensed_chain.Unfolding` with each state's step at
    every corner of the bands (module docs)."""

    max_states: int | None = None

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self._subsets: dict[frozenset[str], tuple[list[frozenset[str]],
                                                  list[tuple[bool, ...]]]] = {}
        self._branches: dict[tuple[frozenset[str], frozenset[str], int],
                             list[tuple[frozenset[str], tuple[float, ...]]]] = {}
        self._advance: dict[tuple[frozenset[str], int], Any] = {}
        self._reports: dict[tuple[frozenset[str], tuple[int, ...]], Any] = {}
        self._worlds: dict[tuple[Hashable, str, frozenset[str]], list[tuple[Any, float]]] = {}
        self._steps: dict[tuple[int, Hashable, frozenset[str]], int] = {}
        self._follows: dict[tuple[Any, Hashable, frozenset[str], str], Any] = {}
        self._named: dict[tuple[Any, ...], list[tuple[str, tuple[tuple[int, ...], ...]]]] = {}
        self._decided: dict[int, tuple[Any, list[str], list[tuple[str, float]]]] = {}

    def corners(self) -> tuple[Chain, Choices]:
        self.start()
        choices: Choices = []
        while len(choices) < len(self.order):
            if self.max_states is not None and len(self.order) > self.max_states:
                from mitld_lp.util.memory import ProductTooLarge

                raise ProductTooLarge(
                    f"the sensed controller's interval chain has more than "
                    f"{self.max_states:,} states (max_states); raise max_states")
            node = self.order[len(choices)]
            if isinstance(node, str):
                choices.append([("stay", {len(choices): 1.0})])
                continue
            choices.append(self.choices(node))
        union: list[dict[int, float]] = []
        for here in choices:
            row: dict[int, float] = {}
            for _, r in here:
                for k, p in r.items():
                    row[k] = max(row.get(k, 0.0), p)
            union.append(row)
        return self.record(union), choices

    def choices(self, node: tuple[Any, ...]) -> list[tuple[str, dict[int, float]]]:
        """Nature's choices at ``node``: one row per corner (and per action drawn)."""
        g, q, pending, clock, _, memory = node
        clocks = self.sta.clocks
        events = sorted(pending)
        bands = {a: clocks[a].band(clock) for a in events}
        open_ = [a for a, (lo, hi) in bands.items() if lo < hi]
        plan = self.plan
        stop: int | None = None
        stay: tuple[Any, float] | None = None
        branches: list[tuple[str, float]] = []
        drawn: list[str | None] = [None]
        d = plan.decision(g, memory) if UNDECIDED in plan.verdicts_at(memory) else None
        if d is None or d.lost:  # the controller stops
            stop = self.number(self.ends.stopped(q))
        else:
            if d.weights is None or not d.actions:
                branches = [(d.actions[0] if d.actions else plan.fallback(g), 1.0)]
            else:  # randomised: stay for ever, or an action (per action drawn a corner)
                if d.stay > 0.0:
                    stay = (self.ends.stayed(q, memory), d.stay)
                acts, branches = self._mixed(d)
                if open_ and len(acts) > 1:
                    drawn = list(acts)
            self.mixes[self.index[node]] = branches
        templates = {a: self._template(node, a) for a, _ in branches}
        lo_of = {a: lo for a, (lo, _) in bands.items()}
        here = []
        for name, pick in self._picks(tuple(drawn), tuple(open_)):
            per_action = {act: {a: bands[a][e] for a, e in zip(open_, ends, strict=True)}
                          for act, ends in zip(drawn, pick, strict=True)}
            if stop is not None:
                here.append((name, {stop: 1.0}))
                continue
            row: dict[int, float] = {}
            if stay is not None:
                row[self.number(stay[0])] = stay[1]
            for action, p_action in branches:
                corner = per_action.get(action, per_action.get(None, {}))
                hazards = [corner.get(a, lo_of[a]) for a in events]
                self._fill(node, action, templates[action], hazards, p_action, row)
            here.append((name, row))
        return here

    def _picks(self, drawn: tuple[str | None, ...], open_: tuple[str, ...]
               ) -> list[tuple[str, tuple[tuple[int, ...], ...]]]:
        """Nature's corners for the actions ``drawn`` and the open bands ``open_``: each
        choice's name and, per action drawn, each open band's end (0 low, 1 high)."""
        key = (drawn, open_)
        hit = self._named.get(key)
        if hit is None:
            boxes = list(itertools.product((0, 1), repeat=len(open_)))
            hit = self._named[key] = [("/".join(["act", *(
                ("" if act is None else f"{act}:") + f"{a}={('lo', 'hi')[e]}"
                for act, ends in zip(drawn, pick, strict=True)
                for a, e in zip(open_, ends, strict=True))]), pick)
                for pick in itertools.product(boxes, repeat=len(drawn))]
        return hit

    def _mixed(self, d: Any) -> tuple[list[str], list[tuple[str, float]]]:
        """A randomised decision's actions of positive weight, and its actions with their
        probabilities as the chain's step computes them (the weights normalised by their
        sum, stay's share taken); once per decision."""
        hit = self._decided.get(id(d))
        if hit is None or hit[0] is not d:
            import numpy as np

            arr = np.asarray(d.weights, dtype=float)
            acts = [a for a, x in zip(d.actions, d.weights, strict=True) if x > 0.0]
            hit = self._decided[id(d)] = (d, acts, [
                (a, (1.0 - d.stay) * float(x)) for a, x in
                zip(d.actions, arr / arr.sum(), strict=True) if x > 0.0])
        return hit[1], hit[2]

    def _template(self, node: tuple[Any, ...], action: str) -> _Template:
        """``node``'s step under ``action`` for every corner (filled lazily)."""
        _, _, pending, clock, _, _ = node
        occurred, bits = self._subsets_of(pending)
        branches = []
        for e in occurred:
            key = (pending, e, clock)
            spec = self._branches.get(key)
            if spec is None:
                spec = self._branches[key] = self._never_branches(pending, e, clock)
            branches.append([_Branch(left, f) for left, f in spec])
        return _Template(occurred, bits, branches)

    def _subsets_of(self, pending: frozenset[str]
                    ) -> tuple[list[frozenset[str]], list[tuple[bool, ...]]]:
        """Every set of ``pending`` events in the order :meth:`Unfolding.events` lists
        them, with which of the sorted pending events each holds."""
        hit = self._subsets.get(pending)
        if hit is None:
            out: list[tuple[frozenset[str], tuple[bool, ...]]] = [(frozenset(), ())]
            for a in sorted(pending):
                out = [(e | {a}, (*b, True)) for e, b in out] + [
                    (e, (*b, False)) for e, b in out]
            hit = self._subsets[pending] = ([e for e, _ in out], [b for _, b in out])
        return hit

    def _never_branches(self, pending: frozenset[str], occurred: frozenset[str], clock: int
                        ) -> list[tuple[frozenset[str], tuple[float, ...]]]:
        """:meth:`Unfolding.outcomes`'s branches of one set of events: what is left
        pending and the factors of its probability after the events' (a sensed event
        that may never happen, at its truncation point)."""
        branches: list[tuple[frozenset[str], tuple[float, ...]]] = [(pending - occurred, ())]
        for a in sorted(pending - occurred):
            never = never_share(self.sta.clocks[a], clock)
            if never is None:
                continue
            branches = [(b - {a}, (*f, never)) for b, f in branches] + [
                (b, (*f, 1.0 - never)) for b, f in branches]
        return branches

    def _fill(self, node: tuple[Any, ...], action: str, t: _Template, hazards: list[float],
              p_action: float, row: dict[int, float]) -> None:
        """Add to ``row`` the successors of ``node`` under ``action`` at the corner whose
        hazards (per sorted pending event) are ``hazards``: the arithmetic and the order
        of :meth:`Unfolding.moves`."""
        index = self.index
        for e, bits, branches in zip(t.occurred, t.bits, t.branches, strict=True):
            p_events = 1.0
            for h, on in zip(hazards, bits, strict=True):
                p_events = p_events * h if on else p_events * (1.0 - h)
            if not p_events > 0.0:
                continue
            for br in branches:
                qv = p_events
                for f in br.factors:
                    qv = qv * f
                if not qv > 0.0:
                    continue
                if br.truncated is None:
                    self._fill_branch(node, action, e, br)
                if br.truncated:
                    k = self.number("truncated")
                    row[k] = row.get(k, 0.0) + p_action * qv
                    continue
                base = p_action * qv
                for p_reports, seen, unreported2, succ in br.reports:
                    pr = base * p_reports
                    for s in succ:
                        p = pr * s.p_world
                        if p <= 0.0:
                            continue
                        key = s.key
                        if key is None:
                            key = s.key = self._key(node, action, e, seen, unreported2,
                                                    br, s.g2)
                        k = index.get(key)
                        if k is None:
                            k = self.number(key)
                        row[k] = row.get(k, 0.0) + p

    def _fill_branch(self, node: tuple[Any, ...], action: str, occurred: frozenset[str],
                     br: _Branch) -> None:
        """The clock's advance, the sensors' reports and the world's moves of a branch."""
        g, _, _, clock, unreported, _ = node
        key = (br.left, clock)
        after = self._advance.get(key)
        if after is None:
            after = self._advance[key] = self.sta.advance(br.left, clock)
        br.truncated, br.clock = bool(after.truncated), after.clock
        if br.truncated:
            return
        rkey = (occurred, unreported)
        reports = self._reports.get(rkey)
        if reports is None:
            reports = self._reports[rkey] = self.reports(occurred, unreported)
        wkey = (g, action, occurred)
        worlds = self._worlds.get(wkey)
        if worlds is None:
            worlds = self._worlds[wkey] = list(self.game.successors(g, action, occurred))
        unsensed = occurred - frozenset(self.sensed)
        br.reports = [(p_reports, unsensed | reported, unreported2,
                       [_Successor(g2, p_world) for g2, p_world in worlds])
                      for reported, unreported2, p_reports in reports]

    def _key(self, node: tuple[Any, ...], action: str, occurred: frozenset[str],
             seen: frozenset[str], unreported2: tuple[int, ...], br: _Branch,
             g2: Hashable) -> Hashable:
        """The chain key of a successor (:meth:`Unfolding.enter`'s): the automaton's
        step on the new state's propositions and the true events, the controller's
        memory after its observation."""
        _, q, _, _, _, memory = node
        skey = (q, g2, occurred)
        q2 = self._steps.get(skey)
        if q2 is None:
            q2 = self._steps[skey] = self.dta.step(q, self.label(g2) | occurred)
        fkey = (memory, g2, seen, action)
        memory2 = self._follows.get(fkey, _NONE)
        if memory2 is _NONE:
            memory2 = self._follows[fkey] = self.plan.follow(memory, g2, seen, action)[0]
        end = self.ends.end(q2)
        return (g2, q2, br.left, br.clock, unreported2, memory2) if end is None else end
